"""Board poses, projection of board points into an image, and the rotation that best maps one
lens's projections onto pixels.

A pose (rvec, tvec) maps board to camera (``T_cam_board``), as ``cv2.projectPoints`` takes it.
"""

from __future__ import annotations

import cv2
import numpy as np

from aicalib_tf.geometry.camera import Camera
from aicalib_tf.geometry.lens import Lens

__all__ = ["project_points", "in_frame", "best_rotation"]

def project_points(points: np.ndarray, rvec, tvec, camera: Camera) -> np.ndarray:
    """(N, 3) board points -> (N, 2) float64 pixels.

    Pinhole models go through ``cv2.projectPoints`` (finite even where the lens does not image
    the point, as today's labels have it); the fisheye models (``IS_FISHEYE``) through
    :func:`aicalib_tf.geometry.lens.project`, valid past 90° off-axis, with points the model
    cannot project (beyond its monotonic range) at -1e6 px, far outside any image.
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    rvec = np.asarray(rvec, dtype=np.float64).reshape(3, 1)
    tvec = np.asarray(tvec, dtype=np.float64).reshape(3, 1)
    if not camera.fisheye:
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


ROTATION_TOL = 1e-12  # stop when a step (rad) or the relative decrease of the cost is below this
_NO_PROJECTION = 1e3  # px: the residual of a ray the rotated lens cannot image (the fit turns away from it)


def best_rotation(lens: Lens, rays: np.ndarray, pixels: np.ndarray, max_iterations: int = 50) -> np.ndarray:
    """The rotation R (3, 3) minimising Σ |lens.project(R·v) − q|² over rays v (M, 3) and pixels q (M, 2) px.

    Levenberg–Marquardt from R = I with the update R ← exp([δ]×)·R, whose Jacobian per ray is
    d project / dX · (−[R·v]×) (:func:`~aicalib_tf.geometry.lens.projection_jacobian`); used to compare two calibrations of one
    camera (:func:`aicalib_tf.calib.quality.rotation_compensated_diff`). The rotations
    sought are small (a fraction of a degree between two calibrations of one camera): a few steps.
    """
    v = np.asarray(rays, np.float64).reshape(-1, 3)
    q = np.asarray(pixels, np.float64).reshape(-1, 2)

    def evaluate(R):
        p = v @ R.T
        uv, Jp, _ = lens.projection_jacobian(p)
        bad = ~np.isfinite(uv).all(axis=1)
        r = np.where(bad[:, None], _NO_PROJECTION, uv - q)
        skew = np.zeros((len(p), 3, 3))  # −[p]×: d(δ × p)/dδ
        skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = p[:, 2], -p[:, 1], p[:, 0]
        skew[:, 1, 0], skew[:, 2, 0], skew[:, 2, 1] = -p[:, 2], p[:, 1], -p[:, 0]
        J = np.where(bad[:, None, None], 0.0, np.nan_to_num(Jp) @ skew).reshape(-1, 3)
        return r.ravel(), J

    R, lam = np.eye(3), 1e-3
    r, J = evaluate(R)
    cost = float(r @ r)
    for _ in range(max_iterations):
        A, g = J.T @ J, J.T @ r
        step_taken = converged = False
        while lam < 1e12:
            delta = -np.linalg.solve(A + lam * np.diag(np.maximum(np.diag(A), 1e-12)), g)
            R_new = cv2.Rodrigues(delta)[0] @ R
            r_new, J_new = evaluate(R_new)
            c_new = float(r_new @ r_new)
            if np.isfinite(c_new) and c_new <= cost:
                converged = cost - c_new <= ROTATION_TOL * cost or np.linalg.norm(delta) <= ROTATION_TOL
                R, r, J, cost, lam, step_taken = R_new, r_new, J_new, c_new, lam / 3.0, True
                break
            lam *= 10.0
        if not step_taken or converged:
            break
    return R
