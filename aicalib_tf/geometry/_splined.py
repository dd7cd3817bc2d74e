"""A splined lens model: a Kannala–Brandt (equidistant) base projection corrected by a cubic B-spline surface.

Reached through :mod:`aicalib_tf.geometry.lens` (the public front; use that). The idea is mrcal's
``LENSMODEL_SPLINED_STEREOGRAPHIC`` (a smooth free-form correction over a fisheye base projection);
the maths below is this module's own, and its base is a fitted radial projection, not a fixed one.

For a camera point P, the base image point is the equidistant model's
``(u, v) = θ_d·(X, Y)/r``, ``θ_d = θ·(1 + k1·θ² + k2·θ⁴ + k3·θ⁶ + k4·θ⁸)`` (:mod:`._equidistant`; valid
beyond 90°). The normalized image point is ``(a, b) = (u, v) + Δ(u, v)`` and the pixel
``(fx·a + cx, fy·b + cy)`` as for every model. Δ = (Δx, Δy) is a uniform tensor-product cubic
B-spline over a regular grid of ``nx × ny`` control points (knots) in the (u, v) plane, spacing h,
centred on u = v = 0: control point (j, i) sits at (x₀ + i·h, y₀ + j·h) with x₀ = −U − h, where
U = fov/2 in radians (the base's θ_d of a ray fov/2 off-axis with k = 0) and h = 2U / (nx − 3);
y₀ = −V − h with V = h·(ny − 3)/2. A point uses the 4×4 control points around it, so the spline is
defined on [−U, U] × [−V, V]; rays whose base image falls outside are not imaged (``valid`` False,
NaN through :mod:`~aicalib_tf.geometry.lens`). The radial base carries the lens's bulk (a fisheye's
or a wide pinhole's strong radial term), so the spline only holds what no radial polynomial does:
decentring, asymmetry, local bumps.

Coefficients: k1..k4, then the control points' Δx values (ny × nx, row-major), then their Δy values,
in normalized units (one unit is fx px): ``4 + 2·nx·ny`` of them. The layout is part of the model's
name, as mrcal names its splined models: ``splined_equidistant_nx=12_ny=9_fov=170_smooth=0.5``
(``smooth``: the regularization's weight, below). The bare name ``splined_equidistant`` is the layout
nx = ny = 10, fov = 220°, smooth = 1; a fit of it chooses its layout from the views
(:mod:`aicalib_tf.calib.splined_fit`).

Regularization (:meth:`SplinedModel.prior`): least-squares residuals added to the fit, ``smooth`` px
per normalized unit of each control grid's second differences along x, along y and across (√2 × the
mixed difference: a thin plate's bending energy), ``RIDGE`` × smooth per unit of each value, and
``GAUGE`` px per unit of each grid's affine part (the least-squares fit of a + b·x + c·y to its
control values: a spline with affine control values is that affine map, which K and the poses hold
already; without these rows the fit would drift along them). The fit sees them through their QR factor
(the same cost in n rows; :meth:`SplinedModel._prior_matrix` has them one by one).
"""

from __future__ import annotations

import functools
import math
import re

import numpy as np

from . import _equidistant as _kb
from .lens_model import LensModel

__all__ = ["SPLINED", "SplinedModel", "splined_name", "FAMILY_NAME", "N_BASE"]

FAMILY_NAME = "splined_equidistant"
N_BASE = 4  # k1..k4 of the base projection lead the coefficients
DEFAULT_LAYOUT = (10, 10, 220.0, 1.0)  # nx, ny, fov (deg), smooth (px per unit)
RIDGE = 1e-3  # the values' own weight, relative to smooth
GAUGE = 1e4  # px per normalized unit of each grid's affine part (held at 0: K holds it)
MIN_KNOTS, MAX_KNOTS = 6, 40
_CHUNK = 1 << 16  # points per block in project and unproject
_NAME = re.compile(rf"^{FAMILY_NAME}_nx=(\d+)_ny=(\d+)_fov=([0-9.]+)_smooth=([0-9.eE+-]+)$")


def splined_name(nx: int, ny: int, fov_deg: float, smooth: float) -> str:
    """The model name of a layout: ``splined_equidistant_nx=.._ny=.._fov=.._smooth=..``."""
    return f"{FAMILY_NAME}_nx={int(nx)}_ny={int(ny)}_fov={float(fov_deg):.6g}_smooth={float(smooth):.6g}"


def _basis(t):
    """Uniform cubic B-spline weights of the 4 control points around t ∈ [0, 1]: (w (N, 4), dw/dt (N, 4))."""
    t2, t3 = t * t, t * t * t
    w = np.stack([(1 - t) ** 3, 3 * t3 - 6 * t2 + 4, -3 * t3 + 3 * t2 + 3 * t + 1, t3], axis=-1) / 6.0
    dw = np.stack([-3 * (1 - t) ** 2, 9 * t2 - 12 * t, -9 * t2 + 6 * t + 3, 3 * t2], axis=-1) / 6.0
    return w, dw


class SplinedModel(LensModel):
    """Equidistant base + cubic B-spline corrections on an ``nx × ny`` grid (module docstring)."""

    NAMES: dict = {}
    ALIASES = ()
    RANK = 6
    START = "layout"  # the fit chooses the layout from the views (calib.splined_fit)
    WARM_FROM = "equidistant"
    FAMILY = FAMILY_NAME

    def __init__(self, nx: int, ny: int, fov_deg: float, smooth: float, name: str | None = None):
        if not (MIN_KNOTS <= nx <= MAX_KNOTS and MIN_KNOTS <= ny <= MAX_KNOTS):
            raise ValueError(f"{FAMILY_NAME}: nx and ny must be in [{MIN_KNOTS}, {MAX_KNOTS}], got {nx}, {ny}")
        if not (1.0 <= fov_deg < 360.0) or not (smooth > 0 and math.isfinite(smooth)):
            raise ValueError(f"{FAMILY_NAME}: fov must be in [1, 360) deg and smooth > 0, got {fov_deg}, {smooth}")
        self.nx, self.ny, self.fov_deg, self.smooth = int(nx), int(ny), float(fov_deg), float(smooth)
        self.NAME = name or splined_name(nx, ny, fov_deg, smooth)
        self.NAMES = {"opencv": None, "ros": self.NAME, "kalibr": None}
        self.U = math.radians(self.fov_deg) / 2.0
        self.h = 2.0 * self.U / (self.nx - 3)
        self.V = self.h * (self.ny - 3) / 2.0
        self.COEFF_NAMES = ("k1", "k2", "k3", "k4") + tuple(
            f"{c}_{j}_{i}" for c in ("dx", "dy") for j in range(ny) for i in range(nx))
        self.DEFAULT = self.FIT_START = (0.0,) * (N_BASE + 2 * nx * ny)
        self.MAX_ANGLE = min(math.hypot(self.U, self.V), _kb.THETA_CAP)
        self.IS_FISHEYE = self.MAX_ANGLE > math.pi / 2
        self._prior_J = None

    # ------------------------------------------------------------------ layout
    def layout(self) -> dict:
        """The knot layout, JSON-able: {"base", "order", "nx", "ny", "fov_x_deg", "smooth", "spacing",
        "u_range", "v_range"} (the (u, v) rectangle the spline covers, normalized units)."""
        return {"base": "equidistant", "order": 3, "nx": self.nx, "ny": self.ny, "fov_x_deg": self.fov_deg,
                "smooth": self.smooth, "spacing": self.h, "u_range": [-self.U, self.U], "v_range": [-self.V, self.V]}

    def variant(self, name: str):
        return _variant(name)

    def resolve(self, n: int) -> str | None:
        return self.NAME if n == self.n_coeffs else None

    def max_angle(self, d) -> float:
        return min(self.MAX_ANGLE, _kb.monotonic_limit(tuple(float(v) for v in np.asarray(d)[:N_BASE])))

    def _grids(self, d):
        d = np.asarray(d, np.float64)[N_BASE:]
        m = self.nx * self.ny
        return d[:m].reshape(self.ny, self.nx), d[m:].reshape(self.ny, self.nx)

    def locate(self, u, v):
        """Flat (u, v) -> (inside (N,), flat control indices (N, 4, 4), weights (N, 4, 4), d/du (N, 4, 4), d/dv)."""
        eps = 1e-9 * self.h
        inside = (np.abs(u) <= self.U + eps) & (np.abs(v) <= self.V + eps)
        sx = np.nan_to_num((u + self.U + self.h) / self.h)
        sy = np.nan_to_num((v + self.V + self.h) / self.h)
        ix = np.clip(np.floor(sx), 1, self.nx - 3).astype(np.int64)
        iy = np.clip(np.floor(sy), 1, self.ny - 3).astype(np.int64)
        wx, dwx = _basis(np.clip(sx - ix, 0.0, 1.0))
        wy, dwy = _basis(np.clip(sy - iy, 0.0, 1.0))
        off = np.arange(-1, 3)
        idx = (iy[:, None] + off)[:, :, None] * self.nx + (ix[:, None] + off)[:, None, :]
        w = wy[:, :, None] * wx[:, None, :]
        wu = wy[:, :, None] * dwx[:, None, :] / self.h
        wv = dwy[:, :, None] * wx[:, None, :] / self.h
        return inside, idx, w, wu, wv

    def correction(self, u, v, d):
        """Flat (u, v) -> (Δx, Δy, G (N, 2, 2) dΔ/d(u, v), inside, idx, w) (:meth:`locate`'s idx, w)."""
        cx, cy = (g.ravel() for g in self._grids(d))
        inside, idx, w, wu, wv = self.locate(u, v)
        kx, ky = cx[idx], cy[idx]
        G = np.empty(u.shape + (2, 2))
        G[:, 0, 0], G[:, 0, 1] = np.sum(wu * kx, axis=(1, 2)), np.sum(wv * kx, axis=(1, 2))
        G[:, 1, 0], G[:, 1, 1] = np.sum(wu * ky, axis=(1, 2)), np.sum(wv * ky, axis=(1, 2))
        return np.sum(w * kx, axis=(1, 2)), np.sum(w * ky, axis=(1, 2)), G, inside, idx, w

    # ------------------------------------------------------------------ the interface
    def project(self, P, d):
        P = np.asarray(P, np.float64)
        shape = P.shape[:-1]
        u, v, ok = _kb.project(P.reshape(-1, 3), np.asarray(d, np.float64)[:N_BASE])
        a, b, inside = np.empty_like(u), np.empty_like(v), np.empty(u.shape, bool)
        for s in range(0, u.size, _CHUNK):  # bounded memory for dense maps (16 weights per point)
            c = slice(s, s + _CHUNK)
            dx, dy, _, inside[c], _, _ = self.correction(u[c], v[c], d)
            a[c], b[c] = u[c] + dx, v[c] + dy
        return a.reshape(shape), b.reshape(shape), (ok & inside).reshape(shape)

    def project_jac(self, P, d):
        P = np.asarray(P, np.float64).reshape(-1, 3)
        u, v, ok, Js, Jk = _kb.project_jac(P, np.asarray(d, np.float64)[:N_BASE])
        dx, dy, G, inside, idx, w = self.correction(u, v, d)
        n, m = P.shape[0], self.nx * self.ny
        Jp = Js + G @ Js  # (I + G)·d(u, v)/dP
        Jd = np.zeros((n, 2, N_BASE + 2 * m))
        Jd[:, :, :N_BASE] = Jk + G @ Jk
        rows = np.repeat(np.arange(n), 16)
        Jd[rows, 0, N_BASE + idx.reshape(-1)] = w.reshape(-1)
        Jd[rows, 1, N_BASE + m + idx.reshape(-1)] = w.reshape(-1)
        return u + dx, v + dy, ok & inside, Jp, Jd

    def unproject(self, a, b, d):
        """Flat normalized (a, b) -> (N, 3) unit rays: (u, v) + Δ(u, v) = (a, b) by 2-D Newton inside the
        spline's rectangle, then the base's ray (:func:`._equidistant.unproject`)."""
        a, b = np.asarray(a, np.float64).ravel(), np.asarray(b, np.float64).ravel()
        if a.size <= _CHUNK:
            return self._unproject(a, b, d)
        return np.concatenate([self._unproject(a[s:s + _CHUNK], b[s:s + _CHUNK], d) for s in range(0, a.size, _CHUNK)])

    def _unproject(self, a, b, d, tol: float = 1e-12, max_iter: int = 40):
        u, v = a.copy(), b.copy()
        for _ in range(max_iter):
            dx, dy, G, _, _, _ = self.correction(u, v, d)
            fx, fy = u + dx - a, v + dy - b
            J00, J01, J10, J11 = 1 + G[:, 0, 0], G[:, 0, 1], G[:, 1, 0], 1 + G[:, 1, 1]
            det = J00 * J11 - J01 * J10
            with np.errstate(invalid="ignore", divide="ignore"):
                su, sv = (J11 * fx - J01 * fy) / det, (J00 * fy - J10 * fx) / det
            su, sv = np.nan_to_num(su), np.nan_to_num(sv)
            u = np.clip(u - su, -self.U, self.U)
            v = np.clip(v - sv, -self.V, self.V)
            if np.nanmax(np.abs(np.concatenate([su, sv])), initial=0.0) < tol:
                break
        dx, dy, G, inside, _, _ = self.correction(u, v, d)
        det = (1 + G[:, 0, 0]) * (1 + G[:, 1, 1]) - G[:, 0, 1] * G[:, 1, 0]
        scale = np.maximum(1.0, np.hypot(a, b))
        good = inside & (np.hypot(u + dx - a, v + dy - b) <= 1e-9 * scale) & (det > 0)
        rays = _kb.unproject(u, v, np.asarray(d, np.float64)[:N_BASE])
        rays[~good] = np.nan
        return rays

    # ------------------------------------------------------------------ regularization
    def prior(self, d):
        """Regularization residuals (module docstring): (r (M,) px, J (M, n) dr/dd), linear in d.

        The rows are the triangular factor R of :meth:`_prior_matrix` (its QR decomposition): RᵀR is
        that matrix's JᵀJ, so the cost and the normal equations are the same, with n rows in place of
        about 4·nx·ny (a bundle step adds JᵀJ to its normal equations: 4× fewer operations)."""
        if self._prior_J is None:
            full = self._prior_matrix()
            R = np.linalg.qr(full, mode="r")
            R[:, :N_BASE] = 0.0  # k1..k4 are not regularized (their columns are 0; QR leaves rounding)
            self._prior_J = R
        return self._prior_J @ np.asarray(d, np.float64), self._prior_J

    def _prior_matrix(self) -> np.ndarray:
        nx, ny, m = self.nx, self.ny, self.nx * self.ny
        eye = np.eye(m).reshape(ny, nx, m)
        rows = [(eye[:, :-2] - 2 * eye[:, 1:-1] + eye[:, 2:]).reshape(-1, m),
                (eye[:-2] - 2 * eye[1:-1] + eye[2:]).reshape(-1, m),
                math.sqrt(2.0) * (eye[1:, 1:] - eye[1:, :-1] - eye[:-1, 1:] + eye[:-1, :-1]).reshape(-1, m),
                RIDGE * np.eye(m)]
        one = np.concatenate([self.smooth * np.concatenate(rows), GAUGE * self._affine_rows()])
        J = np.zeros((2 * one.shape[0], N_BASE + 2 * m))  # k1..k4 are not regularized
        J[: one.shape[0], N_BASE:N_BASE + m], J[one.shape[0]:, N_BASE + m:] = one, one
        return J


    def _affine_rows(self) -> np.ndarray:
        """(3, m): the least-squares affine part (1, x, y) of one grid's values, orthonormalized.

        A cubic B-spline whose control values are an affine function of their positions is that affine
        function: K (and, for Δ's rotation part, the poses) would hold the same map, so it is pinned at 0."""
        xs = (np.arange(self.nx) - (self.nx - 1) / 2) * self.h
        ys = (np.arange(self.ny) - (self.ny - 1) / 2) * self.h
        X, Y = np.meshgrid(xs, ys)
        A = np.stack([np.ones(X.size), X.ravel(), Y.ravel()], axis=1)
        q, _ = np.linalg.qr(A)
        return q.T


@functools.lru_cache(maxsize=64)
def _variant(name: str) -> SplinedModel | None:
    """The spline of a layout name (module docstring), or None when ``name`` is not one."""
    if not isinstance(name, str):
        return None
    found = _NAME.match(name)
    if found is None:
        return None
    nx, ny, fov, smooth = int(found[1]), int(found[2]), float(found[3]), float(found[4])
    try:
        model = SplinedModel(nx, ny, fov, smooth)
    except ValueError:
        return None
    return model if model.NAME == name else SplinedModel(nx, ny, fov, smooth, name=name)


SPLINED = SplinedModel(*DEFAULT_LAYOUT, name=FAMILY_NAME)
