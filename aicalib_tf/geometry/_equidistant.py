"""The equidistant (Kannala–Brandt) fisheye model, valid beyond 90 degrees off-axis.

Reached through :mod:`aicalib_tf.geometry.lens` (the public front; use that). For a camera
point (X, Y, Z), r = hypot(X, Y) and θ = atan2(r, Z) (so rays at and behind 90° work);
``θ_d = θ·(1 + k1·θ² + k2·θ⁴ + k3·θ⁶ + k4·θ⁸)`` and the normalized image point is
``(θ_d·X/r, θ_d·Y/r)``, as ``cv2.fisheye`` (which takes θ = atan(r/Z), valid for Z > 0 only).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .lens_model import LensModel

__all__ = ["EQUIDISTANT", "EquidistantModel", "theta_d", "dtheta_d", "monotonic_limit", "project", "project_jac",
           "unproject"]

THETA_CAP = math.pi
_LUT_SIZE = 2048


def theta_d(theta, k):
    t2 = theta * theta
    return theta * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))))


def dtheta_d(theta, k):
    t2 = theta * theta
    return 1.0 + t2 * (3.0 * k[0] + t2 * (5.0 * k[1] + t2 * (7.0 * k[2] + t2 * 9.0 * k[3])))


@functools.lru_cache(maxsize=1024)
def monotonic_limit(k: tuple) -> float:
    """Largest θ (rad, cap π) up to which θ -> θ_d increases: the smallest positive root of
    1 + 3k1·u + 5k2·u² + 7k3·u³ + 9k4·u⁴ in u = θ²."""
    if not any(k):
        return THETA_CAP
    roots = np.roots([9.0 * k[3], 7.0 * k[2], 5.0 * k[1], 3.0 * k[0], 1.0])
    real = roots[np.abs(roots.imag) < 1e-12].real if roots.size else roots.real
    pos = real[real > 0]
    if pos.size == 0:
        return THETA_CAP
    return float(min(math.sqrt(pos.min()), THETA_CAP))


@functools.lru_cache(maxsize=256)
def _lut(k: tuple) -> tuple[np.ndarray, np.ndarray]:
    t = np.linspace(0.0, monotonic_limit(k), _LUT_SIZE)
    td = theta_d(t, k)
    t.setflags(write=False)
    td.setflags(write=False)
    return td, t


def _angles(points):
    x, y, z = points[..., 0], points[..., 1], points[..., 2]
    r = np.hypot(x, y)
    theta = np.arctan2(r, z)
    return x, y, z, r, theta


def _valid(r, z, theta, k):
    # A ray straight behind (r = 0, z < 0) has no single image point; neither has the origin.
    return (theta <= monotonic_limit(tuple(k))) & ((r > 0) | (z > 0))


def project(points, k):
    """(..., 3) camera points -> normalized fisheye coordinates (a, b) and a validity mask."""
    x, y, z, r, theta = _angles(points)
    valid = _valid(r, z, theta, k)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(r > 0, theta_d(theta, k) / r, 0.0)
    return x * scale, y * scale, valid


def project_jac(points, k):
    """Flat (N, 3) points -> (a, b, valid, J (N, 2, 3) d(a, b)/dP, Jk (N, 2, 4) d(a, b)/dk)."""
    x, y, z, r, theta = _angles(points)
    valid = _valid(r, z, theta, k)
    td = theta_d(theta, k)
    tdp = dtheta_d(theta, k)
    rho2 = r * r + z * z
    pos = r > 0
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.where(pos, td / r, 1.0 / z)  # θ_d / r, -> 1/z on the axis
        h = np.where(pos, (tdp * z * r / rho2 - td) / (r * r * r), 0.0)  # (df/dr) / r
        ux = np.where(pos, x / r, 0.0)
        uy = np.where(pos, y / r, 0.0)
    a, b = x * f, y * f
    J = np.empty(x.shape + (2, 3))
    J[..., 0, 0] = f + x * x * h
    J[..., 0, 1] = x * y * h
    J[..., 1, 0] = J[..., 0, 1]
    J[..., 1, 1] = f + y * y * h
    J[..., 0, 2] = -x * tdp / rho2
    J[..., 1, 2] = -y * tdp / rho2
    t2 = theta * theta
    odd = np.stack([theta * t2, theta * t2 * t2, theta * t2 ** 3, theta * t2 ** 4], axis=-1)
    Jk = np.stack([ux[..., None] * odd, uy[..., None] * odd], axis=-2)
    return a, b, valid, J, Jk


def unproject(a, b, k, *, tol: float = 1e-12, max_iter: int = 50):
    """Flat normalized fisheye (a, b) -> unit rays (N, 3); NaN rows beyond the monotonic domain.

    θ_d -> θ is a 1-D monotone root, solved by Newton from a look-up-table start, kept inside
    [0, θ_max]; the ray is (sinθ·a/θ_d, sinθ·b/θ_d, cosθ).
    """
    key = tuple(float(v) for v in k)
    td = np.hypot(a, b)
    lut_td, lut_t = _lut(key)
    outside = ~(td <= lut_td[-1])
    lim = lut_t[-1]
    if any(key):
        theta = np.interp(td, lut_td, lut_t)
        with np.errstate(invalid="ignore", divide="ignore"):
            for _ in range(max_iter):
                step = (theta_d(theta, key) - td) / dtheta_d(theta, key)
                theta = np.clip(theta - step, 0.0, lim)
                if np.nanmax(np.where(outside, 0.0, np.abs(step)), initial=0.0) < tol:
                    break
    else:
        theta = td.copy()
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(td > 0, np.sin(theta) / td, 0.0)
    rays = np.stack([a * s, b * s, np.cos(theta)], axis=-1)
    rays[outside | (theta > lim) | ~np.all(np.isfinite(rays), axis=-1)] = np.nan
    return rays


class EquidistantModel(LensModel):
    """Kannala–Brandt [k1, k2, k3, k4] as ``cv2.fisheye`` (ROS ``equidistant``, Kalibr ``pinhole-equi``)."""

    NAME = "equidistant"
    COEFF_NAMES = ("k1", "k2", "k3", "k4")
    NAMES = {"opencv": "fisheye", "ros": "equidistant", "kalibr": ("pinhole", "equidistant")}
    ALIASES = ("fisheye",)
    IS_FISHEYE = True
    MAX_ANGLE = THETA_CAP
    RANK = 1
    START = "rays"
    DEFAULT = FIT_START = (0.0, 0.0, 0.0, 0.0)
    FAMILY = "equidistant"

    def max_angle(self, d):
        return monotonic_limit(tuple(float(v) for v in d))

    def radius(self, theta, d):
        return float(theta_d(min(float(theta), self.max_angle(d)), d))

    def project(self, P, d):
        return project(P, d)

    def project_jac(self, P, d):
        return project_jac(P, d)

    def unproject(self, a, b, d):
        return unproject(a, b, d)


EQUIDISTANT = EquidistantModel()
