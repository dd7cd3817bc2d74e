"""The renderer's camera: a :class:`aicalib_tf.geometry.lens.Lens` plus the image circle.

All lens maths lives in :mod:`aicalib_tf.geometry.lens` (one implementation per model); this
module only adds what data generation needs on top of it:

* pixel -> ray (:meth:`Camera.pixel_to_ray`), the ray a renderer intersects with the board
  plane. Pinhole models return (x/z, y/z, 1) (so today's renders stay bit-for-bit), the fisheye
  models (``IS_FISHEYE``: equidistant, ds, eucm) return unit rays, valid beyond 90° off-axis;
* the image circle of a fisheye: ``max_theta`` (radians off-axis) bounds what the lens images,
  so a 185° lens sees up to 92.5° and pixels beyond its circle are dark;
* what is imaged (:meth:`Camera.imaged`): in front of the lens, inside the model's monotonic
  domain and inside the circle.

Conventions (``shared/DESIGN.md``): pixels (x, y), centre of pixel (0, 0) at (0.0, 0.0);
``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``; coefficients in OpenCV order for ``model``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from aicalib_tf.geometry import lens as _lens

__all__ = ["Camera", "distort_normalized", "undistort_normalized", "monotonic_radius", "normalized_rays",
           "distortion_field", "model_for_dist"]


def model_for_dist(dist) -> str:
    """The pinhole-family model an OpenCV coefficient vector of this length means (4/5, 8, 12/14)."""
    n = np.asarray(dist, dtype=np.float64).size
    return _lens.model_from_ros("rational_polynomial", n)


def distort_normalized(xy: np.ndarray, dist) -> np.ndarray:
    """Brown–Conrady (OpenCV pinhole family): (..., 2) undistorted normalized -> distorted normalized.

    A thin call into :func:`aicalib_tf.geometry.lens.project_normalized`; NaN beyond the model's
    monotonic radius.
    """
    return _lens.project_normalized(xy, model_for_dist(dist), dist)


def undistort_normalized(xy_d: np.ndarray, dist) -> np.ndarray:
    """Exact inverse of :func:`distort_normalized`: (..., 2) distorted -> undistorted normalized (NaN if none)."""
    rays = _lens.unproject(xy_d, model_for_dist(dist), np.eye(3), dist)
    with np.errstate(divide="ignore", invalid="ignore"):
        return rays[..., :2] / rays[..., 2:3]


def monotonic_radius(dist) -> float:
    """Largest undistorted normalized radius where the pinhole model's radial map increases (cap 20)."""
    return _lens.monotonic_limit(model_for_dist(dist), dist)


def normalized_rays(points: np.ndarray, K: np.ndarray, dist: np.ndarray, *, model: str | None = None,
                    tol_px: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Undistort image points to normalized camera coordinates, and say where that worked.

    points : (N, 2) px. K : (3, 3). dist : coefficients of ``model`` (default: the pinhole
    model of that length). Returns (xy (N, 2) float64 (x/z, y/z), ok (N,) bool): ``ok`` is
    False where no ray exists, the ray is at or behind 90°, or projecting it back misses the
    point by more than ``tol_px`` px.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    model = model or model_for_dist(dist)
    rays = _lens.unproject(pts, model, K, dist)
    with np.errstate(invalid="ignore", divide="ignore"):
        ok = np.all(np.isfinite(rays), axis=1) & (rays[:, 2] > 1e-9)
        xy = rays[:, :2] / rays[:, 2:3]
        back = _lens.project(rays, model, K, dist)
        ok &= np.linalg.norm(back - pts, axis=1) < tol_px
    return np.where(ok[:, None], xy, np.nan), ok


def distortion_field(points: np.ndarray, K: np.ndarray, dist: np.ndarray, *,
                     model: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`aicalib_tf.geometry.lens.distortion_field` with the model inferred from ``dist``'s length.

    points : (N, 2) px. Returns (field (N, 2) px = ideal pinhole image - point, ok (N,) bool).
    """
    return _lens.distortion_field(points, model or model_for_dist(dist), K, dist)


@dataclass(frozen=True, eq=False)
class Camera:
    """An intrinsic camera for rendering: lens model, K, coefficients, image size, image circle.

    Attributes
    ----------
    K : (3, 3) float64 camera matrix, px.
    dist : (n,) float64 coefficients for ``model`` (plumb_bob: [k1, k2, p1, p2, k3]).
    image_size : (width, height) px.
    model : a :data:`aicalib_tf.geometry.lens.MODELS` name; "plumb_bob" by default.
    max_theta : largest off-axis angle the lens images (radians); None: the model's own domain.
        For a fisheye it sets the image circle (radius ``f·θ_d(max_theta)`` px).
    lens : the :class:`~aicalib_tf.geometry.lens.Lens` (derived).
    r_mono : :func:`aicalib_tf.geometry.lens.monotonic_limit` (normalized radius for pinhole
        models, θ in radians for the fisheye models; derived).
    """

    K: np.ndarray
    dist: np.ndarray
    image_size: tuple[int, int]
    model: str = "plumb_bob"
    max_theta: float | None = None
    lens: _lens.Lens = field(init=False, repr=False)
    r_mono: float = field(init=False, repr=False)

    def __post_init__(self):
        ln = _lens.Lens(self.model, np.asarray(self.K, dtype=np.float64).reshape(3, 3), self.dist, self.image_size)
        if self.max_theta is not None and not 0.0 < float(self.max_theta) <= math.pi:
            raise ValueError(f"max_theta must be in (0, pi] radians, got {self.max_theta}")
        object.__setattr__(self, "lens", ln)
        object.__setattr__(self, "K", ln.K)
        object.__setattr__(self, "dist", ln.dist)
        object.__setattr__(self, "image_size", ln.image_size)
        object.__setattr__(self, "model", ln.model)
        object.__setattr__(self, "r_mono", ln.monotonic_limit())
        if self.max_theta is not None:
            object.__setattr__(self, "max_theta", float(self.max_theta))

    fx = property(lambda self: float(self.K[0, 0]), doc="Focal length x, px.")
    fy = property(lambda self: float(self.K[1, 1]), doc="Focal length y, px.")
    cx = property(lambda self: float(self.K[0, 2]), doc="Principal point x, px.")
    cy = property(lambda self: float(self.K[1, 2]), doc="Principal point y, px.")

    @property
    def fisheye(self) -> bool:
        """True for a model that images rays at and beyond 90° (``IS_FISHEYE``: equidistant, ds, eucm)."""
        return self.lens.spec.IS_FISHEYE

    def theta_limit(self) -> float:
        """Largest imaged off-axis angle, radians: ``max_theta`` or the model's domain (pinhole: < π/2)."""
        lim = self.lens.max_angle()
        return lim if self.max_theta is None else min(lim, self.max_theta)

    def circle_radius(self) -> float:
        """The image circle's radius in normalized distorted units (px = this·fx, ·fy); inf for pinhole."""
        if not self.fisheye:
            return math.inf
        return self.lens.spec.radius(self.theta_limit(), self.dist)

    def inside_circle(self, uv: np.ndarray) -> np.ndarray:
        """(...,) bool: pixels (..., 2) inside the image circle (always True for pinhole models)."""
        uv = np.asarray(uv, dtype=np.float64)
        if not self.fisheye:
            return np.ones(uv.shape[:-1], dtype=bool)
        rho = np.hypot((uv[..., 0] - self.cx) / self.fx, (uv[..., 1] - self.cy) / self.fy)
        return rho <= self.circle_radius()

    def pixel_to_ray(self, uv: np.ndarray) -> np.ndarray:
        """(..., 2) px -> (..., 3) rays, NaN where not imaged.

        Pinhole models: (x/z, y/z, 1). Fisheye models: unit rays (any direction up to ``max_theta``).
        """
        uv = np.asarray(uv, dtype=np.float64)
        if not self.fisheye:
            xy = self.pixel_to_normalized(uv)
            return np.concatenate([xy, np.where(np.isnan(xy[..., :1]), np.nan, 1.0)], axis=-1)
        rays = self.lens.unproject(uv)
        if self.max_theta is not None:
            with np.errstate(invalid="ignore"):
                out = np.arctan2(np.hypot(rays[..., 0], rays[..., 1]), rays[..., 2]) > self.max_theta
            rays = np.where(out[..., None], np.nan, rays)
        return rays

    def pixel_to_normalized(self, uv: np.ndarray) -> np.ndarray:
        """(..., 2) px -> (..., 2) undistorted normalized (x/z, y/z); NaN if not imaged or at/behind 90°."""
        uv = np.asarray(uv, dtype=np.float64)
        if self.fisheye:
            rays = self.pixel_to_ray(uv)
            with np.errstate(invalid="ignore", divide="ignore"):
                z = np.where(rays[..., 2:3] > 1e-12, rays[..., 2:3], np.nan)
                return rays[..., :2] / z
        xd = (uv[..., 0] - self.cx) / self.fx
        yd = (uv[..., 1] - self.cy) / self.fy
        return undistort_normalized(np.stack([xd, yd], axis=-1), self.dist)

    def normalized_to_pixel(self, xy: np.ndarray) -> np.ndarray:
        """(..., 2) undistorted normalized (x/z, y/z) -> (..., 2) px (NaN where not imaged)."""
        xy = np.asarray(xy, dtype=np.float64)
        return self.project(np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1))

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """(..., 3) camera-frame points -> (..., 2) px via :func:`aicalib_tf.geometry.lens.project`; NaN where not imaged."""
        P = np.asarray(points_cam, dtype=np.float64)
        uv = self.lens.project(P)
        return np.where(self.imaged(P)[..., None], uv, np.nan)

    def imaged(self, points_cam: np.ndarray) -> np.ndarray:
        """(...,) bool: points (..., 3) the lens images: in front, in the monotonic domain, in the circle."""
        P = np.asarray(points_cam, dtype=np.float64)
        x, y, z = P[..., 0], P[..., 1], P[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            if not self.fisheye:
                r = np.hypot(x / z, y / z)
                ok = (z > 0) & (r < self.r_mono)
                if self.max_theta is not None:
                    ok &= np.arctan(r) <= self.max_theta
                return ok
            theta = np.arctan2(np.hypot(x, y), z)
            return np.isfinite(theta) & (theta < self.theta_limit() + (0.0 if self.max_theta is None else 1e-12))

    def horizontal_fov_deg(self) -> float:
        """Full horizontal field of view through the principal point, degrees (capped by the circle)."""
        h = _lens.field_of_view(self.model, self.K, self.dist, self.image_size)["horizontal"]
        cap = 2.0 * math.degrees(self.theta_limit())
        return cap if not math.isfinite(h) else min(h, cap)

    def diagonal_fov_deg(self) -> float:
        """Full diagonal field of view, degrees: the corners' angles, or the circle's where it is inside the frame."""
        d = _lens.field_of_view(self.model, self.K, self.dist, self.image_size)["diagonal"]
        cap = 2.0 * math.degrees(self.theta_limit())
        return cap if not math.isfinite(d) else min(d, cap)

    def to_dict(self) -> dict:
        """JSON-able {"model", "K", "dist", "image_size", "max_theta_deg"} (null: the model's domain)."""
        return {"model": self.model, "K": self.K.tolist(), "dist": self.dist.tolist(),
                "image_size": list(self.image_size),
                "max_theta_deg": None if self.max_theta is None else math.degrees(self.max_theta)}
