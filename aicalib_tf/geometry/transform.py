"""Rigid transforms: 4×4 matrices, Rodrigues vectors, unit quaternions (numpy/OpenCV).

``T_a_b`` (4, 4) maps coordinates in frame b into frame a (ROS REP 103 names). Quaternions are
Hamilton, ordered x, y, z, w as ROS writes them. A small change of a transform is [ω, τ]: the
rotation exp(ω) applied on the left (ω in the parent frame, radians) and τ added to the
translation (:func:`perturb`).
"""

from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = ["to_T", "from_T", "inv", "rotation_angle", "quat_to_matrix", "matrix_to_quat", "exp_rotations", "perturb"]


def to_T(rvec, tvec) -> np.ndarray:
    """(3,) Rodrigues vector, (3,) translation -> (4, 4) transform.

    >>> to_T([0, 0, 0], [1, 2, 3])[:3, 3].tolist()
    [1.0, 2.0, 3.0]
    """
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))[0]
    T[:3, 3] = np.ravel(tvec)
    return T


def from_T(T) -> tuple[np.ndarray, np.ndarray]:
    """(4, 4) transform -> ((3,) Rodrigues vector, (3,) translation)."""
    T = np.asarray(T, np.float64)
    return cv2.Rodrigues(np.ascontiguousarray(T[:3, :3]))[0].ravel(), np.array(T[:3, 3], np.float64)


def inv(T) -> np.ndarray:
    """Inverse of (..., 4, 4) rigid transforms."""
    T = np.asarray(T, np.float64)
    out = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def rotation_angle(R) -> np.ndarray:
    """Angle (radians) of (..., 3, 3) rotations."""
    c = (np.trace(np.asarray(R), axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.arccos(np.clip(c, -1.0, 1.0))


def quat_to_matrix(q) -> np.ndarray:
    """(4,) unit quaternion x, y, z, w (Hamilton) -> (3, 3) rotation matrix.

    >>> np.round(quat_to_matrix([0, 0, 1, 0]), 6).tolist()[0]
    [-1.0, 0.0, 0.0]
    """
    x, y, z, w = (float(v) for v in q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def matrix_to_quat(R) -> np.ndarray:
    """(3, 3) rotation -> (4,) unit quaternion x, y, z, w with w >= 0 (Shepperd's method)."""
    R = np.asarray(R, dtype=np.float64)
    tr = float(np.trace(R))
    k = int(np.argmax([tr, R[0, 0], R[1, 1], R[2, 2]]))
    if k == 0:
        s = 2.0 * math.sqrt(1.0 + tr)
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s]
    else:
        i, j, m = k - 1, k % 3, (k + 1) % 3
        s = 2.0 * math.sqrt(max(1.0 + R[i, i] - R[j, j] - R[m, m], 1e-300))
        q = [0.0] * 4
        q[i] = 0.25 * s
        q[j] = (R[j, i] + R[i, j]) / s
        q[m] = (R[m, i] + R[i, m]) / s
        q[3] = (R[m, j] - R[j, m]) / s
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def _skew(w) -> np.ndarray:
    S = np.zeros((len(w), 3, 3))
    S[:, 0, 1], S[:, 0, 2], S[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    S[:, 1, 0], S[:, 2, 0], S[:, 2, 1] = w[:, 2], -w[:, 1], w[:, 0]
    return S


def exp_rotations(w) -> np.ndarray:
    """(V, 3) rotation vectors (radians) -> (V, 3, 3) rotations (Rodrigues' formula, vectorised)."""
    w = np.asarray(w, np.float64).reshape(-1, 3)
    th = np.linalg.norm(w, axis=1)
    small = th < 1e-12
    Kx = _skew(w / np.where(small, 1.0, th)[:, None])
    s, c = np.sin(th)[:, None, None], (1 - np.cos(th))[:, None, None]
    R = np.eye(3) + s * Kx + c * (Kx @ Kx)
    R[small] = np.eye(3) + _skew(w[small])
    return R


def perturb(T0, d) -> np.ndarray:
    """(..., 4, 4) transforms moved by (..., 6) [ω (rad), τ] (rotation on the left, translation added)."""
    T0 = np.asarray(T0, np.float64)
    d = np.asarray(d, np.float64).reshape(-1, 6)
    T = np.array(T0, copy=True).reshape(-1, 4, 4)
    T[:, :3, :3] = exp_rotations(d[:, :3]) @ T[:, :3, :3]
    T[:, :3, 3] += d[:, 3:]
    return T.reshape(T0.shape)
