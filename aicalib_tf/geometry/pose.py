"""Board poses and projection of board points into an image.

A pose (rvec, tvec) maps board to camera (``T_cam_board``), as ``cv2.projectPoints`` takes it.
"""

from __future__ import annotations

import cv2
import numpy as np

from aicalib_tf.geometry.camera import Camera

__all__ = ["project_points", "in_frame"]

def project_points(points: np.ndarray, rvec, tvec, camera: Camera) -> np.ndarray:
    """(N, 3) board points -> (N, 2) float64 pixels.

    Pinhole models go through ``cv2.projectPoints`` (finite even where the lens does not image
    the point, as today's labels have it); ``equidistant`` through
    :func:`aicalib_tf.geometry.lens.project`, valid past 90° off-axis, with points the model
    cannot project (beyond its monotonic range) at -1e6 px, far outside any image.
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    rvec = np.asarray(rvec, dtype=np.float64).reshape(3, 1)
    tvec = np.asarray(tvec, dtype=np.float64).reshape(3, 1)
    if camera.model != "equidistant":
        pts, _ = cv2.projectPoints(P.reshape(-1, 1, 3), rvec, tvec, camera.K, camera.dist)
        return pts.reshape(-1, 2)
    R, _ = cv2.Rodrigues(rvec)
    uv = camera.lens.project(P @ R.T + tvec.ravel())
    return np.where(np.isfinite(uv), uv, -1e6)


def in_frame(uv: np.ndarray, size: tuple[int, int], border: float = 0.0) -> np.ndarray:
    """(N,) bool: points (N, 2) px at least ``border`` px inside the image's outer edge.

    The outer edge of a (w, h) image is x in [-0.5, w - 0.5], y in [-0.5, h - 0.5];
    ``border=0.5`` keeps points within the hull of the pixel centres.
    """
    w, h = size
    lo = -0.5 + border
    with np.errstate(invalid="ignore"):
        return (uv[:, 0] >= lo) & (uv[:, 0] <= w - 1 - lo) & (uv[:, 1] >= lo) & (uv[:, 1] <= h - 1 - lo)


