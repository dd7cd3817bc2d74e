"""Calibration from detected boards: views -> :class:`Calibration` for any lens model (numpy/OpenCV/scipy).

A view is one image's detected corners with their board ids (col, row). Full and partial boards
are equal citizens: each view has its own pose, so a board cut by the frame still constrains the
intrinsics. Board-frame points: corner (c, r) is at (c·s, r·s, 0) with s the square size, so
translations come out in the unit of ``square_size``.

Outlier views are rejected one at a time, worst first: after each calibration, a view whose RMS
reprojection error exceeds ``max(3 × median, 0.5 px)`` of the views' RMS is dropped and the rest
recalibrated. A misordered board sits tens of px off; corners pulled a few px by a refiner (as
``cornerSubPix`` does under strong distortion) bend the fit for every view, which is why only the
worst view goes at a time. At most a third of the views are rejected, never below ``min_views``.

The fit is one least-squares bundle over all views (:mod:`aicalib_tf.calib.bundle`). Inside each
solve (:mod:`aicalib_tf.calib.robust`) single outlying corners are rejected, corners are weighted by
their views' ``sigmas``, and with ``flex="auto"`` the board's shape is solved and used, shrunk towards
flat by the noise of its estimate (:mod:`aicalib_tf.calib.board_shape`). Starts: the
pinhole models from OpenCV's multi-start plumb_bob fit; the fisheye models (equidistant, ds, eucm) from a grid of focal lengths
(:func:`~aicalib_tf.calib.starts.fisheye_start`), so fisheye lenses need no guess. ``model="auto"``
picks the model by cross-validation over views (:mod:`aicalib_tf.calib.select`).

Parameter standard deviations and the covariance are σ²·(JᵀJ)⁻¹ at the minimum: they describe the
noise the data leaves, not systematic errors. A forced model whose fit is rank-deficient still
returns (pseudo-inverse covariance; ``meta["fit_note"]`` says so); under ``auto`` it gets a table row.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import cv2
import numpy as np

from aicalib_tf.calib.bundle import BundleResult, CalibrationError, param_names, poses_from_rays
from aicalib_tf.calib.flex_check import confirm_flex, solve_fields
from aicalib_tf.calib.opencv_start import opencv_start
from aicalib_tf.calib.robust import SolveOptions, solve
from aicalib_tf.calib.select import select_model
from aicalib_tf.calib.starts import convert_start, fisheye_start, widest_angle
from aicalib_tf.calib.view_checks import MIN_VIEW_CORNERS, duplicates, view_problem
from aicalib_tf.geometry.image_circle import ImageCircle
from aicalib_tf.geometry.lens import MODELS, N_COEFFS, Lens, get_model, model_from_ros, project
from aicalib_tf.geometry.pattern import board_points, check_lattice

__all__ = ["View", "Calibration", "CalibrationError", "calibrate_camera", "fit_views", "choose_model", "view_rms",
           "MIN_VIEW_CORNERS", "outlier_threshold"]

@dataclass(frozen=True)
class View:
    """One image's board.

    name : label for reports (usually the file name).
    corners : (N, 2) float (x, y) px.
    ids : (N, 2) int (col, row) of each corner on the board.
    relative : the ids are relative to the visible part (a board larger than the frame): they keep
        the lattice but not the place on the board, which a view's own pose absorbs.
    sigmas : (N,) float64 px, each corner's σ (isotropic, per axis): its weight in the fit is 1/σ
        (:mod:`aicalib_tf.calib.robust`); None: all corners equal.
    """

    name: str
    corners: np.ndarray
    ids: np.ndarray
    relative: bool = False
    sigmas: np.ndarray | None = None

    def __post_init__(self):
        c = np.asarray(self.corners, dtype=np.float64).reshape(-1, 2)
        i = np.asarray(self.ids, dtype=np.int64).reshape(-1, 2)
        if len(c) != len(i):
            raise ValueError(f"{self.name}: {len(c)} corners but {len(i)} ids")
        object.__setattr__(self, "corners", c)
        object.__setattr__(self, "ids", i)
        if self.sigmas is not None:
            sig = np.asarray(self.sigmas, dtype=np.float64).ravel()
            if len(sig) != len(c) or not np.all(np.isfinite(sig)) or np.any(sig <= 0):
                raise ValueError(f"{self.name}: sigmas must be {len(c)} finite values > 0 px, one per corner")
            object.__setattr__(self, "sigmas", sig)


@dataclass(frozen=True)
class Calibration:
    """A calibrated camera and how well the views support it.

    model : the lens model, a :data:`~aicalib_tf.geometry.lens.MODELS` name.
    K : (3, 3) float64 camera matrix, px. dist : (n,) the model's coefficients (5, 8, 12, 4 or 2), OpenCV order
    (Kalibr's for ds [ξ, α] and eucm [α, β]).
    image_size : (width, height) px. pattern_size : (cols, rows). square_size, square_unit: the
    board's square and its unit ("mm", "m", ... or "" when unitless); tvecs are in that unit.
    rms : overall RMS reprojection error, px (over all corners of the used views).
    views : names of the used views, in order; rvecs, tvecs (V, 3) float64 board-to-camera poses
    (``T_cam_board``); per_view_rms (V,) px; corner_counts (V,).
    std : {parameter name: standard deviation} for fx, fy, cx, cy and the distortion terms (names of
    ``lens.COEFF_NAMES``). covariance : (4 + n, 4 + n) covariance of [fx, fy, cx, cy, *dist] (σ²·(JᵀJ)⁻¹
    restricted to the intrinsics; None when unknown). model_table : the model choice, one dict per model
    {"model", "n_params", "rms", "cv_rms", "cv_se", "chosen", "note"}. quality : filled by calib.quality.
    rejected : {view name: reason} for views given but not used.
    meta : free-form provenance (detector, model sha256, flags) kept in the JSON file.
    image_circle : a circular fisheye's :class:`~aicalib_tf.geometry.image_circle.ImageCircle`
    (px; estimated from the photos), or None when the photos fill the frame or it is unknown.
    flex : (2,) the board flex (w_x, w_y) in squares (``flex="sag"``, :mod:`aicalib_tf.calib.flex`), or (7,) the
    board shape's terms (``flex="auto"``, :mod:`aicalib_tf.calib.board_shape`), or None when the board was taken as flat;
    flex_covariance : (K, K) squares²; flex_note : why there is no flex ("" otherwise; for a shape, the terms
    taken as 0).
    rejected_corners : {view name: (K, 2) ids (col, row)} of single corners rejected inside the solve.
    """

    K: np.ndarray
    dist: np.ndarray
    image_size: tuple[int, int]
    pattern_size: tuple[int, int]
    square_size: float
    rms: float
    views: tuple[str, ...]
    rvecs: np.ndarray
    tvecs: np.ndarray
    per_view_rms: np.ndarray
    corner_counts: np.ndarray
    std: dict
    rejected: dict = field(default_factory=dict)
    square_unit: str = ""
    meta: dict = field(default_factory=dict)
    model: str = "plumb_bob"
    covariance: np.ndarray | None = None
    model_table: tuple = ()
    quality: dict = field(default_factory=dict)
    image_circle: ImageCircle | None = None
    flex: np.ndarray | None = None
    flex_covariance: np.ndarray | None = None
    flex_note: str = ""
    rejected_corners: dict = field(default_factory=dict)

    @property
    def n_rejected_corners(self) -> int:
        """How many single corners the solve rejected."""
        return int(sum(len(v) for v in self.rejected_corners.values()))

    @property
    def lens(self) -> Lens:
        """The camera as a :class:`~aicalib_tf.geometry.lens.Lens` (model, K, dist, image_size)."""
        return Lens(self.model, self.K, self.dist, self.image_size)

    @property
    def fx(self) -> float:
        """K[0, 0], px."""
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        """K[1, 1], px."""
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        """K[0, 2], px."""
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        """K[1, 2], px."""
        return float(self.K[1, 2])

    def worst_view(self) -> tuple[str, float]:
        """(name, RMS px) of the used view with the largest reprojection error."""
        k = int(np.argmax(self.per_view_rms))
        return self.views[k], float(self.per_view_rms[k])


def view_rms(view: View, K, dist, rvec, tvec, square_size: float, model: str | None = None) -> tuple[float, np.ndarray]:
    """(RMS px, residuals (N, 2) px = detected − projected) of one view under a camera and pose.

    model : the lens model of ``dist``; None guesses a pinhole model from its length (4 means
    plumb_bob here: pass the model for a fisheye). Unprojectable corners give NaN.
    """
    model = model_from_ros("rational_polynomial", np.asarray(dist).size) if model is None else model
    R, _ = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))
    pts = board_points(view.ids, square_size) @ R.T + np.asarray(tvec, np.float64).ravel()
    res = view.corners - project(pts, model, K, dist)
    return float(np.sqrt(np.mean(np.sum(res * res, axis=1)))), res


def outlier_threshold(per_view_rms: np.ndarray) -> float:
    """The RMS (px) above which a view is an outlier: max(3 × median of the views' RMS, 0.5 px)."""
    return max(3.0 * float(np.median(np.asarray(per_view_rms, dtype=np.float64))), 0.5)


def _sort_views(views, pattern_size: tuple[int, int], image_size=None) -> tuple[list[View], dict[str, str]]:
    """Split views into the usable ones and {name: why} for the rest (:mod:`~aicalib_tf.calib.view_checks`;
    a view repeating an earlier one counts once); two views of one name are an error."""
    rejected: dict[str, str] = {}
    usable: list[View] = []
    seen: set[str] = set()
    for k, v in enumerate(views):
        view = v if isinstance(v, View) else View(getattr(v, "name", f"view{k}"), v.corners, v.ids,
                                                  bool(getattr(v, "relative", False)), getattr(v, "sigmas", None))
        if view.name in seen:  # per-view results and rejections are keyed by name
            raise ValueError(f"two views are named {view.name!r}; view names must be unique")
        seen.add(view.name)
        why = view_problem(view.corners, view.ids, pattern_size, image_size)
        if why is None:
            usable.append(view)
        else:
            rejected[view.name] = why
    repeats = duplicates(usable)
    for name, first in repeats.items():
        rejected[name] = f"the same view as {first} (every corner within 1 px): counted once"
    return [v for v in usable if v.name not in repeats], rejected


def _check_args(pattern_size, square_size, image_size, min_views) -> tuple[int, int]:
    pattern_size = check_lattice(pattern_size)
    if not np.isfinite(square_size) or square_size <= 0:
        raise ValueError(f"square_size must be a positive number, got {square_size!r}")
    if image_size is None or len(image_size) != 2 or min(int(s) for s in image_size) < 2:
        raise ValueError(f"image_size must be (width, height) px, got {image_size!r}")
    if min_views < 3:
        raise ValueError(f"min_views must be at least 3, got {min_views}")
    return pattern_size


def _usable_views(views, pattern_size, min_views, image_size=None) -> tuple[list[View], dict[str, str]]:
    usable, rejected = _sort_views(views, pattern_size, image_size)
    if len(usable) < min_views:
        raise CalibrationError(f"{len(usable)} usable views; need at least {min_views}"
                               + (f" ({len(rejected)} unusable: " + "; ".join(f"{n}: {r}" for n, r in rejected.items()) + ")"
                                  if rejected else ""))
    return usable, rejected


def _fit_model(model: str, views: list[View], square_size: float, image_size, start=None,
               fix_k3: bool = False, rank_strict: bool = True, options: SolveOptions | None = None) -> BundleResult:
    """One bundle fit of ``model`` to the views, from ``start`` (a Lens or Calibration) or from scratch.

    From scratch, the pinhole models (``START == "opencv"``) start from OpenCV's multi-start
    plumb_bob fit (extra coefficients 0) and the fisheye models from
    :func:`~aicalib_tf.calib.starts.fisheye_start`. ``fix_k3`` holds k3 at 0 (models with ``FIX_K3``).
    Raises CalibrationError naming the model when it cannot be fitted (a rank-deficient fit only
    when ``rank_strict``). options : the solve's board flex and corner rejection
    (:class:`~aicalib_tf.calib.robust.SolveOptions`; default: corners rejected, flat board).
    """
    spec = get_model(model)
    obj = [board_points(v.ids, square_size) for v in views]
    px = [v.corners for v in views]
    if spec.START == "layout":  # a model whose layout the views choose (the spline's knots: calib.splined_fit)
        from aicalib_tf.calib.splined_fit import fit_splined
        return fit_splined(model, obj, px, image_size, start.lens if isinstance(start, Calibration) else start,
                           rank_strict, views, options)
    free = np.ones(4 + N_COEFFS[model], bool)
    if fix_k3 and spec.FIX_K3 is not None:
        free[4 + spec.FIX_K3] = False
    if start is not None:
        lens0 = start.lens if isinstance(start, Calibration) else start
        intr = convert_start(lens0, model, widest_angle(lens0, px))
        poses = poses_from_rays(lens0, obj, px)
        if poses is None:
            raise CalibrationError(f"{model}: the start lens sees no board in front of it in some view")
    elif spec.START == "rays":
        intr, poses = fisheye_start(obj, px, image_size, free, model)
    else:
        K, dist, rvecs, tvecs = opencv_start(views, square_size, image_size, cv2.CALIB_FIX_K3 if fix_k3 else 0)
        intr = np.zeros(4 + N_COEFFS[model])
        intr[:4], intr[4:9] = (K[0, 0], K[1, 1], K[0, 2], K[1, 2]), dist[:5]
        poses = (rvecs, tvecs)
    intr = np.where(free, intr, 0.0)
    return solve(model, views, obj, px, intr, poses, free=free, rank_strict=rank_strict, options=options,
                 unit=square_size)


def _calibration(fit: BundleResult, views, pattern_size, square_size, image_size, rejected, square_unit,
                 meta, table=(), image_circle=None) -> Calibration:
    """The Calibration of a fit made with a unit square: translations scaled to ``square_size`` (the
    square size only scales the poses, so fitting with 1 keeps the numbers well conditioned for any unit)."""
    std = dict(zip(param_names(fit.model), np.sqrt(np.maximum(np.diag(fit.covariance), 0.0))))
    lens = Lens.from_intrinsics(fit.model, fit.intrinsics, image_size)
    return Calibration(
        K=lens.K, dist=lens.dist, image_size=(int(image_size[0]), int(image_size[1])),
        pattern_size=pattern_size, square_size=float(square_size), rms=fit.rms, views=tuple(v.name for v in views),
        rvecs=fit.rvecs, tvecs=fit.tvecs * float(square_size), per_view_rms=fit.per_view_rms,
        corner_counts=np.array([len(v.ids) for v in views]), std={k: float(v) for k, v in std.items()},
        rejected=dict(rejected), square_unit=square_unit, meta=dict(meta or {}, **({"fit_note": fit.note} if fit.note else {})), model=fit.model,
        covariance=fit.covariance, model_table=tuple(table), image_circle=image_circle, **solve_fields(fit, views))


def fit_views(views, pattern_size: tuple[int, int], square_size: float, image_size: tuple[int, int], model: str,
              *, start=None, fix_k3: bool = False, square_unit: str = "", meta: dict | None = None,
              flex: str = "off", reject_corners: bool = True) -> Calibration:
    """One fit of one lens model to the views: no view rejection, no model choice.

    views : sequence of :class:`View` (at least 3 usable; unusable ones land in ``rejected``).
    model : a :data:`~aicalib_tf.geometry.lens.MODELS` name. start : optional Lens or Calibration to
    start from (any model; its K and, within the pinhole family, its coefficients). Raises
    :class:`CalibrationError` naming the model when it cannot be fitted, ValueError for bad arguments.
    flex, reject_corners : the board flex and single-corner rejection inside the solve (:func:`calibrate_camera`).
    """
    pattern_size = _check_args(pattern_size, square_size, image_size, 3)
    if model not in MODELS:
        raise ValueError(f"unknown lens model {model!r}; choose from {', '.join(MODELS)}")
    usable, rejected = _usable_views(views, pattern_size, 3, image_size)
    opts = SolveOptions(pattern_size, flex, reject_corners)
    fit = _fit_model(model, usable, 1.0, image_size, start, fix_k3, False, opts)  # a unit square: tvecs scaled last
    fit = confirm_flex(fit, usable, _flex_refit(fit, image_size, fix_k3, opts), opts.flex, image_size)
    return _calibration(fit, usable, pattern_size, square_size, image_size, rejected, square_unit, meta)


def _flex_refit(fit: BundleResult, image_size, fix_k3, opts: SolveOptions):
    """(views, flex mode) -> a fit of ``fit``'s model from its intrinsics: the refits of :func:`confirm_flex`
    (mode "auto", "off", or a (w_x, w_y) squares the board is held at)."""
    start = Lens.from_intrinsics(fit.model, fit.intrinsics, image_size)
    held = lambda m: dataclasses.replace(opts, flex="off", flex_value=tuple(m))  # noqa: E731
    return lambda vs, mode: _fit_model(fit.model, vs, 1.0, image_size, start, fix_k3, False,
                                       dataclasses.replace(opts, flex=mode) if isinstance(mode, str) else held(mode))


def _resolve_model(model: str, rational: bool) -> str:
    if rational:
        if model not in ("auto", "rational_polynomial"):
            raise ValueError(f"rational=True asks for rational_polynomial but model={model!r}")
        return "rational_polynomial"
    if model != "auto" and model not in MODELS:
        raise ValueError(f"unknown lens model {model!r}; choose from auto, {', '.join(MODELS)}")
    return model


def _refit(model, usable, square_size, image_size, warm: BundleResult, fix_k3, opts=None) -> BundleResult:
    """Refit after a view was dropped: from the last fit, and from scratch for the pinhole models; the lower cost wins."""
    fits = [_fit_model(model, usable, square_size, image_size, Lens.from_intrinsics(model, warm.intrinsics, image_size),
                       fix_k3, False, opts)]
    if get_model(model).START == "opencv":
        try:
            fits.append(_fit_model(model, usable, square_size, image_size, None, fix_k3, False, opts))
        except CalibrationError:
            pass
    return min(fits, key=lambda f: f.cost)


def choose_model(views, pattern_size: tuple[int, int], image_size: tuple[int, int], models=MODELS, *,
                 fix_k3: bool = False, image_circle: ImageCircle | None = None, flex: str = "off",
                 reject_corners: bool = True) -> str:
    """The model ``auto`` chooses among ``models`` for these views (:mod:`aicalib_tf.calib.select`;
    no outlier rejection): e.g. each half of the views' choice. Raises CalibrationError when no model fits."""
    pattern_size = _check_args(pattern_size, 1.0, image_size, 3)
    usable, _ = _usable_views(views, pattern_size, 3, image_size)
    opts = SolveOptions(pattern_size, flex, reject_corners)
    return select_model(usable, 1.0, lambda vs, m, start: _fit_model(m, vs, 1.0, image_size, start, fix_k3, True, opts),
                        tuple(models), circle=image_circle, pattern_size=pattern_size)[1]


def calibrate_camera(views, pattern_size: tuple[int, int], square_size: float = 1.0,
                     image_size: tuple[int, int] | None = None, *, model: str = "auto", rational: bool = False,
                     fix_k3: bool = False, reject_outliers: bool = True, min_views: int = 3, square_unit: str = "",
                     meta: dict | None = None, image_circle: ImageCircle | None = None, flex: str = "off",
                     reject_corners: bool = True) -> Calibration:
    """Calibrate a camera from detected boards: a bundle fit of the lens model over all views.

    views : sequence of :class:`View` (or objects with ``corners``, ``ids`` and ``name``).
    pattern_size : (cols, rows) inner corners. square_size : > 0, in ``square_unit``.
    image_size : (width, height) px; required.
    model : "auto" (k-fold cross-validation over views picks the simplest model within one standard
    error of the best, see :mod:`aicalib_tf.calib.select`) or a lens model name to force it.
    rational : the same as model="rational_polynomial". fix_k3 : hold k3 at 0 (pinhole models).
    reject_outliers : drop views by the rule in the module docstring and refit.
    image_circle : a circular fisheye's image circle (:func:`~aicalib_tf.geometry.image_circle.estimate_image_circle`),
    kept in the Calibration; under ``auto`` a pinhole model is not eligible when the circle's rim lies
    at or near 90° off-axis. flex : "auto" (or "shape") solves the board's shape (sag, twist, cubics:
    :mod:`aicalib_tf.calib.board_shape`) with the camera and uses each term shrunk towards flat by the noise of
    its estimate, "sag" does so for the parabolic sag alone (:mod:`aicalib_tf.calib.flex`), "off" (default)
    takes the board as flat (their cost and gain on real photos: docs/benchmark.md). reject_corners :
    reject single outlying corners inside every solve (:mod:`aicalib_tf.calib.robust`); a view's
    ``sigmas`` weight its corners.
    Raises :class:`CalibrationError` with fewer than ``min_views`` usable views or when the model
    cannot be fitted, and ``ValueError`` for bad arguments (two views of one name among them).
    """
    pattern_size = _check_args(pattern_size, square_size, image_size, min_views)
    model = _resolve_model(model, rational)
    usable, rejected = _usable_views(views, pattern_size, min_views, image_size)
    opts = SolveOptions(pattern_size, flex, reject_corners)
    if model == "auto":
        table, model, fit = select_model(
            usable, 1.0, lambda vs, m, start: _fit_model(m, vs, 1.0, image_size, start, fix_k3, True, opts),
            circle=image_circle, pattern_size=pattern_size)
    else:
        fit = _fit_model(model, usable, 1.0, image_size, None, fix_k3, False, opts)  # a unit square: tvecs scaled last
        model = fit.model  # a model that chose its layout (a spline) refits with that layout
        table = ({"model": model, "n_params": fit.intrinsics.size, "rms": fit.rms, "cv_rms": float("nan"),
                  "cv_se": float("nan"), "chosen": True, "note": "forced"},)
    max_drop = len(usable) // 3
    while reject_outliers and len(usable) > min_views and max_drop > 0:
        thr = outlier_threshold(fit.per_view_rms)
        worst = int(np.argmax(fit.per_view_rms))
        if fit.per_view_rms[worst] <= thr:
            break
        rejected[usable[worst].name] = f"outlier: RMS {fit.per_view_rms[worst]:.2f} px > {thr:.2f} px"
        usable.pop(worst)
        max_drop -= 1
        fit = _refit(model, usable, 1.0, image_size, fit, fix_k3, opts)
    fit = confirm_flex(fit, usable, _flex_refit(fit, image_size, fix_k3, opts), opts.flex, image_size)
    return _calibration(fit, usable, pattern_size, square_size, image_size, rejected, square_unit, meta, table,
                        image_circle)
