"""Pure metric functions on arrays (no file access, no TensorFlow).

Corner arrays are (N, 2) float (x, y) px in OpenCV order (index = r·cols + c).
"""

from __future__ import annotations

import cv2
import numpy as np

from aicalib_tf.geometry.camera import model_for_dist
from aicalib_tf.geometry.lens import Lens
from aicalib_tf.geometry.pattern import board_symmetries

__all__ = ["WRONG_PX", "align_to_truth", "corner_error_stats", "calibration_errors", "board_detection_outcome", "partial_board_stats", "detection_agreement", "OUTCOMES"]

WRONG_PX = 2.0  # DESIGN.md: a full board with any corner further from the truth is a wrong detection


def align_to_truth(detected: np.ndarray, truth: np.ndarray, pattern_size: tuple[int, int]) -> np.ndarray:
    """Reorder a full detection by the board symmetry that best matches the truth.

    detected, truth : (cols·rows, 2) px. Returns the reordered (cols·rows, 2) detection.
    Raises ``ValueError`` if the sizes disagree with ``pattern_size``.
    """
    det = np.asarray(detected, dtype=np.float64).reshape(-1, 2)
    gt = np.asarray(truth, dtype=np.float64).reshape(-1, 2)
    n = int(pattern_size[0]) * int(pattern_size[1])
    if det.shape[0] != n or gt.shape[0] != n:
        raise ValueError(f"need {n} corners for pattern {tuple(pattern_size)}, got {det.shape[0]} and {gt.shape[0]}")
    best = min(board_symmetries(pattern_size), key=lambda p: float(np.sum((det[p] - gt) ** 2)))
    return det[best]


def corner_error_stats(errors: np.ndarray) -> dict:
    """Summary of per-corner errors (px): count, median, RMSE, p95, p99, max."""
    e = np.asarray(errors, dtype=np.float64).ravel()
    if e.size == 0:
        return {"count": 0, "median": float("nan"), "rmse": float("nan"), "p95": float("nan"), "p99": float("nan"), "max": float("nan")}
    return {
        "count": int(e.size),
        "median": float(np.median(e)),
        "rmse": float(np.sqrt(np.mean(e * e))),
        "p95": float(np.percentile(e, 95)),
        "p99": float(np.percentile(e, 99)),
        "max": float(np.max(e)),
    }


def _field_points(image_size, grid, lens_true: Lens, max_theta_true: float | None) -> np.ndarray:
    """(N, 2) grid pixels over the image where the true lens is defined (inside its circle)."""
    w, h = image_size
    gx, gy = np.meshgrid(np.linspace(0, w - 1, grid[0]), np.linspace(0, h - 1, grid[1]))
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    rays = lens_true.unproject(pts)
    ok = np.all(np.isfinite(rays), axis=1)
    if max_theta_true is not None:
        with np.errstate(invalid="ignore"):
            ok &= np.arctan2(np.hypot(rays[:, 0], rays[:, 1]), rays[:, 2]) <= max_theta_true
    return pts[ok]


def _hull_mask(pts: np.ndarray, seen) -> np.ndarray:
    hull = cv2.convexHull(np.asarray(seen, np.float32).reshape(-1, 1, 2))
    return np.array([cv2.pointPolygonTest(hull, (float(x), float(y)), False) >= 0 for x, y in pts], dtype=bool)


def _stats(prefix: str, d: np.ndarray) -> dict:
    return {f"{prefix}_mean_px": float(d.mean()) if d.size else float("nan"),
            f"{prefix}_max_px": float(d.max()) if d.size else float("nan")}


def calibration_errors(K: np.ndarray, dist: np.ndarray, K_true: np.ndarray, dist_true: np.ndarray,
                       image_size: tuple[int, int], *, model: str | None = None, model_true: str | None = None,
                       max_theta_true: float | None = None, grid: tuple[int, int] = (32, 24),
                       seen: np.ndarray | None = None) -> dict:
    """An estimated camera against the true one (DESIGN.md's calibration metrics).

    K, K_true : (3, 3). dist, dist_true : coefficients of ``model`` / ``model_true`` (lens
    model names of :mod:`aicalib_tf.geometry.lens`; None: the pinhole model of that length, so
    the two sides may be different models). image_size : (width, height) px. grid : (nx, ny)
    sample pixels spread over the image; max_theta_true : the true lens' image circle (radians
    off-axis; None: wherever the true model is defined). Returns:

    * fx_pct, fy_pct (signed relative focal errors, %), pp_px (principal-point distance, px);
    * proj_err_mean_px / proj_err_max_px: the projection error field, |project_est(unproject_true(p)) - p|
      over the grid pixels the true lens images (for a circular fisheye: the image circle);
      proj_err_points counts them, proj_err_fail_frac is the fraction the estimate cannot project
      at all (e.g. rays past 90° for a pinhole estimate; left out of the mean and max);
    * dist_field_mean_px / dist_field_max_px: how far apart the two models' undistortion fields are
      (only where both give a ray in front of the 90° plane);
    * with ``seen`` ((M, 2) px, e.g. every visible true corner of every view) the same over the grid
      points inside their convex hull, the area the boards covered: proj_err_seen_mean_px,
      proj_err_seen_max_px, dist_field_seen_mean_px, dist_field_seen_max_px.
    """
    K = np.asarray(K, dtype=np.float64)
    Kt = np.asarray(K_true, dtype=np.float64)
    model = model or model_for_dist(dist)
    model_true = model_true or model_for_dist(dist_true)
    est = Lens(model, K, dist, image_size)
    true = Lens(model_true, Kt, dist_true, image_size)
    pts = _field_points(image_size, grid, true, max_theta_true)
    back = est.project(true.unproject(pts))
    proj_ok = np.all(np.isfinite(back), axis=1)
    proj = np.linalg.norm(back - pts, axis=1)
    f_est, ok_est = est.distortion_field(pts)
    f_true, ok_true = true.distortion_field(pts)
    field_ok = ok_est & ok_true
    dfield = np.linalg.norm(f_est - f_true, axis=1)
    out = {
        "fx_pct": float(100.0 * (K[0, 0] - Kt[0, 0]) / Kt[0, 0]),
        "fy_pct": float(100.0 * (K[1, 1] - Kt[1, 1]) / Kt[1, 1]),
        "pp_px": float(np.hypot(K[0, 2] - Kt[0, 2], K[1, 2] - Kt[1, 2])),
        **_stats("proj_err", proj[proj_ok]),
        "proj_err_points": int(len(pts)),
        "proj_err_fail_frac": float(1.0 - proj_ok.mean()) if len(pts) else float("nan"),
        **_stats("dist_field", dfield[field_ok]),
        "dist_field_points": int(field_ok.sum()),
    }
    if seen is not None:
        inside = _hull_mask(pts, seen)
        out.update(_stats("proj_err_seen", proj[proj_ok & inside]))
        out.update(_stats("dist_field_seen", dfield[field_ok & inside]))
    return out


# --- detection outcomes -------------------------------------------------------------------------

OUTCOMES = ("hit", "wrong", "miss")


def board_detection_outcome(detected, truth: np.ndarray, pattern_size: tuple[int, int],
                            wrong_px: float = WRONG_PX) -> tuple[str, np.ndarray]:
    """Classify one full-board detection against the truth (DESIGN.md's detection rate).

    detected : (cols·rows, 2) px in any admissible board order, or None when no full board was
        returned. truth : (cols·rows, 2) px, OpenCV order.
    Returns (outcome, errors): ``"miss"`` (nothing returned; errors empty), ``"hit"`` (every
    corner within ``wrong_px`` px after the best board symmetry) or ``"wrong"`` (a full board
    with any corner further off — including corners that are not on the board at all);
    errors is the (cols·rows,) px distance of each aligned corner to its true position.
    """
    if wrong_px <= 0:
        raise ValueError(f"wrong_px must be > 0, got {wrong_px}")
    gt = np.asarray(truth, dtype=np.float64).reshape(-1, 2)
    if detected is None:
        n = int(pattern_size[0]) * int(pattern_size[1])
        if gt.shape[0] != n:
            raise ValueError(f"need {n} true corners for pattern {tuple(pattern_size)}, got {gt.shape[0]}")
        return "miss", np.zeros(0)
    errors = np.linalg.norm(align_to_truth(detected, gt, pattern_size) - gt, axis=1)
    return ("hit" if float(errors.max()) <= wrong_px else "wrong"), errors


def _inverse_symmetries(pattern_size: tuple[int, int]) -> list[np.ndarray]:
    """For each board symmetry, the map detected index -> true index (inverse permutation)."""
    return [np.argsort(p) for p in board_symmetries(pattern_size)]


def partial_board_stats(corners: np.ndarray, ids: np.ndarray, truth: np.ndarray, visible: np.ndarray,
                        pattern_size: tuple[int, int], max_px: float = WRONG_PX) -> dict:
    """Score a (possibly partial) board: how many visible corners it recovered with the right id.

    corners : (N, 2) px. ids : (N, 2) int (col, row) of each detected corner.
    truth : (cols·rows, 2) px, OpenCV order. visible : (cols·rows,) bool, the corners a detector
    could see. A detected corner is *correct* when its id, read under the single board symmetry
    (identity, 180°, and 90° turns for square patterns) that gives the most correct corners,
    names a visible true corner within ``max_px`` px (each true corner counted once, the closest
    detection winning). A full detection is the case N = cols·rows.
    Returns visible (count), detected (N), correct, hidden_found (detections with the right id
    within ``max_px`` of a true corner flagged invisible, e.g. a full board drawn through an
    occluder: neither correct nor wrong), wrong_ids (= N − correct − hidden_found), recall
    (= correct / visible; NaN when nothing is visible), symmetry (index into
    :func:`board_symmetries`) and errors ((correct,) px of the correct corners).
    """
    cols, rows = (int(v) for v in pattern_size)
    n = cols * rows
    pts = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    ij = np.asarray(ids).reshape(-1, 2)
    gt = np.asarray(truth, dtype=np.float64).reshape(-1, 2)
    vis = np.asarray(visible, dtype=bool).ravel()
    if gt.shape[0] != n or vis.shape[0] != n:
        raise ValueError(f"need {n} true corners and visibility flags for pattern {(cols, rows)}, "
                         f"got {gt.shape[0]} and {vis.shape[0]}")
    if ij.shape[0] != pts.shape[0]:
        raise ValueError(f"corners and ids disagree: {pts.shape[0]} corners, {ij.shape[0]} ids")
    if max_px <= 0:
        raise ValueError(f"max_px must be > 0, got {max_px}")
    ij = ij.astype(np.int64)
    inside = (ij[:, 0] >= 0) & (ij[:, 0] < cols) & (ij[:, 1] >= 0) & (ij[:, 1] < rows)
    index = np.where(inside, ij[:, 1] * cols + ij[:, 0], 0)
    best = (-1, 0, np.zeros(0), 0)
    for s, inv in enumerate(_inverse_symmetries((cols, rows))):
        t = inv[index]
        d = np.linalg.norm(pts - gt[t], axis=1)
        ok = inside & (d <= max_px)
        # one detection per true corner: the closest one keeps it
        keep: dict[int, int] = {}
        for k in np.flatnonzero(ok):
            if int(t[k]) not in keep or d[k] < d[keep[int(t[k])]]:
                keep[int(t[k])] = int(k)
        chosen = np.array(sorted(k for ti, k in keep.items() if vis[ti]), dtype=np.int64)
        if len(chosen) > best[0]:
            best = (len(chosen), s, d[chosen], len(keep) - len(chosen))
    correct, sym, errs, hidden = best
    n_vis = int(vis.sum())
    return {
        "visible": n_vis,
        "detected": int(len(pts)),
        "correct": int(correct),
        "hidden_found": int(hidden),
        "wrong_ids": int(len(pts) - correct - hidden),
        "recall": float(correct / n_vis) if n_vis else float("nan"),
        "symmetry": int(sym),
        "errors": errs,
    }


def detection_agreement(a: np.ndarray, b: np.ndarray, pattern_size: tuple[int, int]) -> dict:
    """How closely two full-board detections of the same image agree (no ground truth needed).

    a, b : (cols·rows, 2) px, each in any admissible board order. ``b`` is read under the board
    symmetry that best matches ``a``. Returns median_px, max_px and rms_px of the per-corner
    distances.
    """
    pa = np.asarray(a, dtype=np.float64).reshape(-1, 2)
    d = np.linalg.norm(align_to_truth(b, pa, pattern_size) - pa, axis=1)
    return {"median_px": float(np.median(d)), "max_px": float(d.max()), "rms_px": float(np.sqrt(np.mean(d * d)))}
