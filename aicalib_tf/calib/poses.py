"""Board poses from a lens guess: every view's pose from rays, for boards seen up to and past 90° off-axis.

:func:`poses_from_rays` unprojects each corner with the guessed lens, turns the view's rays so that
their mean points along +z (a board seen 90° or more off-axis then lies in front of the turned
camera), solves ``cv2.solvePnP`` on normalized coordinates with K = I and turns the pose back.
"""

from __future__ import annotations

import cv2
import numpy as np

from aicalib_tf.geometry.lens import Lens

__all__ = ["poses_from_rays"]


def poses_from_rays(lens: Lens, obj, px, min_z: float = 0.2):
    """Every view's pose from a lens guess: (rvecs (V, 3), tvecs (V, 3)), or None if a view fails.

    Each corner is unprojected with ``lens``; the view's rays are turned so that their mean points
    along +z (a board seen 90° or more off-axis then lies in front of the turned camera), the rays
    with z > ``min_z`` there (0.05 when fewer than 4 remain) go to ``cv2.solvePnP`` as normalized
    coordinates with K = I, and the pose is turned back.
    """
    rvecs, tvecs = [], []
    for o, p in zip(obj, px):
        o, p = np.asarray(o, np.float64).reshape(-1, 3), np.asarray(p, np.float64).reshape(-1, 2)
        rays = lens.unproject(p)
        fin = np.isfinite(rays).all(axis=1)
        if fin.sum() < 4:
            return None
        Q = _turn_to_z(np.mean(rays[fin] / np.linalg.norm(rays[fin], axis=1, keepdims=True), axis=0))
        turned = rays @ Q.T
        pose = None
        for z in (min_z, 0.05):
            ok = fin & (turned[:, 2] > z * np.linalg.norm(turned, axis=1))
            if ok.sum() >= 4:
                pose = _pnp(o[ok], turned[ok, :2] / turned[ok, 2:])
                break
        if pose is None:
            return None
        R, _ = cv2.Rodrigues(pose[0])
        rvecs.append(cv2.Rodrigues(Q.T @ R)[0].ravel())
        tvecs.append(Q.T @ pose[1])
    return np.array(rvecs), np.array(tvecs)


def _turn_to_z(m: np.ndarray) -> np.ndarray:
    """A rotation (3, 3) that takes the direction ``m`` (3,) to +z (the identity when m is +z)."""
    m = m / np.linalg.norm(m)
    axis = np.cross(m, [0.0, 0.0, 1.0])
    s, c = np.linalg.norm(axis), float(m[2])
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    return cv2.Rodrigues(axis / s * np.arctan2(s, c))[0]


def _pnp(o, xn):
    """Pose of planar board points o (M, 3) seen at normalized coordinates xn (M, 2), or None."""
    eye = np.eye(3)
    for flags in (cv2.SOLVEPNP_IPPE, cv2.SOLVEPNP_ITERATIVE):
        try:
            ok, r, t = cv2.solvePnP(o, xn.reshape(-1, 1, 2), eye, None, flags=flags)
        except cv2.error:
            continue
        if ok and np.all(np.isfinite(r)) and np.all(np.isfinite(t)) and t[2, 0] > 0:
            return r.ravel(), t.ravel()
    return None
