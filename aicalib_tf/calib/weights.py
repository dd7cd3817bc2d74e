"""Per-corner weights of a calibration fit: which σ each corner enters a fit with, and the weights σ_ref / σ.

Every fit (one camera, a rig's joint fit, the field check, the live page's calibrations) takes its
corners' σ from :func:`fit_sigmas`, so all of them weigh corners by one rule, ``WEIGHTING``:

* ``"view"`` (the default): each corner takes the median σ of its view. The detector's σ says well
  which views are blurred or noisy (a fit of views 20 times noisier than the others comes 4–30
  times nearer the truth weighted so: the rig, field check and hand-eye tests), while inside one
  view it spreads only 0.8–1.2 times its median. On rendered calibration sequences with mixed blur
  and noise (``python benchmarks/corner_sigma.py --calibrate --repeats 4``, 16 calibrations) the
  projection error over the boards was 0.526 px with equal weights, 0.593 with the view's median
  and 0.642 with each corner's own σ (0.644 clipped); each corner's own σ against the view's
  median +0.049 ± 0.043 px, better in 6 of 16: not better, though σ follows the corners' errors
  (docs/benchmark.md, "Per-corner σ"); that error is mostly the principal point's (0.52-0.63 px),
  whatever the weighting;
* ``"clipped"``: each corner's own σ, held within ``CLIP`` times its view's median;
* ``"corner"``: each corner's own σ.

Views without σ (an OpenCV detector's) take the median of the others' (all equal when none has).
:func:`corner_weights` turns the σ into weights σ_ref / σ with σ_ref the median σ, so the weighted
residuals stay in px-like units and a fit whose corners all share one σ weighs them all 1 (the
unweighted fit's numbers).
"""

from __future__ import annotations

import numpy as np

__all__ = ["WEIGHTING", "WEIGHTINGS", "CLIP", "fit_sigmas", "corner_weights"]

WEIGHTINGS = ("view", "clipped", "corner")
WEIGHTING = "view"  # the rule every fit uses (benchmarks/corner_sigma.py --calibrate compares the others)
CLIP = (0.5, 2.0)  # "clipped": a corner's σ within these multiples of its view's median σ


def fit_sigmas(given, counts, rule: str | None = None) -> list | None:
    """Per-view (N_v,) float64 σ px that the views' corners enter a fit with, or None when no view has any.

    given : per view an (N_v,) σ px array or None (no σ: the detector gave none). counts : per view N_v,
    its number of corners. rule : one of ``WEIGHTINGS`` (None: ``WEIGHTING``). A view without σ takes
    the median over the others' medians. Raises ValueError for an unknown rule or a σ array of the wrong
    length, not finite, or not > 0.
    """
    rule = WEIGHTING if rule is None else rule
    if rule not in WEIGHTINGS:
        raise ValueError(f"weighting must be one of {', '.join(WEIGHTINGS)}, got {rule!r}")
    given = [None if g is None else np.asarray(g, np.float64).ravel() for g in given]
    if all(g is None for g in given):
        return None
    for g, n in zip(given, counts):
        if g is not None and (g.size != n or not np.all(np.isfinite(g)) or np.any(g <= 0)):
            raise ValueError(f"sigmas must hold {n} finite values > 0 px, one per corner, got {g.size}")
    medians = [None if g is None else float(np.median(g)) for g in given]
    fill = float(np.median([m for m in medians if m is not None]))
    out = []
    for g, m, n in zip(given, medians, counts):
        if g is None or rule == "view":
            out.append(np.full(int(n), fill if m is None else m))
        elif rule == "clipped":
            out.append(np.clip(g, CLIP[0] * m, CLIP[1] * m))
        else:
            out.append(g.copy())
    return out


def corner_weights(sigmas, inliers, n: int) -> np.ndarray | None:
    """(n,) float64 weights σ_ref / σ (σ_ref the median σ; 1 without sigmas), 0 for corners not in ``inliers``;
    None when neither is given (every weight 1). sigmas : list of (N_v,) px or one (n,) array."""
    if sigmas is None and inliers is None:
        return None
    w = np.ones(n)
    if sigmas is not None:
        sig = np.concatenate([np.asarray(s, np.float64).ravel() for s in sigmas]) if isinstance(sigmas, (list, tuple)) \
            else np.asarray(sigmas, np.float64).ravel()
        if sig.size != n or not np.all(np.isfinite(sig)) or np.any(sig <= 0):
            raise ValueError(f"sigmas must hold {n} finite values > 0 px, one per corner")
        w = np.median(sig) / sig
    if inliers is not None:
        keep = np.asarray(inliers, bool).ravel()
        if keep.size != n:
            raise ValueError(f"inliers must hold {n} values, one per corner, got {keep.size}")
        w = np.where(keep, w, 0.0)
    return w
