"""How much of a solved board flex to use: its sag, shrunk towards 0 by the noise of its own estimate.

The fit's covariance, behind the σ rule of :func:`~aicalib_tf.calib.flex.flex_problem`, takes every
corner's error as independent. Real corners' errors are not: the print, the light and the
detector's bias follow a view, so a view's corners err together. On OpenCV's 13 left-camera photos
halves of 6–7 views each found a flex within σ = 0.001 squares of its own, 8σ apart; over random
halves of the real sets the spread of the sag over the views is 2.5–5 times what that σ says.

What the views say about the sag is measured on the views themselves: each view is left out once
and the flex refitted (from the fit's intrinsics), and the V sags s₍ᵢ₎ give the jackknife standard
error σ_J = √((V − 1)/V · Σ (s₍ᵢ₎ − s̄)²), right whatever the errors' correlation within a view. A
refit that keeps no flex (its σ rule) counts with sag 0. The sag's standard error is
SE = max(σ_s, σ_J), σ_s the fit's own; with fewer than :data:`MIN_JACKKNIFE_VIEWS` views, σ_s alone.

Estimate: firm shrinkage of the sag s = w_x + w_y towards 0 (Gao and Bruce's, in standard errors
t = |s| / SE): nothing of it up to t = :data:`SHRINK_FROM` (the board flat), all of it from
t = :data:`SHRINK_TO` (a sag the views settle is not biased), linear in between,
ŝ = sign(s) · SE · SHRINK_TO · (t − SHRINK_FROM) / (SHRINK_TO − SHRINK_FROM); the flex is scaled with
it, ŵ = (ŝ / s) · w. The camera is refitted with the board held at ŵ (its intrinsics' covariance is the
solved fit's, the flex's uncertainty included); the flex's covariance is the fit's scaled so that the
sag's σ is SE. Unlike a keep-or-drop test at a confidence level, the estimate changes smoothly with
the views, so two sets of photos of one board whose sags lie either side of a threshold do not get
one a bent board and the other a flat one.

Measured (48 random half-splits of each real set, ``benchmarks/real_split_noise.py``'s columns;
geometric mean of the halves' projection difference against the flat board and against the flex as
solved): OpenCV's left photos 1.23 × flat (a 95% keep-or-drop test 1.14, as solved 1.53), the bent
udacity board 1.03 × as solved (the test 1.63, flat 2.6), the 185° fisheye 1.14 × flat (the test 1.20,
as solved 1.08). No rule tried is the best of flat and as solved on all three: soft thresholds at
0.25–1 SE, James–Stein's 1 − c²SE²/s² (c 0.5–1), normal and spike-and-slab priors of 0.005–0.1
squares each cost 15–60% on one set; a soft threshold of 0.5 SE (worst 1.16) misses the synthetic
sags of ``benchmarks/board_flex.py`` (0.2 px) by 0.5 SE of bias. Halves of 6–9 views cannot tell a
sag of 0.004 squares from noise (median t 0.6 on OpenCV's photos), and any flex they keep moves the lens.

A board shape (:mod:`aicalib_tf.calib.board_shape`) shrinks each of its terms by this rule
(:func:`confirm_shape`); with ``flex="auto"`` it is first tested as a whole (:func:`lens_shift`,
:func:`afford_cut`): kept only when it moves the lens over the boards by more than its own
leave-one-view-out noise allows (that module's docstring gives the rule and its measurements).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from aicalib_tf.calib import board_shape
from aicalib_tf.calib.board_shape import AUTO_MODE, SHAPE_MODE, SHAPE_SHRINK_FROM, SHAPE_TERMS, leave_one_out_fits, loo_shapes
from aicalib_tf.calib.bundle import CalibrationError
from aicalib_tf.calib.significance import t_quantile

__all__ = ["MIN_JACKKNIFE_VIEWS", "SHRINK_FROM", "SHRINK_TO", "AFFORD_LEVEL", "leave_one_out_sags", "jackknife_se",
           "AFFORD_FULL", "sag_estimate", "confirm_flex", "shape_estimate", "lens_shift", "afford_cut", "afford_part",
           "confirm_shape", "solve_fields"]

MIN_JACKKNIFE_VIEWS = 4  # every leave-one-out refit keeps at least 3 views
SHRINK_FROM = SHAPE_SHRINK_FROM  # t up to which the board is taken as flat (the module docstring's measurements)
SHRINK_TO = 4.0  # t from which the sag is used as solved
AFFORD_LEVEL = 0.90  # flex="auto": the one-sided Student-t level a shape's lens shift must pass (board_shape's docstring)
AFFORD_FULL = 2.0  # flex="auto": the shape is used whole from this many times the cut, scaled down linearly below


def leave_one_out_sags(views, refit) -> np.ndarray:
    """(V,) squares: the sag w_x + w_y of refit(views less view i, "sag") for each view i (0 where that
    refit keeps no flex). refit(views, mode) -> BundleResult with a unit square; CalibrationError propagates."""
    sags = []
    for i in range(len(views)):
        f = refit(views[:i] + views[i + 1:], "sag")
        sags.append(0.0 if f.flex is None else float(np.sum(f.flex)))
    return np.array(sags)


def _sag_sigma(fit) -> float:
    """squares: the fit's own σ of w_x + w_y (its (2, 2) flex covariance, unit square)."""
    c = np.asarray(fit.flex_covariance, np.float64)
    return float(np.sqrt(max(c[0, 0] + c[1, 1] + 2 * c[0, 1], 0.0)))


def jackknife_se(loo) -> float:
    """The jackknife standard error of an estimate from its (V,) leave-one-out values.

    >>> round(jackknife_se([0.0, 0.002, 0.0, 0.002]), 6)  # √(3/4 · 4 · 1e-6)
    0.001732
    """
    s = np.asarray(loo, np.float64)
    return float(np.sqrt((len(s) - 1) / len(s) * np.sum((s - s.mean()) ** 2)))


def sag_estimate(sag: float, sigma: float, loo=None, shrink_from: float = SHRINK_FROM) -> tuple[float, float, str]:
    """(ŝ, SE, how SE was found) for a solved sag (squares) with its fit's σ and the leave-one-out sags
    ``loo`` ((V,), or None with fewer than :data:`MIN_JACKKNIFE_VIEWS` views): the module docstring's rule
    (flat up to t = ``shrink_from``).

    >>> [round(v, 5) for v in sag_estimate(0.010, 0.001, 0.010 + 0.0005 * np.arange(8))[:2]]  # t 3.3
    [0.0097, 0.00303]
    >>> sag_estimate(-0.002, 0.001, -0.002 + 0.002 * np.arange(8))[0]  # t 0.17 on σ_J 0.012: flat
    0.0
    """
    se, how = float(sigma), "the fit's own σ"
    if loo is not None and len(loo) >= MIN_JACKKNIFE_VIEWS:
        jack = jackknife_se(loo)
        if jack > se:
            se, how = jack, f"from leaving each of the {len(loo)} views out"
    t = abs(sag) / se if se > 0 else float("inf")
    lo, hi = shrink_from, SHRINK_TO
    part = 0.0 if t <= lo else 1.0 if t >= hi else hi * (1 - lo / t) / (hi - lo)
    est = float(sag * part)
    return round(est, 12) + 0.0, se, how  # + 0.0: no -0.0


def confirm_flex(fit, views, refit, mode: str = SHAPE_MODE, image_size=None):
    """The fit with the flex of :func:`sag_estimate`: ``fit`` itself when it has no flex, else the views
    refitted with the board held at the estimate, or flat (``flex_note`` saying why) when it is 0.
    refit(views, "sag" | "off" | (w_x, w_y) held) -> BundleResult (unit square); a board shape's fit goes to
    :func:`confirm_shape` (``mode`` "auto": kept only when the views afford it, which needs ``image_size``)."""
    if getattr(fit, "flex", None) is None:
        return fit
    if len(fit.flex) > 2:  # a board shape (flex="shape" or "auto"): each of its terms shrunk
        return confirm_shape(fit, views, refit, image_size if mode == AUTO_MODE else None)
    try:
        loo = leave_one_out_sags(views, refit) if len(views) >= MIN_JACKKNIFE_VIEWS else None
    except CalibrationError as exc:
        why = f"not used: a fit leaving one view out failed ({exc}); the board is taken as flat"
        return dataclasses.replace(refit(views, "off"), flex_note=why)
    sag, sigma = float(np.sum(fit.flex)), _sag_sigma(fit)
    est, se, how = sag_estimate(sag, sigma, loo)
    if est == 0.0:
        why = (f"not used: the sag {sag:+.4f} squares is within {SHRINK_FROM:g} standard error of 0 (± {se:.4f}, "
               f"{how}); the board is taken as flat")
        return dataclasses.replace(refit(views, "off"), flex_note=why)
    w = np.asarray(fit.flex, np.float64) * (est / sag)
    try:
        held = refit(views, (float(w[0]), float(w[1])))
    except CalibrationError:  # the board held where the free fit went past: that fit stands
        return fit
    cov = np.asarray(fit.flex_covariance, np.float64) * (se / sigma) ** 2 if sigma > 0 else fit.flex_covariance
    return dataclasses.replace(held, flex=w, flex_covariance=cov, covariance=fit.covariance, flex_note="")


def shape_estimate(shape, sigma, loo=None, shrink_from: float | None = None) -> tuple[np.ndarray, np.ndarray, str]:
    """(ŵ (K,), SE (K,), how the SE were found): each term of ``shape`` (K,) squares with its fit's σ (K,)
    and leave-one-out values ``loo`` ((V, K), or None) shrunk by :func:`sag_estimate` (flat up to t =
    ``shrink_from``, default :data:`~aicalib_tf.calib.board_shape.SHAPE_SHRINK_FROM`).

    >>> est, se, _ = shape_estimate([0.02, 0.0003], [0.001, 0.001])
    >>> est.tolist(), se.tolist()
    ([0.02, 0.0], [0.001, 0.001])
    """
    w, s = np.asarray(shape, np.float64).ravel(), np.asarray(sigma, np.float64).ravel()
    use = loo is not None and len(loo) >= MIN_JACKKNIFE_VIEWS
    lo = board_shape.SHAPE_SHRINK_FROM if shrink_from is None else shrink_from
    found = [sag_estimate(w[k], s[k], np.asarray(loo)[:, k] if use else None, lo) for k in range(len(w))]
    how = f"from leaving each of the {len(loo)} views out" if use else "the fit's own σ"
    return np.array([f[0] for f in found]), np.array([f[1] for f in found]), how


def lens_shift(flat, shaped, loo, views, image_size) -> tuple[float, float]:
    """(shift, SE) px: how far a board shape moves the lens, and that lens's own noise, over the boards.

    Over the cells of a 32 × 24 grid that the views' corners cover (:func:`aicalib_tf.calib.diff.view_coverage`),
    rays through the cell centres by the ``flat`` fit's lens are projected by another lens after the rotation
    that best aligns the two (what comparing two calibrations fits out): d (M, 2) px for the ``shaped`` fit
    and d_i for each of the V leave-one-out shaped fits ``loo``. shift = RMS |d|; SE = the jackknife's
    √((V − 1)/V · Σ_i mean |d_i − d̄|²). Fits: BundleResult with ``model`` and ``intrinsics``."""
    from aicalib_tf.calib.diff import GRID, grid_points, view_coverage
    from aicalib_tf.geometry.lens import Lens
    from aicalib_tf.geometry.pose import best_rotation

    lens = lambda f: Lens.from_intrinsics(f.model, f.intrinsics, image_size)  # noqa: E731
    q = grid_points(image_size, GRID)[view_coverage([v.corners for v in views], image_size, GRID)]
    rays = lens(flat).unproject(q)
    ok = np.all(np.isfinite(rays), axis=1)
    q, rays = q[ok], rays[ok]

    def moved(f):
        other = lens(f)
        return other.project(rays @ best_rotation(other, rays, q).T) - q

    d, di = moved(shaped), np.array([moved(f) for f in loo])
    ok = np.all(np.isfinite(d), axis=1) & np.all(np.isfinite(di), axis=(0, 2))
    d, di = d[ok], di[:, ok]
    var = (len(di) - 1) / len(di) * float(np.sum(np.mean(np.sum((di - di.mean(axis=0)) ** 2, axis=2), axis=1)))
    return float(np.sqrt(np.mean(np.sum(d ** 2, axis=1)))), float(np.sqrt(var))


def afford_cut(n_views: int) -> float:
    """The shift / SE beyond which ``n_views`` views afford a board shape: Student's t at :data:`AFFORD_LEVEL`
    (one-sided) with n_views − 1 degrees of freedom, the jackknife SE's.

    >>> round(afford_cut(6), 2), round(afford_cut(20), 2)
    (1.48, 1.33)
    """
    return t_quantile(AFFORD_LEVEL, n_views - 1)


def afford_part(shift: float, se: float, n_views: int) -> float:
    """The part of a board shape ``n_views`` views afford, by its lens shift and SE (px, :func:`lens_shift`):
    0 up to z = shift / SE = c = :func:`afford_cut`, 1 from :data:`AFFORD_FULL` · c, (z − c) / ((AFFORD_FULL − 1) · c)
    between (the firm shrinkage of :func:`sag_estimate`, on the shape as a whole).

    >>> afford_part(0.1, 0.1, 6), afford_part(0.5, 0.1, 6), round(afford_part(0.2, 0.1, 6), 2)
    (0.0, 1.0, 0.36)
    """
    c = afford_cut(n_views)
    z = shift / se if se > 0 else float("inf")
    return float(np.clip((z - c) / ((AFFORD_FULL - 1.0) * c), 0.0, 1.0))


def _afford(fit, views, refit, fits, image_size):
    """flex="auto": (the flat fit, the part of the shape afforded, the words on its shift)."""
    flat = refit(views, "off")
    shift, se = lens_shift(flat, fit, fits, views, image_size)
    cut, part = afford_cut(len(views)), afford_part(shift, se, len(views))
    words = (f"it moves the projection over the boards {shift:.3f} px, {shift / se if se > 0 else float('inf'):.2f} "
             f"times its leave-one-view-out noise (± {se:.3f} px; {len(views)} views afford none of a shape up to "
             f"{cut:.2f}, all of it from {AFFORD_FULL * cut:.2f})")
    return flat, part, words


def confirm_shape(fit, views, refit, image_size=None):
    """The fit with the board shape of :func:`shape_estimate` (:mod:`aicalib_tf.calib.board_shape`): the views
    refitted with the board held there, or flat (``flex_note`` saying why) when every term is 0.
    refit(views, "shape" | "off" | (K,) squares held) -> BundleResult (unit square). With ``image_size``
    (width, height) px (flex="auto") the shape is first tested: kept only when it moves the lens by more than
    :func:`afford_cut` times its noise (:func:`lens_shift`), scaled by :func:`afford_part`, else the flat fit,
    the note saying why."""
    gate = image_size is not None
    if gate and len(views) < MIN_JACKKNIFE_VIEWS:
        return dataclasses.replace(refit(views, "off"), flex_note=(
            f"not used: {len(views)} views cannot measure the shape's noise (each view is left out once: at least "
            f"{MIN_JACKKNIFE_VIEWS}); the board is taken as flat"))
    try:
        fits = leave_one_out_fits(views, refit) if len(views) >= MIN_JACKKNIFE_VIEWS else None
    except CalibrationError as exc:
        why = f"not used: a fit leaving one view out failed ({exc}); the board is taken as flat"
        return dataclasses.replace(refit(views, "off"), flex_note=why)
    kept, part = "", 1.0
    if gate:
        flat, part, words = _afford(fit, views, refit, fits, image_size)
        if part == 0.0:
            return dataclasses.replace(flat, flex_note=f"not used: {words}; the board is taken as flat")
        kept = f"{'all' if part == 1.0 else f'{part:.0%}'} of it kept: {words}"
    w = np.asarray(fit.flex, np.float64)
    cov = np.asarray(fit.flex_covariance, np.float64)
    sigma = np.sqrt(np.maximum(np.diag(cov), 0.0))
    est, se, how = shape_estimate(w, sigma, None if fits is None else loo_shapes(fits))
    est = est * part
    lo = board_shape.SHAPE_SHRINK_FROM
    if not np.any(est):
        return dataclasses.replace(refit(views, "off"), flex_note=(
            f"not used: every term of the board's shape is within {lo:g} standard error of 0 ({how}); "
            "the board is taken as flat"))
    try:
        held = refit(views, tuple(float(v) for v in est))
    except CalibrationError:  # the board held where the free fit went past: that fit stands
        return fit
    scale = np.where(sigma > 0, se / np.where(sigma > 0, sigma, 1.0), 1.0)
    zero = [SHAPE_TERMS[k] for k in range(len(est)) if est[k] == 0.0]
    note = "; ".join(filter(None, [kept, f"taken as 0 (within {lo:g} standard error, {how}): {', '.join(zero)}"
                                   if zero else ""]))
    return dataclasses.replace(held, flex=est, flex_covariance=cov * np.outer(scale, scale), covariance=fit.covariance,
                               flex_note=note)


def solve_fields(fit, views) -> dict:
    """The Calibration fields of a solve's flex (fit with a unit square) and rejected corners:
    {"flex_note", "rejected_corners" ({view name: (K, 2) ids}), and "flex", "flex_covariance" when solved}."""
    flex, inliers = getattr(fit, "flex", None), getattr(fit, "inliers", None)
    out = {"flex_note": getattr(fit, "flex_note", ""), "rejected_corners": {}}
    if flex is not None:
        out.update(flex=np.asarray(flex, np.float64).copy(), flex_covariance=np.asarray(fit.flex_covariance, np.float64))
    if inliers is not None:
        for v, keep in zip(views, np.split(np.asarray(inliers, bool), np.cumsum([len(v.ids) for v in views])[:-1])):
            if not keep.all():
                out["rejected_corners"][v.name] = v.ids[~keep].copy()
    return out
