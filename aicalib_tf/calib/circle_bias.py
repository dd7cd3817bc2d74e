"""The projected-centre bias of circle grids, corrected by iterating with the current lens.

A circle's image is an ellipse (a pinhole camera) or a slightly bent one (a lens); the detector
(:mod:`aicalib_tf.detect.boards.circles`) measures the centroid of that dark area, which is not the
projection of the circle's centre: a circle tilted away from the camera has its near half larger
in the image than its far half, and distortion adds to it. The offset grows with the circle's
radius (about r²/Z² at first order) and biases the focal length and the principal point.

With a calibration (lens, and each view's pose), the offset of each circle is computed as the
centroid of its projected boundary (``BOUNDARY`` points, a polygon's area centroid; for a
pinhole this is the ellipse's centre exactly, the polygon being an affine image of a regular one)
minus the projection of its centre. :func:`corrected_views` subtracts it from the measured
centres; :func:`calibrate_circles` calibrates, corrects, and calibrates again (``iterations``
times), each time correcting the measurements as detected.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from aicalib_tf.geometry.lens import project

__all__ = ["BOUNDARY", "centre_offsets", "corrected_views", "calibrate_circles"]

BOUNDARY = 64  # points on each circle's boundary


def _polygon_centroid(p: np.ndarray) -> np.ndarray:
    """(..., M, 2) closed polygons -> (..., 2) area centroids."""
    x, y = p[..., 0], p[..., 1]
    xn, yn = np.roll(x, -1, axis=-1), np.roll(y, -1, axis=-1)
    cross = x * yn - xn * y
    area = cross.sum(axis=-1) / 2
    cx = ((x + xn) * cross).sum(axis=-1) / (6 * area)
    cy = ((y + yn) * cross).sum(axis=-1) / (6 * area)
    return np.stack([cx, cy], axis=-1)


def centre_offsets(centres: np.ndarray, radius: float, rvec, tvec, model: str, K, dist) -> np.ndarray:
    """(N, 2) float64 px: the projected circle's area centroid minus its centre's projection.

    centres : (N, 3) board-frame centres; radius : the circles' radius, same unit; rvec, tvec :
    board-to-camera pose; model, K, dist : the lens (:func:`aicalib_tf.geometry.lens.project`).
    NaN where a circle does not project (behind the camera, outside the lens's domain).
    """
    c = np.asarray(centres, np.float64).reshape(-1, 3)
    t = np.linspace(0.0, 2 * np.pi, BOUNDARY, endpoint=False)
    ring = float(radius) * np.stack([np.cos(t), np.sin(t), np.zeros_like(t)], axis=1)
    R, _ = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))
    tv = np.asarray(tvec, np.float64).reshape(1, 3)
    boundary = project((c[:, None, :] + ring[None]) @ R.T + tv, model, K, dist)  # (N, M, 2)
    centre = project(c @ R.T + tv, model, K, dist)
    return _polygon_centroid(boundary) - centre


def corrected_views(views, cal, board) -> list:
    """Views (:class:`~aicalib_tf.calib.fit.View`) with each centre moved by minus its offset under
    ``cal`` (a :class:`~aicalib_tf.calib.fit.Calibration`); ``board`` a
    :class:`~aicalib_tf.geometry.circles.CircleGrid`. Views without a pose in ``cal`` (rejected) and
    circles whose offset is not finite are left as they are."""
    poses = {name: (cal.rvecs[k], cal.tvecs[k]) for k, name in enumerate(cal.views)}
    out = []
    for v in views:
        if v.name not in poses:
            out.append(v)
            continue
        off = centre_offsets(board.object_points(v.ids), board.radius, *poses[v.name], cal.model, cal.K, cal.dist)
        off = np.where(np.isfinite(off), off, 0.0)
        out.append(dataclasses.replace(v, corners=v.corners - off))
    return out


def calibrate_circles(views, board, fit, iterations: int = 2):
    """Calibrate circle-grid ``views`` with the bias correction; returns (the last Calibration, the
    corrected views it was fitted to).

    fit : ``views -> Calibration`` (e.g. :func:`~aicalib_tf.calib.fit.calibrate_camera` with its
    arguments bound). iterations : corrections after the first fit (0: no correction).
    The Calibration's ``meta`` records ``circle_bias_iterations`` and the largest offset applied (px).
    """
    cal, fixed = fit(views), list(views)
    largest = 0.0
    for _ in range(int(iterations)):
        fixed = corrected_views(views, cal, board)
        largest = max([largest] + [float(np.max(np.abs(a.corners - b.corners))) for a, b in zip(fixed, views)
                                   if len(a.corners)])
        cal = fit(fixed)
    meta = dict(cal.meta or {}, circle_bias_iterations=int(iterations), circle_bias_max_px=round(largest, 4))
    return dataclasses.replace(cal, meta=meta), fixed
