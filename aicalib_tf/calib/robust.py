"""One calibration solve with per-corner weights, single-corner outlier rejection and the board flex.

Weights: a view's ``sigmas`` (one σ per corner, px) weight its corners by 1/σ' (:func:`view_sigmas`,
:func:`~aicalib_tf.calib.bundle.corner_weights`); views without them take the median σ of those that
have them (all equal when none has). σ' adds to the detector's σ the error it leaves unexplained, shared
by all corners (:func:`with_floor`, from a first fit with the σ alone; the rule and its figures:
:mod:`aicalib_tf.calib.weights`): on OpenCV's 13 left-camera photos the detector's σ have median 0.029 px
while the fit's residuals are 0.12 px per axis, so σ' is nearly equal for all corners; weighted by 1/σ
alone the fit moved fx by 0.86 px (2.3σ) and rejected 26 corners.

Corner outliers: after each fit every corner's normalised residual e = |r|·σ_ref/σ (px) is compared
with T = max(:data:`CORNER_K` · ŝ, :data:`CORNER_FLOOR_PX`), ŝ = median(e) / √(2 ln 2) over the
corners in use: the per-axis σ of a 2-D Gaussian residual, from its median norm (a Rayleigh median), so
a few gross errors do not inflate it. With Gaussian noise a corner passes T with probability
exp(−K²/2) = 4·10⁻⁵ (K = 4.5). Corners beyond T get weight 0 and the fit is redone from the last one,
until the set of rejected corners repeats (at most :data:`MAX_ROUNDS` fits); a corner rejected once is
tested again against each refit. Limits: a view keeps at least two thirds of its corners and
:data:`~aicalib_tf.calib.view_checks.MIN_VIEW_CORNERS` (a view worse than that is the view-rejection
rule's of :mod:`aicalib_tf.calib.fit`: none of its corners is rejected), and at most
:data:`MAX_CORNER_FRACTION` of all corners go, the worst first. The floor keeps the rule from cutting
into a fit whose residuals are far below a detector's precision.

Flex: see :mod:`aicalib_tf.calib.flex` (``flex="sag"``) and :mod:`aicalib_tf.calib.board_shape`
(``flex="auto"`` or ``"shape"``). The flex or shape is solved in every fit and,
when the views do not determine it, the last fit is redone with a flat board.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from aicalib_tf.calib.bundle import BundleResult, CalibrationError, bundle_adjust
from aicalib_tf.calib.board_shape import SHAPE_MODES, shape_problem
from aicalib_tf.calib.flex import FLEX_MODES, basis_of_views, flex_problem, mode_terms
from aicalib_tf.calib.view_checks import MIN_VIEW_CORNERS
from aicalib_tf.calib.weights import fit_sigmas, total_sigmas
from aicalib_tf.geometry.board_shape import shaped_points

__all__ = ["SolveOptions", "solve", "view_sigmas", "with_floor", "flag_corners", "CORNER_K", "CORNER_FLOOR_PX", "MAX_ROUNDS",
           "MAX_CORNER_FRACTION"]

CORNER_K = 4.5
CORNER_FLOOR_PX = 0.25
MAX_ROUNDS = 5
MAX_CORNER_FRACTION = 0.05
_RAYLEIGH_MEDIAN = float(np.sqrt(2.0 * np.log(2.0)))  # median of |r| / σ for a 2-D Gaussian r


@dataclass(frozen=True)
class SolveOptions:
    """How a calibration solve treats corners and the board.

    pattern_size : (cols, rows) inner corners, needed to solve the flex (None: flat board).
    flex : "auto" or "shape" (the board's shape of :mod:`aicalib_tf.calib.board_shape`), "sag" (the flex of
    :mod:`aicalib_tf.calib.flex`: solve it, keep it when determined) or "off". reject_corners : reject single corners.
    flex_value : with flex "off", the board held flexed by this (w_x, w_y) squares, or shaped by these K
    shape terms, instead of flat (the estimate of :mod:`aicalib_tf.calib.flex_check`; needs ``pattern_size``),
    or None.
    """

    pattern_size: tuple[int, int] | None = None
    flex: str = "auto"
    reject_corners: bool = True
    flex_value: tuple[float, ...] | None = None

    def __post_init__(self):
        if self.flex not in FLEX_MODES:
            raise ValueError(f"flex must be one of {', '.join(FLEX_MODES)}, got {self.flex!r}")
        if self.flex_value is not None and (self.flex != "off" or self.pattern_size is None):
            raise ValueError("flex_value holds the board's flex: it needs flex='off' and a pattern_size")


def view_sigmas(views) -> list | None:
    """Per-view (N_v,) σ px for :func:`~aicalib_tf.calib.bundle.bundle_adjust`, or None when no view has
    any, by the rule every fit shares (:func:`aicalib_tf.calib.weights.fit_sigmas`; views without their own
    take the median of the others')."""
    return fit_sigmas([getattr(v, "sigmas", None) for v in views], [len(v.ids) for v in views])


def with_floor(sigmas, fit: BundleResult) -> list:
    """Per-view σ' px with the error the detector's σ do not explain (lens-model misfit, print, focus) added
    from ``fit``'s residuals, by the rule every fit shares (:func:`aicalib_tf.calib.weights.total_sigmas`;
    the fit's parameters: its intrinsics, when it has them, and 6 a view). Without it a corner whose σ is ten
    times below the residuals' scale gets a hundred times the weight of its neighbours for an error it does
    not have (module docstring)."""
    n_params = np.size(getattr(fit, "intrinsics", ())) + 6 * len(fit.residuals)
    return total_sigmas(sigmas, fit.residuals, n_params)


def flag_corners(fit: BundleResult, sigmas) -> np.ndarray:
    """(N,) bool over all corners: True where a corner is kept by the rule of the module docstring.

    fit : the last fit (its ``inliers`` are the corners in use). sigmas : per-view σ or None."""
    res = np.concatenate(fit.residuals)
    n = len(res)
    w = np.ones(n)
    if sigmas is not None:
        sig = np.concatenate([np.asarray(s, np.float64) for s in sigmas])
        w = np.median(sig) / sig
    e = np.linalg.norm(res, axis=1) * w
    e = np.where(np.isfinite(e), e, np.inf)
    used = np.ones(n, bool) if fit.inliers is None else fit.inliers
    thr = max(CORNER_K * float(np.median(e[used])) / _RAYLEIGH_MEDIAN, CORNER_FLOOR_PX)
    out = e > thr
    starts = np.cumsum([0] + [len(r) for r in fit.residuals])
    for a, b in zip(starts[:-1], starts[1:]):
        if out[a:b].sum() > (b - a) // 3 or (b - a) - out[a:b].sum() < MIN_VIEW_CORNERS:
            out[a:b] = False  # the view as a whole is off: the view-rejection rule's case
    cap = int(MAX_CORNER_FRACTION * n)
    if out.sum() > cap:
        worst = np.argsort(np.where(out, -e, 0.0), kind="stable")[:cap]
        out[:] = False
        out[worst] = True
    return ~out


def _refit(fit: BundleResult, obj, px, free, sigmas, inliers, basis, rank_strict, max_nfev=None) -> BundleResult:
    flex = fit.flex if (basis is not None and fit.flex is not None) else None
    return bundle_adjust(fit.model, obj, px, fit.intrinsics, fit.rvecs, fit.tvecs, free=free, sigmas=sigmas,
                         inliers=inliers, flex_basis=basis, flex=flex, rank_strict=rank_strict, max_nfev=max_nfev)


def solve(model: str, views, obj, px, intrinsics, poses, *, free, rank_strict: bool,
          options: SolveOptions | None = None, unit: float = 1.0, max_nfev: int | None = None,
          inliers=None) -> BundleResult:
    """Fit ``model`` to the views with the options' flex and corner rejection; returns the final fit, its
    ``flex_note`` saying why the flex is not used ("" when it is, or when ``flex="off"``).

    views : the View list (ids, sigmas, relative); obj, px : their board points (in ``unit`` per square)
    and corners; intrinsics, poses : the start ((4 + n,), (rvecs, tvecs)); max_nfev : each fit's evaluation
    cap (None: to convergence; a spline's fit caps it); inliers : (N,) bool, the corners the first fit uses
    (None: all; every corner is tested again after it). Raises CalibrationError as
    :func:`~aicalib_tf.calib.bundle.bundle_adjust` does.
    """
    options = options or SolveOptions()
    if options.flex_value is not None:  # the board held flexed: its points moved, nothing more solved
        obj = [shaped_points(o, options.pattern_size, options.flex_value, unit) for o in obj]
    sigmas = view_sigmas(views)
    basis, why = ((None, "") if options.flex == "off"
                  else basis_of_views(views, options.pattern_size, mode_terms(options.flex)))
    fit = None
    if basis is not None:
        try:
            fit = bundle_adjust(model, obj, px, intrinsics, *poses, free=free, sigmas=sigmas, flex_basis=basis,
                                rank_strict=True, max_nfev=max_nfev, inliers=inliers)
        except CalibrationError:
            basis, why = None, "not determined by these views"
    if fit is None:
        fit = bundle_adjust(model, obj, px, intrinsics, *poses, free=free, sigmas=sigmas, rank_strict=rank_strict,
                            max_nfev=max_nfev, inliers=inliers)
    if sigmas is not None:  # the error the σ's do not explain, shared by every corner, then the weighted refit
        sigmas = with_floor(sigmas, fit)
        fit = _refit(fit, obj, px, free, sigmas, inliers, basis, rank_strict, max_nfev)
    seen = set()
    for _ in range(MAX_ROUNDS - 1 if options.reject_corners else 0):
        keep = flag_corners(fit, sigmas)
        key = keep.tobytes()
        if key in seen or (fit.inliers is None and keep.all()) or (fit.inliers is not None
                                                                    and np.array_equal(keep, fit.inliers)):
            break
        seen.add(key)
        fit = _refit(fit, obj, px, free, sigmas, None if keep.all() else keep, basis, rank_strict, max_nfev)
    if basis is not None:
        why = (shape_problem if options.flex in SHAPE_MODES else flex_problem)(fit.flex, fit.flex_covariance, unit)
        if why:
            fit = _refit(fit, obj, px, free, sigmas, fit.inliers, None, rank_strict, max_nfev)
    return dataclasses.replace(fit, flex_note=why)
