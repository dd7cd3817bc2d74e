"""The Extended Unified Camera Model (EUCM: Khomutenko, Garcia, Martinet 2016), valid past 180°.

Reached through :mod:`aicalib_tf.geometry.lens` (the public front; use that). Coefficients
[α, β] (Kalibr and basalt name the model ``eucm``: fx fy cx cy α β), with α ∈ [0, 1] and β > 0.
For a camera point (x, y, z), ρ = √(β·(x² + y²) + z²) and the normalized image point is

    (a, b) = (x, y) / (α·ρ + (1 − α)·z),

valid where z > −w·ρ with w = α / (1 − α) for α ≤ 0.5, else (1 − α) / α: the largest off-axis
angle is π − atan(√(1 − w²) / (w·√β)) (π/2 for α = 0, the pinhole; π for α = 0.5). The inverse is
closed-form: with r² = a² + b² (for α > 0.5 only r² ≤ 1 / ((2α − 1)·β) is imaged),

    z = (1 − β·α²·r²) / (α·√(1 − (2α − 1)·β·r²) + 1 − α),   ray ∝ (a, b, z).
"""

from __future__ import annotations

import math

import numpy as np

from .lens_model import LensModel, unified_w

__all__ = ["EUCM", "EUCMModel"]


class EUCMModel(LensModel):
    """Extended Unified Camera Model, coefficients [alpha, beta]."""

    NAME = "eucm"
    COEFF_NAMES = ("alpha", "beta")
    NAMES = {"opencv": None, "ros": "eucm", "kalibr": ("eucm", "none")}
    ALIASES = ("extended_unified",)
    IS_FISHEYE = True
    MAX_ANGLE = math.pi
    RANK = 3
    START = "rays"
    WARM_FROM = "equidistant"
    DEFAULT = (0.0, 1.0)  # α = 0: the pinhole
    FIT_START = (0.5, 1.0)  # the stereographic projection, which images everything but straight back
    EXTRA_COEFFS = {"beta": 1.0}  # β = 1 is the unified model (UCM)
    FAMILY = "eucm"

    def range_problem(self, d):
        if not (0.0 <= d[0] <= 1.0):
            return f"alpha must be in [0, 1], got {d[0]}"
        if not d[1] > 0.0:
            return f"beta must be > 0, got {d[1]}"
        return None

    def max_angle(self, d):
        w, beta = unified_w(float(d[0])), float(d[1])
        if w >= 1.0:
            return math.pi
        if w <= 0.0:
            return math.pi / 2
        return math.pi - math.atan(math.sqrt(1.0 - w * w) / (w * math.sqrt(beta)))

    def _parts(self, P, d):
        alpha, beta = float(d[0]), float(d[1])
        x, y, z = P[..., 0], P[..., 1], P[..., 2]
        r2 = x * x + y * y
        rho = np.sqrt(beta * r2 + z * z)
        n = alpha * rho + (1.0 - alpha) * z
        with np.errstate(invalid="ignore"):
            valid = (z > -unified_w(alpha) * rho) & (n > 0) & (rho > 0)
        nn = np.where(valid, n, 1.0)
        return x, y, z, r2, rho, nn, valid

    def project(self, P, d):
        x, y, _, _, _, n, valid = self._parts(P, d)
        return x / n, y / n, valid

    def project_jac(self, P, d):
        alpha, beta = float(d[0]), float(d[1])
        x, y, z, r2, rho, n, valid = self._parts(P, d)
        a, b = x / n, y / n
        with np.errstate(invalid="ignore", divide="ignore"):
            irho = np.where(rho > 0, 1.0 / rho, 0.0)
        dn = np.stack([alpha * beta * x * irho, alpha * beta * y * irho, alpha * z * irho + (1.0 - alpha)], axis=-1)
        Jp = np.zeros(x.shape + (2, 3))
        Jp[..., 0, 0], Jp[..., 1, 1] = 1.0 / n, 1.0 / n
        Jp[..., 0, :] -= (a / n)[..., None] * dn
        Jp[..., 1, :] -= (b / n)[..., None] * dn
        dn_dd = np.stack([rho - z, 0.5 * alpha * r2 * irho], axis=-1)
        Jd = np.stack([-(a / n)[..., None] * dn_dd, -(b / n)[..., None] * dn_dd], axis=-2)
        return a, b, valid, Jp, Jd

    def unproject(self, a, b, d):
        alpha, beta = float(d[0]), float(d[1])
        r2 = a * a + b * b
        with np.errstate(invalid="ignore", divide="ignore"):
            q = 1.0 - (2.0 * alpha - 1.0) * beta * r2
            z = (1.0 - beta * alpha * alpha * r2) / (alpha * np.sqrt(q) + 1.0 - alpha)
            rays = np.stack([a, b, z], axis=-1)
            rays = rays / np.linalg.norm(rays, axis=-1, keepdims=True)
            rho = np.sqrt(beta * (rays[..., 0] ** 2 + rays[..., 1] ** 2) + rays[..., 2] ** 2)
            bad = ~(q >= 0) | ~(rays[..., 2] > -unified_w(alpha) * rho - 1e-12) | ~np.all(np.isfinite(rays), axis=-1)
        rays[bad] = np.nan
        return rays


EUCM = EUCMModel()
