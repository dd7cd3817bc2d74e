"""Zhang calibration from detected boards: views -> :class:`Calibration` (pure numpy/OpenCV).

A view is one image's detected corners with their board ids (col, row). Full and partial boards
are equal citizens: each view has its own pose, so a board cut by the frame still constrains the
intrinsics. Board-frame points: corner (c, r) is at (c·s, r·s, 0) with s the square size, so
translations come out in the unit of ``square_size``.

Outlier views are rejected one at a time, worst first: after each calibration, a view whose RMS
reprojection error exceeds ``max(3 × median, 0.5 px)`` of the views' RMS is dropped and the rest
recalibrated. A misordered board sits tens of px off; corners pulled a few px by a refiner (as
``cornerSubPix`` does under strong distortion) bend the fit for every view, which is why only the
worst view goes at a time. At most a third of the views are rejected, never below ``min_views``.

Camera parameter standard deviations come from ``cv2.calibrateCameraExtended`` (the diagonal of
the Levenberg–Marquardt covariance scaled by the residual variance): they describe the noise the
data leaves, not systematic errors.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from aicalib_tf.geometry.pattern import board_points, check_pattern

__all__ = ["View", "Calibration", "CalibrationError", "calibrate_camera", "view_rms", "INTRINSIC_NAMES", "MIN_VIEW_CORNERS", "outlier_threshold"]

INTRINSIC_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")
MIN_VIEW_CORNERS = 6  # and spanning ≥ 2 rows and ≥ 2 columns: a homography needs a 2-D spread
_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)


class CalibrationError(ValueError):
    """The views cannot give a calibration (too few usable views, bad sizes, ...)."""


@dataclass(frozen=True)
class View:
    """One image's board.

    name : label for reports (usually the file name).
    corners : (N, 2) float (x, y) px.
    ids : (N, 2) int (col, row) of each corner on the board.
    """

    name: str
    corners: np.ndarray
    ids: np.ndarray

    def __post_init__(self):
        c = np.asarray(self.corners, dtype=np.float64).reshape(-1, 2)
        i = np.asarray(self.ids, dtype=np.int64).reshape(-1, 2)
        if len(c) != len(i):
            raise ValueError(f"{self.name}: {len(c)} corners but {len(i)} ids")
        object.__setattr__(self, "corners", c)
        object.__setattr__(self, "ids", i)


@dataclass(frozen=True)
class Calibration:
    """A calibrated camera and how well the views support it.

    K : (3, 3) float64 camera matrix, px. dist : (5,) or (8,) OpenCV distortion coefficients.
    image_size : (width, height) px. pattern_size : (cols, rows). square_size, square_unit: the
    board's square and its unit ("mm", "m", ... or "" when unitless); tvecs are in that unit.
    rms : overall RMS reprojection error, px (over all corners of the used views).
    views : names of the used views, in order; rvecs, tvecs (V, 3) float64 board-to-camera poses
    (``T_cam_board``); per_view_rms (V,) px; corner_counts (V,).
    std : {parameter name: standard deviation} for fx, fy, cx, cy and the distortion terms.
    rejected : {view name: reason} for views given but not used.
    meta : free-form provenance (detector, model sha256, flags) kept in the JSON file.
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


def view_rms(view: View, K, dist, rvec, tvec, square_size: float) -> tuple[float, np.ndarray]:
    """(RMS px, residuals (N, 2) px = detected − projected) of one view under a camera and pose."""
    proj, _ = cv2.projectPoints(board_points(view.ids, square_size), np.asarray(rvec, np.float64),
                                np.asarray(tvec, np.float64), np.asarray(K, np.float64), np.asarray(dist, np.float64))
    res = view.corners - proj.reshape(-1, 2)
    return float(np.sqrt(np.mean(np.sum(res * res, axis=1)))), res


def _usable(view: View, pattern_size: tuple[int, int]) -> str | None:
    """Why a view cannot be used, or None."""
    cols, rows = pattern_size
    if len(view.ids) < MIN_VIEW_CORNERS:
        return f"only {len(view.ids)} corners (need {MIN_VIEW_CORNERS})"
    if (view.ids < 0).any() or (view.ids[:, 0] >= cols).any() or (view.ids[:, 1] >= rows).any():
        return f"corner ids outside the {cols}x{rows} pattern"
    if len(np.unique(view.ids, axis=0)) != len(view.ids):
        return "duplicate corner ids"
    if len(np.unique(view.ids[:, 0])) < 2 or len(np.unique(view.ids[:, 1])) < 2:
        return "corners on a single line"
    if not np.isfinite(view.corners).all():
        return "non-finite corner coordinates"
    return None


def _n_dist(flags: int) -> int:
    """How many distortion coefficients a fit with these OpenCV flags estimates."""
    return 8 if flags & cv2.CALIB_RATIONAL_MODEL else 5


def _flags(rational: bool, fix_k3: bool) -> int:
    flags = cv2.CALIB_RATIONAL_MODEL if rational else 0
    if fix_k3:
        flags |= cv2.CALIB_FIX_K3
    return flags


def _starts(image_size, warm) -> list:
    """Initial (K, dist) guesses: OpenCV's own (None), a warm start, and three pinhole fields of view.

    OpenCV initialises from homographies that ignore distortion; under strong barrel distortion
    Levenberg–Marquardt can then settle in a wrong minimum (measured: fx +28% on a data_gen
    sequence whose true fx it finds from a better start). The fit with the lowest RMS wins.
    """
    w, h = (float(s) for s in image_size)
    starts = [None] if warm is None else [None, warm]
    for hfov in (50.0, 80.0, 110.0):
        f = 0.5 * w / np.tan(np.radians(hfov) / 2)
        starts.append((np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]]), None))
    return starts


def _run(views: list[View], square_size: float, image_size, flags: int, warm=None):
    """Calibrate from several starts; returns the lowest-RMS fit and the per-view RMS."""
    obj = [board_points(v.ids, square_size).astype(np.float32) for v in views]
    img = [v.corners.astype(np.float32).reshape(-1, 1, 2) for v in views]
    size = tuple(int(s) for s in image_size)
    best, last_error = None, None
    n_dist = _n_dist(flags)
    for start in _starts(image_size, warm):
        try:
            if start is None:
                fit = cv2.calibrateCameraExtended(obj, img, size, None, None, flags=flags, criteria=_CRITERIA)
            else:
                K0 = start[0].copy()
                d0 = np.zeros(n_dist) if start[1] is None else np.asarray(start[1], np.float64).copy()
                fit = cv2.calibrateCameraExtended(obj, img, size, K0, d0, flags=flags | cv2.CALIB_USE_INTRINSIC_GUESS,
                                                  criteria=_CRITERIA)
        except cv2.error as exc:
            last_error = exc
            continue
        if np.isfinite(fit[0]) and (best is None or fit[0] < best[0]):
            best = fit
    if best is None:
        raise CalibrationError(f"OpenCV could not calibrate from {len(views)} views: {getattr(last_error, 'err', last_error)}")
    rms, K, dist, rvecs, tvecs, std_in, _, _ = best
    rvecs = np.asarray(rvecs, np.float64).reshape(-1, 3)
    tvecs = np.asarray(tvecs, np.float64).reshape(-1, 3)
    per_view = np.array([view_rms(v, K, dist, r, t, square_size)[0] for v, r, t in zip(views, rvecs, tvecs)])
    return float(rms), K, dist.ravel(), rvecs, tvecs, np.asarray(std_in).ravel(), per_view


def outlier_threshold(per_view_rms: np.ndarray) -> float:
    """The RMS (px) above which a view is an outlier: max(3 × median of the views' RMS, 0.5 px)."""
    return max(3.0 * float(np.median(np.asarray(per_view_rms, dtype=np.float64))), 0.5)


def _sort_views(views, pattern_size: tuple[int, int]) -> tuple[list[View], dict[str, str]]:
    """Split views into the usable ones and {name: why} for the rest; two views of one name are an error."""
    rejected: dict[str, str] = {}
    usable: list[View] = []
    seen: set[str] = set()
    for k, v in enumerate(views):
        view = v if isinstance(v, View) else View(getattr(v, "name", f"view{k}"), v.corners, v.ids)
        if view.name in seen:  # per-view results and rejections are keyed by name
            raise ValueError(f"two views are named {view.name!r}; view names must be unique")
        seen.add(view.name)
        why = _usable(view, pattern_size)
        if why is None:
            usable.append(view)
        else:
            rejected[view.name] = why
    return usable, rejected


def calibrate_camera(views, pattern_size: tuple[int, int], square_size: float = 1.0,
                     image_size: tuple[int, int] | None = None, *, rational: bool = False, fix_k3: bool = False,
                     reject_outliers: bool = True, min_views: int = 3, square_unit: str = "",
                     meta: dict | None = None) -> Calibration:
    """Calibrate a camera from detected boards (Zhang's method, ``cv2.calibrateCameraExtended``).

    views : sequence of :class:`View` (or objects with ``corners``, ``ids`` and ``name``).
    pattern_size : (cols, rows) inner corners. square_size : > 0, in ``square_unit``.
    image_size : (width, height) px; required.
    rational : fit OpenCV's 8-coefficient rational model. fix_k3 : hold k3 at 0.
    reject_outliers : drop views by the rule in the module docstring and recalibrate.
    Raises :class:`CalibrationError` with fewer than ``min_views`` usable views, and ``ValueError``
    for bad arguments (two views of one name among them).
    """
    pattern_size = check_pattern(pattern_size)
    if not np.isfinite(square_size) or square_size <= 0:
        raise ValueError(f"square_size must be a positive number, got {square_size!r}")
    if image_size is None or len(image_size) != 2 or min(int(s) for s in image_size) < 2:
        raise ValueError(f"image_size must be (width, height) px, got {image_size!r}")
    if min_views < 3:
        raise ValueError(f"min_views must be at least 3, got {min_views}")
    usable, rejected = _sort_views(views, pattern_size)
    if len(usable) < min_views:
        raise CalibrationError(f"{len(usable)} usable views; need at least {min_views}"
                               + (f" ({len(rejected)} unusable: " + "; ".join(f"{n}: {r}" for n, r in rejected.items()) + ")"
                                  if rejected else ""))
    flags = _flags(rational, fix_k3)
    max_drop = len(usable) // 3
    warm = None
    while True:
        rms, K, dist, rvecs, tvecs, std_in, per_view = _run(usable, square_size, image_size, flags, warm)
        warm = (K, dist)
        if not reject_outliers or len(usable) <= min_views or max_drop == 0:
            break
        thr = outlier_threshold(per_view)
        worst = int(np.argmax(per_view))
        if per_view[worst] <= thr:
            break
        rejected[usable[worst].name] = f"outlier: RMS {per_view[worst]:.2f} px > {thr:.2f} px"
        usable.pop(worst)
        max_drop -= 1
    n_dist = _n_dist(flags)
    names = INTRINSIC_NAMES[: 4 + n_dist]
    std = {n: float(s) for n, s in zip(names, std_in[: len(names)])}
    return Calibration(
        K=np.asarray(K, np.float64), dist=np.asarray(dist[:n_dist], np.float64),
        image_size=(int(image_size[0]), int(image_size[1])), pattern_size=pattern_size,
        square_size=float(square_size), rms=rms, views=tuple(v.name for v in usable), rvecs=rvecs, tvecs=tvecs,
        per_view_rms=per_view, corner_counts=np.array([len(v.ids) for v in usable]), std=std, rejected=rejected,
        square_unit=square_unit, meta=dict(meta or {}),
    )
