"""Per-corner weights of a calibration fit: which σ each corner enters a fit with, and the weights σ_ref / σ.

Every fit (one camera, a rig's joint fit, the hand-eye poses, the field check, the live page's
calibrations) takes its corners' σ from :func:`fit_sigmas` and, after a first fit weighted by them,
adds the error they leave unexplained with :func:`total_sigmas` (through
:func:`aicalib_tf.calib.robust.with_floor`), so all of them weigh corners by one rule, ``WEIGHTING``:

* ``"components"`` (the default): each corner's own σ_i and, after the first fit, σ_total,i² =
  a·σ_i² + τ² per axis: τ the share of the residuals the detector does not explain (the board's print
  and flatness, the lens model's misfit, rendering), a <= 1 the detector's share's scale, both by
  restricted maximum likelihood on the first fit's residuals (:func:`variance_components`). Where τ ≫ σ
  the weights become equal; where the detector's noise dominates (blurred or noisy views) they follow
  σ. a is held at most 1: the residuals cannot tell the detector's noise from a lens-model misfit that
  grows where σ does (far, oblique corners), which on real photos fitted a = 3-47; held so, an error
  in a only moves the weights towards equal.
* ``"view-components"``: the same with each view's median σ.
* ``"view"``: each corner takes the median σ of its view; ``"clipped"``: each corner's own σ, held
  within ``CLIP`` times its view's median; ``"corner"``: each corner's own σ. These three add
  τ² = max(0, s² − mean σ²), s² the residuals' variance per axis (Σ|r|² / 2N): a moment that finds no
  τ when the detector over-states its noisiest corners, whose excess then cancels the clean corners'
  shortfall.

Measured. On rendered sequences with mixed blur and noise the detector's σ of the cleanest views
(median 0.014 px) lie below their true errors (0.039 px per axis) and those of the noisiest above
(0.20 against 0.16 px): the true errors give a = 0.56, τ = 0.038 px, and the residuals alone give
a = 0.4-0.8, τ = 0.030-0.040 px for each calibration, where the moment above finds τ ≈ 0.
Calibrating them (``python benchmarks/corner_sigma.py --calibrate --repeats 4``, 16 calibrations),
the projection error over the boards: equal weights 0.532 px, ``"view"`` 0.585, ``"corner"`` 0.640,
``"clipped"`` 0.642, ``"components"`` 0.392, ``"view-components"`` 0.372; ``"components"`` against
equal −0.139 ± 0.062 px (better in 12 of 16), against ``"view"`` −0.193 ± 0.087 (12 of 16); with
``--repeats 12`` (48): equal 0.545, view 0.578, components 0.392, view-components 0.385 (these two
differ by 0.007 ± 0.010: inside a view σ spreads only 0.8–1.2 times its median). On real photos τ
dominates (0.12 px on OpenCV's left camera, σ median 0.029 px; 0.28 px on a 185° fisheye; 0.64 px on
a bent board) and the weights are nearly equal: over the same 24 random half-splits of each set
(``benchmarks/real_split_noise.py --splits 24 --weighting``, flat fits) the halves differ by a median
0.273 px against 0.265 with ``"view"`` (opencv_left), 4.20 against 4.17 (udacity_lane_cal) and 0.497
against 0.495 (ocam_fisheye); split by split the median change is −0.006 (lower on 14 of 24), +0.001
and +0.000 px: ties. The covariance's predicted 10–90% band
(:func:`aicalib_tf.calib.quality.predicted_half_difference`) holds 83% of opencv_left's splits (79%
with ``"view"``), 25% of udacity's and 21% of ocam's (unchanged): σ̂² of the weighted fit carries τ
already; those misses come from errors shared within a view, not from the weights.
Views with σ 20 times those of the others (rig, field check and hand-eye tests) come 4–30 times nearer
the truth weighted.

Views without σ (an OpenCV detector's) take the median of the others' (all equal when none has).
:func:`corner_weights` turns the σ into weights σ_ref / σ with σ_ref the median σ, so the weighted
residuals stay in px-like units and a fit whose corners all share one σ weighs them all 1 (the
unweighted fit's numbers).
"""

from __future__ import annotations

import numpy as np

__all__ = ["WEIGHTING", "WEIGHTINGS", "CLIP", "OUTLIER_K", "fit_sigmas", "corner_weights", "variance_components",
           "total_sigmas"]

WEIGHTINGS = ("view", "clipped", "corner", "components", "view-components")
WEIGHTING = "components"  # the rule every fit uses (benchmarks/corner_sigma.py --calibrate compares the others)
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
        if g is None or rule in ("view", "view-components"):
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
    left out of the next round. 0 <= a <= 1 (module docstring) and τ² >= 10⁻⁶·median σ² (σ_total > 0 even
    for residuals of 0); when every corner has one σ, a and τ² are not separable and a = 1 (only their sum
    matters to the fit's weights).
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
                a_new, t_new = (w @ (x * y)) / (w @ (x * x)), 0.0
            elif a_new < 0:
                a_new, t_new = 0.0, (w @ y) / w.sum()
        if not scale or a_new > 1.0:
            a_new, t_new = 1.0, max(float(w @ (y - x)) / float(w.sum()), 0.0)
        keep = y <= OUTLIER_K ** 2 * (a_new * x + max(t_new, floor))
        done = abs(a_new - a) <= 1e-4 * max(a, 1e-9) and abs(t_new - t) <= 1e-4 * max(t, floor)
        a, t = float(a_new), float(t_new)
        if done:
            break
    return a, max(t, floor)


def total_sigmas(sigmas, residuals, n_params: int = 0, rule: str | None = None) -> list:
    """Per view (N_v,) σ_total px that a fit's corners are weighed with after a first fit weighted by ``sigmas``.

    sigmas : per view (N_v,) px (:func:`fit_sigmas`); residuals : per view (N_v, 2) px, the first fit's;
    n_params : its parameters. rule : as in :func:`fit_sigmas` (None: ``WEIGHTING``).
    ``"components"``, ``"view-components"``: σ_total² = a·σ² + τ² of :func:`variance_components` on the
    first fit's residuals (once: a second round, estimated again after the refit, moved the rendered
    benchmark's projection error by 0.0003 px over 48 calibrations).
    The other rules: σ² + τ² with τ² = max(0, s² − mean σ²), s² the residuals' variance per axis (Σ|r|² / 2N).
    """
    rule = WEIGHTING if rule is None else rule
    sig = [np.asarray(v, np.float64) for v in sigmas]
    if rule in ("components", "view-components"):
        a, t2 = variance_components(sig, residuals, n_params)
        return [np.sqrt(a * v * v + t2) for v in sig]
    res = np.concatenate([np.asarray(v, np.float64).reshape(-1, 2) for v in residuals])
    fin = np.isfinite(res).all(axis=1)
    s2 = float(np.sum(res[fin] ** 2) / (2 * max(fin.sum(), 1)))
    t2 = max(s2 - float(np.mean(np.concatenate(sig) ** 2)), 0.0)
    return [np.sqrt(v * v + t2) for v in sig]
