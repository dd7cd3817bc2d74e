"""Stereo geometry: rig poses, Bouguet's rectification for any pair of lens models, rectified points.

A rig's camera k sees a point of camera 0's frame at X_k = R_k·X_0 + T_k (OpenCV's ``stereoCalibrate``
convention for the pair (0, 1): ``X2 = R·X1 + T``). T is in the unit of the board's squares.

Rectification (Bouguet's split, as ``cv2.stereoRectify``): both cameras turn by half the relative
rotation, then together so that the baseline lies along the rectified x axis (y for a rig that is
taller than wide). The rectified cameras are pinholes with one focal length and one principal
point, so a world point lands on the same row in both (the same column for a vertical rig):
OpenCV's ``CALIB_ZERO_DISPARITY``. Distortion enters only through
:func:`~aicalib_tf.geometry.lens.unproject` / :func:`~aicalib_tf.geometry.lens.undistort_maps`, so
plumb_bob, the rational family and equidistant fisheyes rectify the same way, in any mix.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from aicalib_tf.geometry.lens import Lens

__all__ = ["Rectification", "rectify_pair", "rectified_points", "essential_matrix", "fundamental_matrix",
           "relative_pose", "compose", "invert", "rotation_angle_deg"]


def compose(Ra, ta, Rb, tb) -> tuple[np.ndarray, np.ndarray]:
    """The transform X -> Ra·(Rb·X + tb) + ta as (R (3, 3), t (3,))."""
    Ra, Rb = np.asarray(Ra, np.float64), np.asarray(Rb, np.float64)
    return Ra @ Rb, Ra @ np.asarray(tb, np.float64) + np.asarray(ta, np.float64)


def invert(R, t) -> tuple[np.ndarray, np.ndarray]:
    """The inverse of X -> R·X + t as (R (3, 3), t (3,))."""
    R = np.asarray(R, np.float64)
    return R.T, -R.T @ np.asarray(t, np.float64)


def relative_pose(rvec_a, tvec_a, rvec_b, tvec_b) -> tuple[np.ndarray, np.ndarray]:
    """Camera b's pose relative to camera a, both seeing one board: (R (3, 3), T (3,)) with X_b = R·X_a + T.

    rvec_*, tvec_* : (3,) board-to-camera poses (``T_cam_board``) of the same board at the same instant.
    """
    Ra, _ = cv2.Rodrigues(np.asarray(rvec_a, np.float64).reshape(3, 1))
    Rb, _ = cv2.Rodrigues(np.asarray(rvec_b, np.float64).reshape(3, 1))
    return compose(Rb, tvec_b, *invert(Ra, tvec_a))


def rotation_angle_deg(R) -> float:
    """The angle of a rotation matrix (3, 3), degrees."""
    return float(np.degrees(np.linalg.norm(cv2.Rodrigues(np.asarray(R, np.float64))[0])))


def _skew(t) -> np.ndarray:
    x, y, z = np.asarray(t, np.float64).ravel()
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def essential_matrix(R, T) -> np.ndarray:
    """E (3, 3) = [T]×·R: x2ᵀ·E·x1 = 0 for normalized rays of one point in cameras 1 and 2."""
    return _skew(T) @ np.asarray(R, np.float64)


def fundamental_matrix(K1, K2, R, T) -> np.ndarray:
    """F (3, 3) = K2⁻ᵀ·E·K1⁻¹, scaled to F[2, 2] = 1 where it is not 0 (pinhole pixels; distortion ignored)."""
    F = np.linalg.inv(np.asarray(K2, np.float64)).T @ essential_matrix(R, T) @ np.linalg.inv(np.asarray(K1, np.float64))
    return F / F[2, 2] if abs(F[2, 2]) > 1e-12 * np.abs(F).max() else F / np.abs(F).max()


@dataclass(frozen=True)
class Rectification:
    """A rectified pair (OpenCV's ``stereoRectify`` outputs).

    R1, R2 : (3, 3) rotations from each camera's frame to its rectified frame. P1, P2 : (3, 4)
    rectified projection matrices, px (P2[0, 3] = f·Tx, or P2[1, 3] = f·Ty for a vertical rig).
    Q : (4, 4) disparity-to-depth matrix. size : (width, height) of the rectified images.
    vertical : the baseline runs along y (rows of the two images are then matched as columns).
    """

    R1: np.ndarray
    R2: np.ndarray
    P1: np.ndarray
    P2: np.ndarray
    Q: np.ndarray
    size: tuple[int, int]
    vertical: bool = False

    @property
    def focal(self) -> float:
        """The rectified focal length, px."""
        return float(self.P1[0, 0])


def _axis_rotation(R, T) -> tuple[np.ndarray, np.ndarray, bool]:
    """(R1, R2, vertical): Bouguet's split of R, then the turn taking the baseline onto ±x (or ±y)."""
    r = cv2.Rodrigues(np.asarray(R, np.float64))[0].ravel()
    r_half = cv2.Rodrigues(-0.5 * r)[0]  # R^(-1/2): camera 2 turned by it meets camera 1 turned by its inverse
    t = r_half @ np.asarray(T, np.float64).ravel()
    vertical = abs(t[1]) > abs(t[0])
    axis = 1 if vertical else 0
    u = np.zeros(3)
    u[axis] = 1.0 if t[axis] > 0 else -1.0
    w = np.cross(t, u)
    n = np.linalg.norm(w)
    turn = np.eye(3) if n < 1e-12 else cv2.Rodrigues(w / n * np.arccos(np.clip(abs(t[axis]) / np.linalg.norm(t), -1, 1)))[0]
    return turn @ r_half.T, turn @ r_half, vertical


def _rectified_focal(lenses) -> float:
    """The rectified focal length: the smaller mean focal length of the two lenses, px (the centre's resolution kept)."""
    return float(min(0.5 * (lens.fx + lens.fy) for lens in lenses))


def rectify_pair(lens1: Lens, lens2: Lens, R, T, *, size: tuple[int, int] | None = None) -> Rectification:
    """Rectify a pair: X2 = R·X1 + T (R (3, 3), T (3,)); any mix of lens models.

    size : (width, height) of the rectified images (default: lens1's image size). The focal length
    is :func:`_rectified_focal`; the shared principal point puts the mean of the two rectified
    optical axes at the image centre. Raises ValueError when T is zero.
    """
    T = np.asarray(T, np.float64).ravel()
    if not np.linalg.norm(T) > 0:
        raise ValueError("the cameras are at the same place (T = 0): there is no baseline to rectify along")
    R1, R2, vertical = _axis_rotation(R, T)
    w, h = lens1.image_size if size is None else (int(size[0]), int(size[1]))
    f = _rectified_focal((lens1, lens2))
    axes = np.stack([R1[:, 2], R2[:, 2]])  # each camera's optical axis in its rectified frame
    offset = f * np.mean(axes[:, :2] / axes[:, 2:], axis=0)
    cx, cy = (w - 1) / 2.0 - offset[0], (h - 1) / 2.0 - offset[1]
    Kr = np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])
    Tr = R2 @ T  # the baseline in the rectified frame: along one axis
    P1 = np.concatenate([Kr, np.zeros((3, 1))], axis=1)
    P2 = P1.copy()
    b = Tr[1] if vertical else Tr[0]
    P2[1 if vertical else 0, 3] = f * b
    Q = np.zeros((4, 4))
    Q[0, 0] = Q[1, 1] = 1.0
    Q[0, 3], Q[1, 3], Q[2, 3], Q[3, 2] = -cx, -cy, f, -1.0 / b
    return Rectification(R1, R2, P1, P2, Q, (w, h), bool(vertical))


def rectified_points(lens: Lens, R_rect, P, pixels) -> np.ndarray:
    """Distorted pixels (N, 2) of one camera -> their rectified pixels (N, 2).

    R_rect : (3, 3) the camera's rectifying rotation (R1 or R2). P : (3, 4) its rectified
    projection (P1 or P2; only its 3×3 left part is used). NaN where the pixel has no ray or the
    ray points behind the rectified camera.
    """
    rays = lens.unproject(np.asarray(pixels, np.float64).reshape(-1, 2)) @ np.asarray(R_rect, np.float64).T
    with np.errstate(invalid="ignore", divide="ignore"):
        ok = rays[:, 2] > 1e-9
        xy = np.where(ok[:, None], rays[:, :2] / np.where(ok, rays[:, 2], 1.0)[:, None], np.nan)
    P = np.asarray(P, np.float64)
    return np.stack([P[0, 0] * xy[:, 0] + P[0, 2], P[1, 1] * xy[:, 1] + P[1, 2]], axis=1)
