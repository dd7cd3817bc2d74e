"""The one interface every lens model implements (Project Aria's camera projections have the same face).

A lens model maps a camera-frame point P = (X, Y, Z) to *normalized* image coordinates (a, b);
the pixel is ``(fx·a + cx, fy·b + cy)`` for every model, so K is applied once, in
:mod:`aicalib_tf.geometry.lens`, and a model only knows its coefficients ``d`` (n,) float64.
Each model lives in its own module (``_pinhole``, ``_equidistant``, ``_double_sphere``, ``_eucm``)
and is listed once in :mod:`aicalib_tf.geometry.lens_registry`; nothing else asks which model it
holds: callers read these attributes instead.

Attributes
----------
NAME : our name (``plumb_bob``, ``equidistant``, ``ds``, ...).
COEFF_NAMES : the coefficients' names, in file order.
NAMES : {"opencv": the OpenCV function family or None, "ros": ROS ``distortion_model`` (our name
    where ROS has none), "kalibr": (camera_model, distortion_model) or None}.
ALIASES : other names files use for it (e.g. ``fisheye`` for ``equidistant``).
IS_FISHEYE : True when the model images rays at and beyond 90° off-axis.
MAX_ANGLE : radians, the widest off-axis angle any coefficients can image (π/2 for pinholes:
    exclusive, a pinhole never reaches it).
RANK : place in the model choice's simplicity order (:mod:`aicalib_tf.calib.select`), lower first.
START : how a fit starts without a guess: "opencv" (OpenCV's plumb_bob fit) or "rays" (a grid of
    focal lengths, poses by PnP on rays).
WARM_FROM : under ``auto``, the model whose fit gives this one's start (None: from scratch).
DEFAULT : coefficients for ``dist=None`` (the undistorted case of the model).
FIT_START : coefficients a fit from scratch starts at.
EXTRA_COEFFS : {name: value} of the coefficients the model choice depends on, each with the value
    at which the model becomes a simpler one (k4 = 0, ξ = 0, β = 1): the choice prefers a model
    whose extras the views determine (|value − that| ≥ 2σ).
FIX_K3 : index of k3 in the coefficients for ``fix_k3`` (None: the option does not apply).

A model family whose layout is part of its name (a spline's knot grid: ``_splined``) answers
:meth:`LensModel.variant` for those names; the registry asks it for names it does not list. A model
whose fit is regularized gives its extra residuals by :meth:`LensModel.prior`.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["LensModel", "pixel_jacobians", "unified_w", "RANGE_EDGE_REL"]

RANGE_EDGE_REL = 1e-6  # a coefficient this close (relative, at least 1 x this) to its range's edge sits on it


class LensModel:
    """Base of every lens model: the attributes above and the methods below (normalized units)."""

    NAME = ""
    COEFF_NAMES: tuple = ()
    NAMES: dict = {}
    ALIASES: tuple = ()
    IS_FISHEYE = False
    MAX_ANGLE = math.pi / 2
    RANK = 99
    START = "rays"
    WARM_FROM: str | None = None
    DEFAULT: tuple = ()
    FIT_START: tuple = ()
    EXTRA_COEFFS: dict = {}
    FIX_K3: int | None = None
    FAMILY = ""

    @property
    def n_coeffs(self) -> int:
        """Number of coefficients."""
        return len(self.COEFF_NAMES)

    def __repr__(self) -> str:
        return f"<lens model {self.NAME}>"

    def coerce(self, d: np.ndarray) -> np.ndarray | None:
        """(n,) coefficients from a finite vector of any length, or None when its length is wrong."""
        return d if d.size == self.n_coeffs else None

    def range_problem(self, d: np.ndarray) -> str | None:
        """Why ``d`` is outside the model's valid range (a sentence), or None."""
        return None

    def range_edge(self, d: np.ndarray, rel: float = RANGE_EDGE_REL) -> str | None:
        """"name = value" of the first coefficient of ``d`` that sits on the edge of the valid range (a step
        of ``rel`` times its magnitude, at least ``rel``, leaves the range), or None."""
        d = np.asarray(d, np.float64)
        for i, name in enumerate(self.COEFF_NAMES):
            for sign in (-1.0, 1.0):
                e = d.copy()
                e[i] += sign * rel * max(1.0, abs(float(d[i])))
                if self.range_problem(e) is not None:
                    return f"{name} = {d[i]:.6g}"
        return None

    def resolve(self, n: int) -> str | None:
        """The model a file means by this model's name with ``n`` coefficients (None: impossible)."""
        return self.NAME if n == self.n_coeffs else None

    def variant(self, name: str) -> "LensModel | None":
        """The model of this family called ``name`` (a configured layout), or None (every fixed model)."""
        return None

    def prior(self, d: np.ndarray):
        """Regularization residuals the fit adds: (r (M,) px, J (M, n) dr/dd), or None (no regularization)."""
        return None

    def max_angle(self, d: np.ndarray) -> float:
        """Radians: the widest off-axis angle these coefficients image."""
        raise NotImplementedError

    def monotonic_limit(self, d: np.ndarray) -> float:
        """Where the model's map stops being valid: off-axis angle, radians (pinholes: the normalized radius)."""
        return self.max_angle(d)

    def radius(self, theta: float, d: np.ndarray) -> float:
        """The normalized image radius of a ray ``theta`` radians off-axis (a hair inside
        :meth:`max_angle` when at or beyond it; inf where the map runs off to infinity)."""
        t = min(float(theta), self.max_angle(d) * (1.0 - 1e-9))
        a, _, valid = self.project(np.array([math.sin(t), 0.0, math.cos(t)]), d)
        return float(a) if bool(valid) and np.isfinite(a) else math.inf

    def project(self, P: np.ndarray, d: np.ndarray):
        """(..., 3) camera points -> (a (...,), b (...,), valid (...,) bool) normalized; a, b are
        unspecified (possibly NaN) where not valid."""
        raise NotImplementedError

    def project_jac(self, P: np.ndarray, d: np.ndarray):
        """(N, 3) points -> (a, b, valid, Jp (N, 2, 3) d(a, b)/dP, Jd (N, 2, n) d(a, b)/dd)."""
        raise NotImplementedError

    def unproject(self, a: np.ndarray, b: np.ndarray, d: np.ndarray) -> np.ndarray:
        """Flat normalized (a, b) -> (N, 3) unit rays, the exact inverse of :meth:`project`; NaN rows
        where no valid ray has that image."""
        raise NotImplementedError


def pixel_jacobians(a, b, Jn, Jc, K):
    """Chain normalized results with K: (uv (N, 2) px, J_points (N, 2, 3), J_intr (N, 2, 4 + n))."""
    fx, fy = K[0, 0], K[1, 1]
    n = Jc.shape[-1]
    uv = np.stack([fx * a + K[0, 2], fy * b + K[1, 2]], axis=-1)
    J_points = Jn * np.array([fx, fy])[:, None]
    J_intr = np.zeros((a.shape[0], 2, 4 + n))
    J_intr[:, 0, 0], J_intr[:, 1, 1], J_intr[:, 0, 2], J_intr[:, 1, 3] = a, b, 1.0, 1.0
    J_intr[:, :, 4:] = Jc * np.array([fx, fy])[:, None]
    return uv, J_points, J_intr


def unified_w(alpha: float) -> float:
    """The unified models' bound on the valid projections, w = α/(1−α) for α ≤ ½ else (1−α)/α
    (Usenko et al. 2018: EUCM's w, Double Sphere's w₁)."""
    return alpha / (1.0 - alpha) if alpha <= 0.5 else (1.0 - alpha) / alpha
