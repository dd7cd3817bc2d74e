"""Pinhole camera with OpenCV's Brown–Conrady distortion and its exact inverse.

Conventions (see ``docs`` and ``../shared/DESIGN.md``):

* Pixel coordinates are (x, y); the centre of pixel (0, 0) is (0.0, 0.0).
* ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``.
* ``dist = [k1, k2, p1, p2, k3]``, the model of ``cv2.projectPoints``:
  ``x_d = x·g(r²) + 2·p1·x·y + p2·(r² + 2x²)`` and
  ``y_d = y·g(r²) + p1·(r² + 2y²) + 2·p2·x·y`` with ``g = 1 + k1·r² + k2·r⁴ + k3·r⁶``.

The inverse (distorted → undistorted normalized coordinates) is solved exactly by Newton's
method started from a monotone radial look-up table, so it converges to the root inside the
model's monotonic domain and agrees with ``cv2.projectPoints`` to ~1e-9 px.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import cv2
import numpy as np

__all__ = ["Camera", "distort_normalized", "undistort_normalized", "monotonic_radius", "normalized_rays", "distortion_field"]

# Radial look-up table resolution for the Newton start; Newton polishes to machine precision.
_LUT_SIZE = 2048
_MAX_RADIUS = 20.0  # normalized radius beyond which we never look (~87 degrees off-axis)


def _radial_gain(r2: np.ndarray, k1: float, k2: float, k3: float) -> np.ndarray:
    return 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))


def distort_normalized(xy: np.ndarray, dist) -> np.ndarray:
    """Apply Brown–Conrady distortion.

    Parameters
    ----------
    xy : (..., 2) float, undistorted normalized coordinates (x/z, y/z).
    dist : (5,) ``[k1, k2, p1, p2, k3]``.

    Returns
    -------
    (..., 2) float64, distorted normalized coordinates.
    """
    k1, k2, p1, p2, k3 = (float(v) for v in np.asarray(dist, dtype=np.float64).ravel()[:5])
    x = np.asarray(xy, dtype=np.float64)[..., 0]
    y = np.asarray(xy, dtype=np.float64)[..., 1]
    r2 = x * x + y * y
    g = _radial_gain(r2, k1, k2, k3)
    xd = x * g + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * g + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.stack([xd, yd], axis=-1)


def monotonic_radius(dist) -> float:
    """Largest undistorted radius up to which the radial map r -> r·g(r²) is increasing.

    The derivative is ``1 + 3k1·u + 5k2·u² + 7k3·u³`` with u = r²; its smallest positive root
    ends the monotonic domain. Returns ``_MAX_RADIUS`` when there is none below it. Beyond this
    radius the polynomial folds back, so points there are not imaged.
    """
    k1, k2, _, _, k3 = (float(v) for v in np.asarray(dist, dtype=np.float64).ravel()[:5])
    return _monotonic_radius(k1, k2, k3)


@functools.lru_cache(maxsize=256)
def _monotonic_radius(k1: float, k2: float, k3: float) -> float:
    roots = np.roots([7.0 * k3, 5.0 * k2, 3.0 * k1, 1.0]) if (k1 or k2 or k3) else np.array([])
    real = roots[np.abs(roots.imag) < 1e-12].real if roots.size else roots
    pos = real[real > 0]
    if pos.size == 0:
        return _MAX_RADIUS
    return float(min(math.sqrt(pos.min()), _MAX_RADIUS))


def _radial_lut(dist) -> tuple[np.ndarray, np.ndarray]:
    k1, k2, _, _, k3 = (float(v) for v in np.asarray(dist, dtype=np.float64).ravel()[:5])
    r_u = np.linspace(0.0, monotonic_radius(dist), _LUT_SIZE)
    r_d = r_u * _radial_gain(r_u * r_u, k1, k2, k3)
    return r_d, r_u


def undistort_normalized(xy_d: np.ndarray, dist, *, tol: float = 1e-9, max_iter: int = 30) -> np.ndarray:
    """Exact inverse of :func:`distort_normalized` inside the monotonic domain.

    Parameters
    ----------
    xy_d : (..., 2) float, distorted normalized coordinates.
    dist : (5,) ``[k1, k2, p1, p2, k3]``.

    Returns
    -------
    (..., 2) float64 undistorted normalized coordinates; NaN where no inverse exists inside
    the monotonic domain (the point cannot be the image of any visible ray). Newton converges
    quadratically, so stopping when the step is below ``tol`` = 1e-9 leaves an error near
    machine precision.
    """
    dist = np.asarray(dist, dtype=np.float64).ravel()[:5]
    k1, k2, p1, p2, k3 = (float(v) for v in dist)
    xy_d = np.asarray(xy_d, dtype=np.float64)
    shape = xy_d.shape
    xd = xy_d[..., 0].ravel()
    yd = xy_d[..., 1].ravel()
    if not np.any(dist):
        return xy_d.astype(np.float64, copy=True)

    # Radial start from the monotone table.
    lut_rd, lut_ru = _radial_lut(dist)
    rd = np.hypot(xd, yd)
    outside = rd > lut_rd[-1]
    ru0 = np.interp(rd, lut_rd, lut_ru)
    scale = np.divide(ru0, rd, out=np.ones_like(rd), where=rd > 0)
    x = xd * scale
    y = yd * scale

    # Newton on the full 2-D model (radial + tangential).
    for _ in range(max_iter):
        xx, yy, xy = x * x, y * y, x * y
        r2 = xx + yy
        g = _radial_gain(r2, k1, k2, k3)
        dg = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # dg/d(r2)
        fx = x * g + (2.0 * p1) * xy + p2 * (r2 + 2.0 * xx) - xd
        fy = y * g + p1 * (r2 + 2.0 * yy) + (2.0 * p2) * xy - yd
        j11 = g + (2.0 * dg) * xx + (2.0 * p1) * y + (6.0 * p2) * x
        j12 = (2.0 * dg) * xy + (2.0 * p1) * x + (2.0 * p2) * y  # the Jacobian is symmetric
        j22 = g + (2.0 * dg) * yy + (6.0 * p1) * y + (2.0 * p2) * x
        det = j11 * j22 - j12 * j12
        dx = (j22 * fx - j12 * fy) / det
        dy = (j11 * fy - j12 * fx) / det
        x -= dx
        y -= dy
        if np.nanmax(np.abs(dx) + np.abs(dy), initial=0.0) < tol:
            break
    r_mono = lut_ru[-1]
    invalid = outside | ((x * x + y * y) > r_mono * r_mono) | ~np.isfinite(x) | ~np.isfinite(y)
    x[invalid] = np.nan
    y[invalid] = np.nan
    return np.stack([x, y], axis=-1).reshape(shape)


@dataclass(frozen=True)
class Camera:
    """An intrinsic camera model.

    Attributes
    ----------
    K : (3, 3) float64 camera matrix, px.
    dist : (5,) float64 ``[k1, k2, p1, p2, k3]``.
    image_size : (width, height) px.
    """

    K: np.ndarray
    dist: np.ndarray
    image_size: tuple[int, int]
    r_mono: float = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        K = np.asarray(self.K, dtype=np.float64).reshape(3, 3)
        dist = np.zeros(5) if self.dist is None else np.asarray(self.dist, dtype=np.float64).ravel()
        if dist.size != 5:
            raise ValueError(f"dist must have 5 coefficients [k1, k2, p1, p2, k3], got {dist.size}")
        w, h = (int(v) for v in self.image_size)
        if w < 1 or h < 1:
            raise ValueError(f"image_size must be (width, height) >= (1, 1), got {self.image_size}")
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ValueError(f"focal lengths must be positive, got fx={K[0, 0]}, fy={K[1, 1]}")
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "dist", dist)
        object.__setattr__(self, "image_size", (w, h))
        object.__setattr__(self, "r_mono", monotonic_radius(dist))

    @property
    def fx(self) -> float:
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        return float(self.K[1, 2])

    def pixel_to_normalized(self, uv: np.ndarray) -> np.ndarray:
        """(..., 2) pixels (x, y) -> (..., 2) undistorted normalized coordinates (NaN if not imaged)."""
        uv = np.asarray(uv, dtype=np.float64)
        xd = (uv[..., 0] - self.cx) / self.fx
        yd = (uv[..., 1] - self.cy) / self.fy
        return undistort_normalized(np.stack([xd, yd], axis=-1), self.dist)

    def normalized_to_pixel(self, xy: np.ndarray) -> np.ndarray:
        """(..., 2) undistorted normalized coordinates -> (..., 2) pixels (x, y)."""
        d = distort_normalized(xy, self.dist)
        return np.stack([d[..., 0] * self.fx + self.cx, d[..., 1] * self.fy + self.cy], axis=-1)

    def horizontal_fov_deg(self) -> float:
        """Full horizontal field of view through the principal point, degrees."""
        w, _ = self.image_size
        left = self.pixel_to_normalized(np.array([-0.5, self.cy]))[0]
        right = self.pixel_to_normalized(np.array([w - 0.5, self.cy]))[0]
        return math.degrees(math.atan(abs(left)) + math.atan(abs(right)))

    def to_dict(self) -> dict:
        return {"K": self.K.tolist(), "dist": self.dist.tolist(), "image_size": list(self.image_size)}


_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)


def normalized_rays(points: np.ndarray, K: np.ndarray, dist: np.ndarray, *,
                    tol_px: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Undistort image points to normalized camera coordinates, and say where that worked.

    points : (N, 2) float (x, y) px in the distorted image. K : (3, 3). dist : OpenCV coefficients.
    Returns (xy (N, 2) float64 normalized (x/z, y/z), ok (N,) bool). ``ok`` is False where the
    iterative inverse did not converge: re-distorting misses the point by more than ``tol_px``
    px (e.g. beyond a strong lens' fold).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 1, 2)
    K = np.asarray(K, dtype=np.float64)
    dist = np.asarray(dist, dtype=np.float64).ravel()
    xy = cv2.undistortPoints(pts, K, dist, R=None, P=None, criteria=_UNDISTORT_CRITERIA).reshape(-1, 2)
    obj = np.concatenate([xy, np.ones((len(xy), 1))], axis=1)
    back, _ = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), K, dist)
    ok = np.linalg.norm(back.reshape(-1, 2) - pts.reshape(-1, 2), axis=1) < tol_px
    return xy, ok


def distortion_field(points: np.ndarray, K: np.ndarray, dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The displacement a lens model's undistortion applies to image points.

    points : (N, 2) float (x, y) px in the distorted image. K : (3, 3). dist : OpenCV coefficients.
    Returns (field (N, 2) px, ok (N,) bool): ``field = undistorted - points``, both in the model's
    own pixel frame (``P = K``); ``ok`` as in :func:`normalized_rays` (1e-3 px).
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    K = np.asarray(K, dtype=np.float64)
    xy, ok = normalized_rays(pts, K, dist)
    ideal = xy * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]
    return ideal - pts, ok


