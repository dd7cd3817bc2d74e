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

__all__ = ["WEIGHTING", "WEIGHTINGS", "CLIP", "OUTLIER_K", "fit_sigmas", "corner_weights", "variance_components",
           "total_sigmas"]

WEIGHTINGS = ("view", "clipped", "corner", "components")
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


OUTLIER_K = 4.5  # a corner whose |r|² exceeds OUTLIER_K² · its σ_total² is left out of the components' estimate
_ROUNDS = 30


def variance_components(sigmas, residuals, n_params: int = 0, *, scale: bool = True) -> tuple[float, float]:
    """(a, τ²) that best explain a fit's residuals as σ_total² = a·σ² + τ² per axis, px².

    sigmas : per view (N_v,) px, the σ the corners entered the fit with; residuals : per view (N_v, 2) px
    (rows with a non-finite value are left out). n_params : the fit's parameters p; each residual's
    variance is taken as (1 − p / 2N) of its corner's (the mean leverage: REML's correction for what the
    fit absorbed). scale : fit a (else a = 1). Restricted maximum likelihood of the Gaussian model by
    Fisher scoring: y = |r|² / 2(1 − p/2N) has mean a·σ² + τ² and variance (a·σ² + τ²)², so each round is the
    least-squares fit of y on [σ², 1] weighted by 1 / (a·σ² + τ²)²; corners beyond ``OUTLIER_K`` σ_total are
    left out of the next round. a >= 0 and τ² >= 0; when every corner has one σ, a and τ² are not separable
    and a = 1 (only their sum matters to the fit's weights).
    """
    x = np.concatenate([np.asarray(v, np.float64).ravel() for v in sigmas]) ** 2
    r = np.concatenate([np.asarray(v, np.float64).reshape(-1, 2) for v in residuals])
    ok = np.isfinite(r).all(axis=1) & np.isfinite(x)
    x, y = x[ok], np.sum(r[ok] ** 2, axis=1) / 2.0
    if y.size == 0:
        return 1.0, 0.0
    y = y / max(1.0 - n_params / (2.0 * y.size), 0.05)
    scale = scale and float(np.ptp(x)) > 0.05 * float(np.median(x))
    a, t = 1.0, max(float(np.mean(y) - np.mean(x)), 0.0)
    floor = 1e-6 * float(np.median(x))  # a least τ² keeps every σ_total > 0
    keep = np.ones(y.size, bool)
    for _ in range(_ROUNDS):
        v = a * x + max(t, floor)
        w = keep / v ** 2
        if scale:
            A = np.array([[w @ (x * x), w @ x], [w @ x, w.sum()]])
            b = np.array([w @ (x * y), w @ y])
            a_new, t_new = np.linalg.solve(A, b) if np.linalg.det(A) > 1e-12 * A[0, 0] * A[1, 1] else (a, t)
            if t_new < 0:
                a_new, t_new = min((w @ (x * y)) / (w @ (x * x)), 1.0), 0.0
            elif a_new < 0:
                a_new, t_new = 0.0, (w @ y) / w.sum()
        if not scale or a_new > 1.0:
            a_new, t_new = 1.0, max(float(w @ (y - x)) / float(w.sum()), 0.0)
        keep = y <= OUTLIER_K ** 2 * (a_new * x + max(t_new, floor))
        done = abs(a_new - a) <= 1e-4 * max(a, 1e-9) and abs(t_new - t) <= 1e-4 * max(t, floor)
        a, t = float(a_new), float(t_new)
        if done:
            break
    return a, t


def total_sigmas(sigmas, residuals, n_params: int = 0, rule: str | None = None) -> list:
    """Per view (N_v,) σ_total px that a fit's corners are weighed with after a first fit weighted by ``sigmas``.

    ``"components"``: σ_total² = a·σ² + τ² of :func:`variance_components` on the first fit's residuals.
    The other rules: σ² + τ² with τ² = max(0, s² − mean σ²), s² the residuals' variance per axis (Σ|r|² / 2N).
    """
    rule = WEIGHTING if rule is None else rule
    sig = [np.asarray(v, np.float64) for v in sigmas]
    if rule == "components":
        a, t2 = variance_components(sig, residuals, n_params)
        return [np.sqrt(a * v * v + t2) for v in sig]
    res = np.concatenate([np.asarray(v, np.float64).reshape(-1, 2) for v in residuals])
    fin = np.isfinite(res).all(axis=1)
    s2 = float(np.sum(res[fin] ** 2) / (2 * max(fin.sum(), 1)))
    t2 = max(s2 - float(np.mean(np.concatenate(sig) ** 2)), 0.0)
    return [np.sqrt(v * v + t2) for v in sig]
