"""The Double Sphere camera model (Usenko, Demmel, Cremers 2018), valid past 180°.

Reached through :mod:`aicalib_tf.geometry.lens` (the public front; use that). Coefficients
[ξ, α] (Kalibr and basalt name the model ``ds``: fx fy cx cy ξ α), with ξ ∈ (−1, 1] and
α ∈ [0, 1]. A camera point (x, y, z) is put on a unit sphere, shifted by ξ along the axis, put on
a second sphere and projected by a pinhole shifted by α / (1 − α): with d₁ = |(x, y, z)|,
k = ξ·d₁ + z and d₂ = √(x² + y² + k²), the normalized image point is

    (a, b) = (x, y) / (α·d₂ + (1 − α)·k),

valid where z > −w₂·d₁, w₂ = (w₁ + ξ) / √(2·w₁·ξ + ξ² + 1), w₁ = α / (1 − α) for α ≤ 0.5, else
(1 − α) / α: the largest off-axis angle is acos(−w₂). The inverse is closed-form: with r² = a² + b²
(for α > 0.5 only r² ≤ 1 / (2α − 1) is imaged),

    m = (1 − α²·r²) / (α·√(1 − (2α − 1)·r²) + 1 − α),
    ray = (m·ξ + √(m² + (1 − ξ²)·r²)) / (m² + r²) · (a, b, m) − (0, 0, ξ).
"""

from __future__ import annotations

import math

import numpy as np

from .lens_model import LensModel, unified_w

__all__ = ["DOUBLE_SPHERE", "DoubleSphereModel"]


def _w2(xi: float, alpha: float) -> float:
    w1 = unified_w(alpha)
    return (w1 + xi) / math.sqrt(2.0 * w1 * xi + xi * xi + 1.0)


class DoubleSphereModel(LensModel):
    """Double Sphere, coefficients [xi, alpha]."""

    NAME = "ds"
    COEFF_NAMES = ("xi", "alpha")
    NAMES = {"opencv": None, "ros": "ds", "kalibr": ("ds", "none")}
    ALIASES = ("double_sphere",)
    IS_FISHEYE = True
    MAX_ANGLE = math.pi
    RANK = 2
    START = "rays"
    WARM_FROM = "equidistant"
    DEFAULT = (0.0, 0.0)  # ξ = 0, α = 0: the pinhole
    FIT_START = (0.0, 0.5)  # the stereographic projection, which images everything but straight back
    EXTRA_COEFFS = {"xi": 0.0}  # ξ = 0 is the unified model (UCM)
    FAMILY = "ds"

    def range_problem(self, d):
        if not (-1.0 < d[0] <= 1.0):
            return f"xi must be in (-1, 1], got {d[0]}"
        if not (0.0 <= d[1] <= 1.0):
            return f"alpha must be in [0, 1], got {d[1]}"
        return None

    def max_angle(self, d):
        return math.acos(min(1.0, max(-1.0, -_w2(float(d[0]), float(d[1])))))

    def _parts(self, P, d):
        xi, alpha = float(d[0]), float(d[1])
        x, y, z = P[..., 0], P[..., 1], P[..., 2]
        r2 = x * x + y * y
        d1 = np.sqrt(r2 + z * z)
        k = xi * d1 + z
        d2 = np.sqrt(r2 + k * k)
        n = alpha * d2 + (1.0 - alpha) * k
        with np.errstate(invalid="ignore"):
            valid = (z > -_w2(xi, alpha) * d1) & (n > 0) & (d1 > 0)
        return x, y, z, d1, k, d2, np.where(valid, n, 1.0), valid

    def project(self, P, d):
        x, y, _, _, _, _, n, valid = self._parts(P, d)
        return x / n, y / n, valid

    def project_jac(self, P, d):
        xi, alpha = float(d[0]), float(d[1])
        x, y, z, d1, k, d2, n, valid = self._parts(P, d)
        a, b = x / n, y / n
        with np.errstate(invalid="ignore", divide="ignore"):
            i1 = np.where(d1 > 0, 1.0 / d1, 0.0)
            i2 = np.where(d2 > 0, 1.0 / d2, 0.0)
        P3 = np.stack([x, y, z], axis=-1)
        dk = xi * P3 * i1[..., None]
        dk[..., 2] += 1.0
        dd2 = (np.stack([x, y, np.zeros_like(z)], axis=-1) + k[..., None] * dk) * i2[..., None]
        dn = alpha * dd2 + (1.0 - alpha) * dk
        Jp = np.zeros(x.shape + (2, 3))
        Jp[..., 0, 0], Jp[..., 1, 1] = 1.0 / n, 1.0 / n
        Jp[..., 0, :] -= (a / n)[..., None] * dn
        Jp[..., 1, :] -= (b / n)[..., None] * dn
        dn_dd = np.stack([alpha * k * d1 * i2 + (1.0 - alpha) * d1, d2 - k], axis=-1)
        Jd = np.stack([-(a / n)[..., None] * dn_dd, -(b / n)[..., None] * dn_dd], axis=-2)
        return a, b, valid, Jp, Jd

    def unproject(self, a, b, d):
        xi, alpha = float(d[0]), float(d[1])
        r2 = a * a + b * b
        with np.errstate(invalid="ignore", divide="ignore"):
            q = 1.0 - (2.0 * alpha - 1.0) * r2
            m = (1.0 - alpha * alpha * r2) / (alpha * np.sqrt(q) + 1.0 - alpha)
            lam = (m * xi + np.sqrt(m * m + (1.0 - xi * xi) * r2)) / (m * m + r2)
            rays = np.stack([lam * a, lam * b, lam * m - xi], axis=-1)
            rays = rays / np.linalg.norm(rays, axis=-1, keepdims=True)
            bad = ~(q >= 0) | ~(rays[..., 2] > -_w2(xi, alpha) - 1e-12) | ~np.all(np.isfinite(rays), axis=-1)
        rays[bad] = np.nan
        return rays


DOUBLE_SPHERE = DoubleSphereModel()
