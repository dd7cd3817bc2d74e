"""The projection difference of two calibrations of one camera, with a rotation fitted out.

Two calibrations of one camera are compared as mrcal's ``projection_diff`` does: each pixel q of
a grid over the image is unprojected with lens A to a ray v; the rotation R that best maps A's
rays onto B's projections (least squares over the pixels of the fit region) is found; the
difference at q is |project_B(R·v) − q|, px. A monocular calibration cannot see a rotation of its
own camera frame (a shift of the principal point is absorbed by the board poses), so the rotation
is fitted out; ``rotation=False`` compares the raw projections.

The region. A calibration is only known where its boards were: the rotation is fitted, and the
median and 95th percentile taken, over the grid cells the boards covered. For two halves of one
set of views (:func:`aicalib_tf.calib.quality.half_difference`) that is the cells holding a
detected corner of any view; for two calibration files (:func:`compare_calibrations`) it is the
cells both files' boards cover, each board projected through its own calibration at its stored
pose, its convex hull filled (:func:`board_coverage`). Cells outside a circular fisheye's image circle are never counted.

Everything here is numpy/OpenCV on :class:`~aicalib_tf.geometry.lens.Lens` objects; the
``calibrate`` command's half-vs-half line, ``python -m aicalib_tf.compare`` and the real-photo
benchmark all call :func:`projection_diff`.
"""

from __future__ import annotations

import cv2
import numpy as np

from aicalib_tf.geometry import lens as L
from aicalib_tf.geometry.pattern import board_points, pattern_ids
from aicalib_tf.geometry.pose import best_rotation

__all__ = ["GRID", "grid_points", "cell_counts", "rotation_compensated_diff", "diff_stats", "projection_diff",
           "view_coverage", "board_coverage", "central_scale", "compare_calibrations", "split_views", "SCALE_MISMATCH"]

GRID = (32, 24)  # (gx, gy) cells over the image: the default sampling of every difference
SCALE_MISMATCH = 1.3  # two lenses whose central pixel scales differ by more than this are different cameras


def grid_points(image_size, grid=GRID) -> np.ndarray:
    """(gy·gx, 2) float64 px: the centres of a gx × gy grid of cells over the image, row-major."""
    w, h = (int(v) for v in image_size)
    gx, gy = (int(v) for v in grid)
    xs = (np.arange(gx) + 0.5) * w / gx - 0.5
    ys = (np.arange(gy) + 0.5) * h / gy - 0.5
    X, Y = np.meshgrid(xs, ys)
    return np.stack([X.ravel(), Y.ravel()], axis=1)


def cell_counts(points, image_size, cells=GRID) -> np.ndarray:
    """(cells_y, cells_x) int64: how many of ``points`` ((N, 2) px) fall in each cell of the
    :func:`grid_points` grid (points outside the image are not counted)."""
    w, h = (int(v) for v in image_size)
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    counts, _, _ = np.histogram2d(pts[:, 1], pts[:, 0], bins=(int(cells[1]), int(cells[0])),
                                  range=((-0.5, h - 0.5), (-0.5, w - 0.5)))
    return counts.astype(np.int64)


def _ray_rotation(rays_a: np.ndarray, rays_b: np.ndarray) -> np.ndarray:
    """(3, 3) the rotation R minimising Σ |R·a − b|² over unit rays (Kabsch, by SVD): the start of the
    pixel fit, so that it need not cross a lens's valid range on its way from the identity."""
    a = rays_a / np.linalg.norm(rays_a, axis=1, keepdims=True)
    b = rays_b / np.linalg.norm(rays_b, axis=1, keepdims=True)
    U, _, Vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    return Vt.T @ np.diag([1.0, 1.0, d]) @ U.T


def rotation_compensated_diff(lens_a: L.Lens, lens_b: L.Lens, pixels, fit_mask=None, *,
                              rotation: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """mrcal-style projection difference of two lenses, px.

    Each pixel q (M, 2) is unprojected with ``lens_a`` to a ray v; the rotation R minimising
    Σ |project_b(R·v) − q|² over the ``fit_mask`` pixels (default all) is found
    (:func:`aicalib_tf.geometry.pose.best_rotation`, started from the rotation that best maps A's
    rays onto B's rays of the same pixels; R = I with ``rotation=False``). Returns
    (diff (M,) px = |project_b(R·v) − q|, NaN where A has no ray or B no projection; R (3, 3)).
    Raises ValueError when fewer than 3 fit pixels are imaged by both lenses.
    """
    q = np.asarray(pixels, np.float64).reshape(-1, 2)
    v = lens_a.unproject(q)
    ok = np.all(np.isfinite(v), axis=1)
    fit = ok if fit_mask is None else ok & np.asarray(fit_mask, bool)
    R0 = np.eye(3)
    if rotation and fit.sum() >= 3:
        vb = lens_b.unproject(q[fit])
        both = np.all(np.isfinite(vb), axis=1)
        if both.sum() >= 3:
            R0 = _ray_rotation(v[fit][both], vb[both])
    imaged = np.zeros(len(q), bool)
    imaged[ok] = np.all(np.isfinite(lens_b.project(v[ok] @ R0.T)), axis=1)
    fit &= imaged
    if fit.sum() < 3:
        raise ValueError(f"only {int(fit.sum())} pixels are imaged by both lenses; cannot compare them")
    R = best_rotation(lens_b, v[fit] @ R0.T, q[fit]) @ R0 if rotation else np.eye(3)
    d = np.full(len(q), np.nan)
    d[ok] = np.linalg.norm(lens_b.project(v[ok] @ R.T) - q[ok], axis=1)
    return d, R


def diff_stats(diff: np.ndarray, mask=None) -> dict:
    """{"median", "p95", "mean", "max" (px; NaN when empty), "cells" (int)} of the finite ``diff[mask]``."""
    d = np.asarray(diff, np.float64)
    x = d[(np.ones(d.shape, bool) if mask is None else np.asarray(mask, bool)) & np.isfinite(d)]
    if not x.size:
        return {"median": float("nan"), "p95": float("nan"), "mean": float("nan"), "max": float("nan"), "cells": 0}
    return {"median": float(np.median(x)), "p95": float(np.percentile(x, 95)), "mean": float(np.mean(x)),
            "max": float(np.max(x)), "cells": int(x.size)}


def projection_diff(lens_a: L.Lens, lens_b: L.Lens, *, grid=GRID, covered=None, inside=None,
                    rotation: bool = True) -> dict:
    """The projection difference of two lenses over a grid, rotation fitted over the covered cells, px.

    covered : (gy·gx,) bool over :func:`grid_points`, the cells the boards covered (None: every
        cell). The rotation is fitted over ``covered & inside`` (over every imaged cell when that
        holds fewer than 3), and the "covered" statistics are taken there.
    inside : (gy·gx,) bool, the cells inside the image circle (None: every cell); the "all"
        statistics are taken over them.
    Returns {"points" (M, 2) px, "diff" (M,) px, "covered" (M,) bool, "grid", "R" (3, 3),
    "rotation_deg", "rotation_fitted" (bool), "covered_stats", "all_stats" (:func:`diff_stats`)}.
    """
    pts = grid_points(lens_a.image_size, grid)
    inside = np.ones(len(pts), bool) if inside is None else np.asarray(inside, bool)
    cov = inside.copy() if covered is None else np.asarray(covered, bool) & inside
    fit = cov if cov.sum() >= 3 else inside
    diff, R = rotation_compensated_diff(lens_a, lens_b, pts, fit, rotation=rotation)
    return {"points": pts, "diff": diff, "covered": cov, "grid": tuple(int(g) for g in grid), "R": R,
            "rotation_deg": float(np.degrees(np.linalg.norm(cv2.Rodrigues(R)[0]))), "rotation_fitted": bool(rotation),
            "covered_stats": diff_stats(diff, cov), "all_stats": diff_stats(diff, inside)}


def view_coverage(corner_sets, image_size, grid=GRID) -> np.ndarray:
    """(gy·gx,) bool over :func:`grid_points`: the cells that hold a corner of any view, or that a
    view's convex hull covers or touches (the area its board covered, as mrcal outlines it).

    corner_sets : iterable of (N, 2) px arrays, one per view (points outside the image are clipped
    by the grid; a view with fewer than 3 points adds its cells only)."""
    w, h = (int(v) for v in image_size)
    gx, gy = (int(v) for v in grid)
    mask = np.zeros((gy, gx), np.uint8)
    pts_all = []
    for pts in corner_sets:
        pts = np.asarray(pts, np.float64).reshape(-1, 2)
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        pts_all.append(pts)
        if len(pts) >= 3:  # cell coordinates: cell (i, j)'s centre is at (j, i)
            cell = (pts + 0.5) * [gx / w, gy / h] - 0.5
            hull = cv2.convexHull(np.round(np.clip(cell, -4 * gx, 4 * gx) * 256).astype(np.int32))
            cv2.fillConvexPoly(mask, hull, 1, lineType=cv2.LINE_8, shift=8)
    hit = cell_counts(np.concatenate(pts_all) if pts_all else np.zeros((0, 2)), image_size, grid) > 0
    return (mask.astype(bool) | hit).ravel()


def board_coverage(lens: L.Lens, pattern_size, square_size: float, rvecs, tvecs, grid=GRID) -> np.ndarray:
    """(gy·gx,) bool over :func:`grid_points`: :func:`view_coverage` of the whole board at each pose
    (``rvecs``, ``tvecs`` (V, 3), board-to-camera, in the unit of ``square_size``) projected through
    ``lens`` (a file keeps no corner positions; a partial board counts whole, its corners outside
    the image left out)."""
    P = board_points(pattern_ids(tuple(pattern_size)), float(square_size))
    rv, tv = np.asarray(rvecs, np.float64).reshape(-1, 3), np.asarray(tvecs, np.float64).reshape(-1, 3)
    w, h = lens.image_size
    views = []
    for r, t in zip(rv, tv):
        uv = lens.project(P @ cv2.Rodrigues(r)[0].T + t)
        ok = np.all(np.isfinite(uv), axis=1) & (uv[:, 0] >= -0.5) & (uv[:, 0] <= w - 0.5)
        views.append(uv[ok & (uv[:, 1] >= -0.5) & (uv[:, 1] <= h - 0.5)])
    return view_coverage(views, lens.image_size, grid)


def central_scale(lens: L.Lens, center=None, step: float = 4.0) -> float:
    """Radians per pixel at ``center`` (default the principal point): the angle between the rays of
    the pixels ``step`` px either side, in x and y, averaged. Model-independent, so lenses of
    different models compare."""
    c = np.array([lens.K[0, 2], lens.K[1, 2]] if center is None else center, np.float64)
    q = c + step * np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]])
    v = lens.unproject(q)
    v = v / np.linalg.norm(v, axis=1, keepdims=True)
    ang = [np.arccos(np.clip(v[i] @ v[i + 1], -1.0, 1.0)) for i in (0, 2)]
    return float(np.mean(ang) / (2 * step))


def compare_calibrations(cal_a, cal_b, *, grid=GRID, rotation: bool = True) -> dict:
    """:func:`projection_diff` of two :class:`~aicalib_tf.calib.fit.Calibration` objects (``.lens``,
    ``.pattern_size``, ``.square_size``, ``.rvecs``, ``.tvecs``, ``.image_circle``), over the cells both
    calibrations' boards cover (:func:`board_coverage`) inside both image circles.

    Returns projection_diff's dict plus "coverage": "both", or "whole image" (either holds no
    views) or "no common area" (their boards share fewer than 3 cells), where the whole image
    stands in for the covered area; "scale_ratio" (the larger over the smaller
    :func:`central_scale` at the image centre).
    Raises ValueError when the image sizes differ or the central scales differ by more than
    :data:`SCALE_MISMATCH` (two different cameras; the message gives both figures).
    """
    la, lb = cal_a.lens, cal_b.lens
    if tuple(la.image_size) != tuple(lb.image_size):
        raise ValueError(f"image sizes differ: {la.image_size[0]}x{la.image_size[1]} and "
                         f"{lb.image_size[0]}x{lb.image_size[1]} px")
    centre = (np.asarray(la.image_size, np.float64) - 1) / 2
    sa, sb = central_scale(la, centre), central_scale(lb, centre)
    ratio = max(sa, sb) / min(sa, sb) if min(sa, sb) > 0 else np.inf
    if not ratio <= SCALE_MISMATCH:
        raise ValueError(f"not one camera: {np.degrees(sa) * 60:.3g} and {np.degrees(sb) * 60:.3g} arcmin per pixel "
                         f"at the image centre (ratio {ratio:.2f} > {SCALE_MISMATCH})")
    pts = grid_points(la.image_size, grid)
    inside = np.ones(len(pts), bool)
    for c in (cal_a, cal_b):
        circle = getattr(c, "image_circle", None)
        if circle is not None:
            inside &= circle.contains(pts)
    coverage, covered = "whole image", None
    if all(len(np.asarray(c.rvecs).reshape(-1, 3)) for c in (cal_a, cal_b)):
        covered = board_coverage(la, cal_a.pattern_size, cal_a.square_size, cal_a.rvecs, cal_a.tvecs, grid)
        covered &= board_coverage(lb, cal_b.pattern_size, cal_b.square_size, cal_b.rvecs, cal_b.tvecs, grid)
        coverage = "both" if np.count_nonzero(covered & inside) >= 3 else "no common area"
        covered = covered if coverage == "both" else None
    out = projection_diff(la, lb, grid=grid, covered=covered, inside=inside, rotation=rotation)
    out.update(coverage=coverage, scale_ratio=float(ratio))
    return out


def split_views(views, split: str) -> tuple[list, list]:
    """Two disjoint halves of ``views``: "evenodd" (0, 2, 4, ... against 1, 3, 5, ...) or "halves"
    (the first ⌈n/2⌉ against the rest). Raises ValueError for another ``split``."""
    views = list(views)
    if split == "evenodd":
        return views[0::2], views[1::2]
    if split == "halves":
        k = (len(views) + 1) // 2
        return views[:k], views[k:]
    raise ValueError(f"split must be 'evenodd' or 'halves', got {split!r}")
