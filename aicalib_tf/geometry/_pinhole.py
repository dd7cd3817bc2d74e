"""Pinhole-family lens models (plumb_bob, rational_polynomial, thin_prism): OpenCV's 12-coefficient
model, its derivatives and exact inverse, and the three models of :mod:`~aicalib_tf.geometry.lens_registry`.

Reached through :mod:`aicalib_tf.geometry.lens` (the public front; use that). Every
coefficient vector here is the full 12-vector ``c = [k1, k2, p1, p2, k3, k4, k5, k6, s1, s2,
s3, s4]`` (plumb_bob and rational_polynomial zero-padded). With undistorted normalized
coordinates (x, y) = (X/Z, Y/Z), r² = x² + y² and the radial gain
``g = (1 + k1·r² + k2·r⁴ + k3·r⁶) / (1 + k4·r² + k5·r⁴ + k6·r⁶)``::

    x_d = x·g + 2·p1·x·y + p2·(r² + 2x²) + s1·r² + s2·r⁴
    y_d = y·g + p1·(r² + 2y²) + 2·p2·x·y + s3·r² + s4·r⁴

which is ``cv2.projectPoints`` with 5, 8 or 12 coefficients.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .lens_model import LensModel

__all__ = ["PinholeModel", "PLUMB_BOB", "RATIONAL_POLYNOMIAL", "THIN_PRISM", "full", "distort", "distort_jac",
           "coeff_jac", "monotonic_limit", "undistort"]

N_FULL = 12
RADIUS_CAP = 20.0  # normalized radius beyond which we never look (~87 degrees off-axis)
_LUT_SIZE = 2048  # radial look-up table for the Newton start; Newton polishes to machine precision
_POLE_MARGIN = 1e-6  # relative margin kept inside a pole of the rational gain


def full(dist: np.ndarray) -> np.ndarray:
    """Zero-pad a 5-, 8- or 12-coefficient vector to the full 12-vector."""
    c = np.zeros(N_FULL)
    c[: dist.size] = dist
    return c


def _radial(r2, c):
    """Numerator and denominator of the radial gain g(r²) (Horner form)."""
    num = 1.0 + r2 * (c[0] + r2 * (c[1] + r2 * c[4]))
    den = 1.0 + r2 * (c[5] + r2 * (c[6] + r2 * c[7]))
    return num, den


def _gain(r2, c):
    """Radial gain g(r²) and 2·dg/d(r²); the division is skipped when k4 = k5 = k6 = 0."""
    num = 1.0 + r2 * (c[0] + r2 * (c[1] + r2 * c[4]))
    dnum = c[0] + r2 * (2.0 * c[1] + 3.0 * c[4] * r2)  # d num / d(r²)
    if not (c[5] or c[6] or c[7]):
        return num, 2.0 * dnum
    den = 1.0 + r2 * (c[5] + r2 * (c[6] + r2 * c[7]))
    g = num / den
    dden = c[5] + r2 * (2.0 * c[6] + 3.0 * c[7] * r2)
    return g, 2.0 * (dnum - g * dden) / den


def distort(x, y, c):
    """Undistorted normalized (x, y) -> distorted normalized (x_d, y_d); no validity check."""
    return distort_jac(x, y, c, jacobian=False)


def distort_jac(x, y, c, *, jacobian: bool = True):
    """:func:`distort` and its 2x2 Jacobian d(x_d, y_d)/d(x, y): (xd, yd, j11, j12, j21, j22)."""
    p1, p2, s1, s2, s3, s4 = c[2], c[3], c[8], c[9], c[10], c[11]
    xx, yy, xy = x * x, y * y, x * y
    r2 = xx + yy
    g, dg2 = _gain(r2, c)
    xd = x * g + (2.0 * p1) * xy + p2 * (r2 + 2.0 * xx)
    yd = y * g + p1 * (r2 + 2.0 * yy) + (2.0 * p2) * xy
    prism = bool(s1 or s2 or s3 or s4)
    if prism:
        xd = xd + r2 * (s1 + s2 * r2)
        yd = yd + r2 * (s3 + s4 * r2)
    if not jacobian:
        return xd, yd
    cross = dg2 * xy + (2.0 * p1) * x + (2.0 * p2) * y
    j11 = g + dg2 * xx + (2.0 * p1) * y + (6.0 * p2) * x
    j22 = g + dg2 * yy + (6.0 * p1) * y + (2.0 * p2) * x
    j12 = j21 = cross
    if prism:
        px = s1 + 2.0 * s2 * r2  # d(s1 r² + s2 r⁴)/d(r²)
        py = s3 + 2.0 * s4 * r2
        j11 = j11 + 2.0 * x * px
        j12 = cross + 2.0 * y * px
        j21 = cross + 2.0 * x * py
        j22 = j22 + 2.0 * y * py
    return xd, yd, j11, j12, j21, j22


def coeff_jac(x, y, c) -> np.ndarray:
    """d(x_d, y_d)/dc for the full 12-vector: (..., 2, 12)."""
    xx, yy, xy = x * x, y * y, x * y
    r2 = xx + yy
    r4 = r2 * r2
    r6 = r4 * r2
    num, den = _radial(r2, c)
    g = num / den
    zero = np.zeros_like(x)
    powers = (r2 / den, r4 / den, r6 / den)
    dx = [x * powers[0], x * powers[1], 2.0 * xy, r2 + 2.0 * xx, x * powers[2],
          -x * g * powers[0], -x * g * powers[1], -x * g * powers[2], r2, r4, zero, zero]
    dy = [y * powers[0], y * powers[1], r2 + 2.0 * yy, 2.0 * xy, y * powers[2],
          -y * g * powers[0], -y * g * powers[1], -y * g * powers[2], zero, zero, r2, r4]
    return np.stack([np.stack(dx, axis=-1), np.stack(dy, axis=-1)], axis=-2)


def _smallest_positive_root(coeffs_ascending: np.ndarray) -> float:
    """Smallest positive real root of a polynomial (ascending coefficients), or inf."""
    roots = np.roots(coeffs_ascending[::-1])
    real = roots[np.abs(roots.imag) < 1e-12].real if roots.size else roots.real
    pos = real[real > 0]
    return float(pos.min()) if pos.size else math.inf


@functools.lru_cache(maxsize=1024)
def monotonic_limit(c: tuple) -> float:
    """Largest undistorted radius up to which r -> r·g(r²) increases (cap ``RADIUS_CAP``).

    With u = r², N and D the gain's numerator and denominator, d(r·g)/dr has the sign of
    ``P(u) = (N + 2u·N')·D - 2u·N·D'``; its smallest positive root ends the domain, as does a
    pole of g (a positive root of D, less a small margin). For plumb_bob P = 1 + 3k1·u +
    5k2·u² + 7k3·u³.
    """
    n = np.array([1.0, c[0], c[1], c[4]])
    d = np.array([1.0, c[5], c[6], c[7]])
    if not (np.any(n[1:]) or np.any(d[1:])):
        return RADIUS_CAP
    p = np.convolve(np.array([1.0, 3.0, 5.0, 7.0]) * n, d)
    p = p - 2.0 * np.convolve(n, np.arange(4.0) * d)
    u_fold = _smallest_positive_root(p)
    u_pole = _smallest_positive_root(d) if np.any(d[1:]) else math.inf
    r = min(math.sqrt(u_fold), math.sqrt(u_pole) * (1.0 - _POLE_MARGIN))
    return float(min(r, RADIUS_CAP))


@functools.lru_cache(maxsize=256)
def _radial_lut(c: tuple) -> tuple[np.ndarray, np.ndarray]:
    """Monotone table (r_d, r_u) over [0, monotonic_limit]."""
    r_u = np.linspace(0.0, monotonic_limit(c), _LUT_SIZE)
    num, den = _radial(r_u * r_u, c)
    r_d = r_u * (num / den)
    r_u.setflags(write=False)
    r_d.setflags(write=False)
    return r_d, r_u


def undistort(xd, yd, c, *, tol: float = 1e-9, max_iter: int = 30):
    """Exact inverse of :func:`distort` inside the monotonic domain (flat float64 arrays in).

    Newton on the full 2-D model, started from the monotone radial table. Returns (x, y), NaN
    where the distorted radius is beyond the table, the root lies beyond the monotonic radius,
    or Newton did not give a finite result. With all coefficients zero it is the identity.
    """
    if not np.any(c):
        return xd.copy(), yd.copy()
    key = tuple(float(v) for v in c)
    lut_rd, lut_ru = _radial_lut(key)
    rd = np.hypot(xd, yd)
    outside = rd > lut_rd[-1]
    ru0 = np.interp(rd, lut_rd, lut_ru)
    scale = np.divide(ru0, rd, out=np.ones_like(rd), where=rd > 0)
    x = xd * scale
    y = yd * scale
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        for _ in range(max_iter):
            fx, fy, j11, j12, j21, j22 = distort_jac(x, y, c)
            fx = fx - xd
            fy = fy - yd
            det = j11 * j22 - j12 * j21
            dx = (j22 * fx - j12 * fy) / det
            dy = (j11 * fy - j21 * fx) / det
            x -= dx
            y -= dy
            if np.nanmax(np.abs(dx) + np.abs(dy), initial=0.0) < tol:
                break
        r_mono = lut_ru[-1]
        invalid = outside | ((x * x + y * y) > r_mono * r_mono) | ~np.isfinite(x) | ~np.isfinite(y)
    x[invalid] = np.nan
    y[invalid] = np.nan
    return x, y


# ----------------------------------------------------------------------------- the models
_OPENCV_LENGTHS = (4, 5, 8, 12, 14)  # the lengths cv2 accepts for the pinhole family


class PinholeModel(LensModel):
    """One member of OpenCV's pinhole family: the first ``n`` of the 12 coefficients."""

    IS_FISHEYE = False
    MAX_ANGLE = math.pi / 2
    START = "opencv"
    FAMILY = "opencv"
    FIX_K3 = 4  # [k1, k2, p1, p2, k3, ...]

    def __init__(self, name, coeff_names, ros, rank, *, warm_from=None, extras=(), lengths=None, resolve=None):
        self.NAME, self.COEFF_NAMES, self.RANK = name, tuple(coeff_names), rank
        self.NAMES = {"opencv": "calibrateCamera", "ros": ros,
                      "kalibr": ("pinhole", "radtan") if name == "plumb_bob" else None}
        self.WARM_FROM, self.EXTRA_COEFFS = warm_from, {e: 0.0 for e in extras}
        self.DEFAULT = self.FIT_START = (0.0,) * len(self.COEFF_NAMES)
        self._lengths = lengths or (len(self.COEFF_NAMES),)
        self._resolve = resolve or {}

    def coerce(self, d):
        n = self.n_coeffs
        if d.size == n:
            return d
        if self.NAME == "plumb_bob" and d.size == 4:
            return np.append(d, 0.0)
        if d.size > n and d.size in _OPENCV_LENGTHS:
            if np.any(d[n:]):
                raise ValueError(f"dist for {self.NAME!r} must have {n} coefficients [{', '.join(self.COEFF_NAMES)}]; "
                                 f"got {d.size} with non-zero extras {d[n:].tolist()} (a different model?)")
            return d[:n]
        return None

    def resolve(self, n):
        return self._resolve.get(n, self.NAME if n in self._lengths else None)

    def monotonic_limit(self, d):
        return monotonic_limit(tuple(float(v) for v in full(d)))

    def max_angle(self, d):
        return math.atan(self.monotonic_limit(d))

    def project(self, P, d):
        c = full(d)
        with np.errstate(invalid="ignore", divide="ignore"):
            valid = P[..., 2] > 0
            z = np.where(valid, P[..., 2], 1.0)
            x, y = P[..., 0] / z, P[..., 1] / z
            a, b = distort(x, y, c)
            if np.any(c):
                lim = monotonic_limit(tuple(float(v) for v in c))
                valid = valid & (x * x + y * y <= lim * lim)
        return a, b, valid

    def project_jac(self, P, d):
        c = full(d)
        with np.errstate(invalid="ignore", divide="ignore"):
            valid = P[:, 2] > 0
            iz = 1.0 / np.where(valid, P[:, 2], 1.0)
            x, y = P[:, 0] * iz, P[:, 1] * iz
            a, b, j11, j12, j21, j22 = distort_jac(x, y, c)
        if np.any(c):
            lim = monotonic_limit(tuple(float(v) for v in c))
            valid &= x * x + y * y <= lim * lim
        Jn = np.empty((P.shape[0], 2, 3))
        Jn[:, 0, 0], Jn[:, 0, 1], Jn[:, 0, 2] = j11 * iz, j12 * iz, -(j11 * x + j12 * y) * iz
        Jn[:, 1, 0], Jn[:, 1, 1], Jn[:, 1, 2] = j21 * iz, j22 * iz, -(j21 * x + j22 * y) * iz
        return a, b, valid, Jn, coeff_jac(x, y, c)[..., :d.size]

    def unproject(self, a, b, d):
        x, y = undistort(a, b, full(d))
        rays = np.stack([x, y, np.ones_like(x)], axis=-1)
        return rays / np.linalg.norm(rays, axis=-1, keepdims=True)


_K = ("k1", "k2", "p1", "p2", "k3")
PLUMB_BOB = PinholeModel("plumb_bob", _K, "plumb_bob", 0, lengths=_OPENCV_LENGTHS)
RATIONAL_POLYNOMIAL = PinholeModel("rational_polynomial", _K + ("k4", "k5", "k6"), "rational_polynomial", 4,
                                   warm_from="plumb_bob", extras=("k4", "k5", "k6"), lengths=_OPENCV_LENGTHS,
                                   resolve={4: "plumb_bob", 5: "plumb_bob", 12: "thin_prism", 14: "thin_prism"})
THIN_PRISM = PinholeModel("thin_prism", _K + ("k4", "k5", "k6", "s1", "s2", "s3", "s4"), "rational_polynomial", 5,
                          warm_from="plumb_bob", extras=("k4", "k5", "k6", "s1", "s2", "s3", "s4"), lengths=(12, 14))
