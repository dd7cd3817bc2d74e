"""Lens models: one implementation of each, for the renderer, the calibration fit and the files.

Conventions (``shared/DESIGN.md``): pixels are (x, y) with the centre of pixel (0, 0) at
(0.0, 0.0), as in OpenCV; ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (no skew); camera
points are (X, Y, Z) with Z along the optical axis. Coefficients are in OpenCV's order:

* ``plumb_bob``: [k1, k2, p1, p2, k3] (``cv2.projectPoints`` with 5 coefficients);
* ``rational_polynomial``: [k1, k2, p1, p2, k3, k4, k5, k6] (``CALIB_RATIONAL_MODEL``);
* ``thin_prism``: [k1, ..., k6, s1, s2, s3, s4] (``CALIB_THIN_PRISM_MODEL``; in ROS files it
  is written as ``rational_polynomial`` with 12 coefficients);
* ``equidistant``: Kannala–Brandt [k1, k2, k3, k4] as ``cv2.fisheye``, with θ = atan2(r, Z) so
  that lenses of 180–200° work;
* ``ds``: Double Sphere [ξ, α] and ``eucm``: Extended Unified [α, β], as Kalibr and basalt name
  and order them (neither has an OpenCV or ROS name; files call them ``ds`` and ``eucm``).

Each model is one module behind one interface (:mod:`~aicalib_tf.geometry.lens_model`), listed
in :mod:`~aicalib_tf.geometry.lens_registry`; this module validates inputs, applies K and
dispatches. Each model is valid only in its domain (:func:`monotonic_limit`); beyond it,
:func:`project` and :func:`unproject` return NaN. :func:`unproject` is the exact inverse of
:func:`project` (Newton iterations or closed form, not OpenCV's fixed-point ``undistortPoints``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .image_circle import circle_tuple, into_circle
from .lens_model import LensModel, pixel_jacobians
from .lens_registry import MODELS, REGISTRY, get_model, model_from_file_name, per_model

__all__ = [
    "MODELS", "N_COEFFS", "COEFF_NAMES", "ROS_NAMES", "Lens", "check_model", "model_from_ros", "get_model",
    "project", "project_normalized", "unproject", "monotonic_limit", "max_angle", "distortion_field",
    "field_of_view", "undistort_maps", "projection_jacobian",
]

COEFF_NAMES = per_model(lambda spec: spec.COEFF_NAMES)  # also a family's configured names (lens_registry)
N_COEFFS = per_model(lambda spec: spec.n_coeffs)
ROS_NAMES = per_model(lambda spec: spec.NAMES["ros"])


# ----------------------------------------------------------------------------- validation
def check_model(model: str, dist) -> tuple[str, np.ndarray]:
    """Validate a model name and its coefficients; return (model, dist (n,) float64 copy).

    ``dist=None`` means the model's undistorted case (all zeros; EUCM [0, 1]). An OpenCV-length
    vector longer than a pinhole model's count is accepted when the extra coefficients are all
    zero (they are dropped); plumb_bob also accepts OpenCV's 4-vector [k1, k2, p1, p2] (k3 = 0).
    Coefficients outside the model's range (DS ξ ∈ (−1, 1], α ∈ [0, 1]; EUCM α ∈ [0, 1], β > 0)
    are refused. Raises ValueError otherwise.
    """
    if not isinstance(model, str) or model not in REGISTRY:
        raise ValueError(f"unknown lens model {model!r}; expected one of {MODELS}")
    spec = REGISTRY[model]
    if dist is None:
        return model, np.array(spec.DEFAULT, dtype=np.float64)
    d = np.asarray(dist, dtype=np.float64).ravel().copy()
    if not np.all(np.isfinite(d)):
        raise ValueError(f"dist for {model!r} must be finite, got {d.tolist()}")
    out = spec.coerce(d)
    if out is None:
        raise ValueError(f"dist for {model!r} must have {spec.n_coeffs} coefficients [{', '.join(spec.COEFF_NAMES)}], "
                         f"got {d.size}")
    why = spec.range_problem(out)
    if why is not None:
        raise ValueError(f"dist for {model!r}: {why}")
    return model, out


def model_from_ros(name: str, n_coeffs: int) -> str:
    """Our model name for a file's ``distortion_model`` string and its coefficient count.

    ``rational_polynomial`` with 12 (or 14, OpenCV's tilt terms) coefficients is ``thin_prism``,
    with 4 or 5 it is ``plumb_bob``; ``fisheye`` is an alias of ``equidistant``; ``ds`` and ``eucm``
    (also ``double_sphere``, ``extended_unified``) take 2. Counts longer than the model's are
    allowed for OpenCV lengths; :func:`check_model` then requires the extras to be zero. Raises
    ValueError for unknown names and impossible counts.
    """
    return model_from_file_name(name, n_coeffs)


def _check_K(K, what: str = "K") -> np.ndarray:
    arr = np.asarray(K, dtype=np.float64)
    if arr.shape != (3, 3):
        raise ValueError(f"{what} must be a 3x3 camera matrix, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what} must be finite, got {arr.tolist()}")
    if arr[0, 0] <= 0 or arr[1, 1] <= 0:
        raise ValueError(f"{what}: focal lengths must be positive, got fx={arr[0, 0]}, fy={arr[1, 1]}")
    if arr[0, 1] != 0 or arr[1, 0] != 0 or not np.array_equal(arr[2], [0.0, 0.0, 1.0]):
        raise ValueError(f"{what} must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] (no skew), got {arr.tolist()}")
    return arr


def _check_size(image_size, what: str = "image_size") -> tuple[int, int]:
    try:
        w, h = (int(v) for v in image_size)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be (width, height), got {image_size!r}") from None
    if w < 1 or h < 1:
        raise ValueError(f"{what} must be (width, height) >= (1, 1), got {image_size!r}")
    return w, h


def _check_points(points, dim: int, what: str) -> np.ndarray:
    arr = np.asarray(points, dtype=np.float64)
    if arr.ndim == 0 or arr.shape[-1] != dim:
        raise ValueError(f"{what} must have shape (..., {dim}), got {arr.shape}")
    return arr


# ----------------------------------------------------------------------------- the maps
def monotonic_limit(model: str, dist) -> float:
    """Where the model's map stops being valid (cached per coefficient vector).

    Pinhole models: the largest undistorted normalized radius r (= tan of the off-axis angle)
    up to which r -> r·g(r²) increases, capped at 20.0. Equidistant: the largest θ (radians,
    capped at π) up to which θ -> θ_d(θ) increases. DS and EUCM: the largest off-axis angle of
    their valid-projection domain, radians.
    """
    model, d = check_model(model, dist)
    return REGISTRY[model].monotonic_limit(d)


def max_angle(model: str, dist) -> float:
    """The widest off-axis angle (radians) the model images with these coefficients (< π/2 for pinholes)."""
    model, d = check_model(model, dist)
    return REGISTRY[model].max_angle(d)


def _project_normalized(P: np.ndarray, spec: LensModel, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(a, b) normalized, NaN where the model does not image the point."""
    a, b, valid = spec.project(P, d)
    return np.where(valid, a, np.nan), np.where(valid, b, np.nan)


def project_normalized(xy, model: str, dist) -> np.ndarray:
    """Project the rays (x, y, 1) to normalized image coordinates: (..., 2) float64.

    For the pinhole models the result is the distorted (x/z, y/z), K⁻¹ of the pixel (NaN beyond
    the monotonic radius); for the other models K⁻¹ of the pixel of the ray (x, y, 1), e.g.
    ``equidistant``'s (θ_d·x/r, θ_d·y/r).
    """
    model, d = check_model(model, dist)
    xy = _check_points(xy, 2, "xy")
    P = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
    return np.stack(_project_normalized(P, REGISTRY[model], d), axis=-1)


def project(points, model: str, K, dist) -> np.ndarray:
    """Project camera-frame points to pixels.

    points : (..., 3) float, camera frame, any scale. K : (3, 3). dist : (n,) as ``model``.
    Returns (..., 2) float64 pixels (x, y); NaN where Z <= 0 (pinhole models) or outside the
    model's domain (:func:`monotonic_limit`).

    >>> K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
    >>> project([0.0, 0.0, 2.0], "plumb_bob", K, [-0.3, 0.1, 0.0, 0.0, 0.0])
    array([320., 240.])
    >>> project([[0.2, -0.1, 1.0], [0.0, 0.0, -1.0]], "plumb_bob", K, None)
    array([[420., 190.],
           [ nan,  nan]])
    """
    model, d = check_model(model, dist)
    K = _check_K(K)
    P = _check_points(points, 3, "points")
    a, b = _project_normalized(P, REGISTRY[model], d)
    return np.stack([K[0, 0] * a + K[0, 2], K[1, 1] * b + K[1, 2]], axis=-1)


def unproject(pixels, model: str, K, dist) -> np.ndarray:
    """Pixels -> unit rays in the camera frame, the exact inverse of :func:`project`.

    pixels : (..., 2) float (x, y) px. Returns (..., 3) float64 rays of norm 1; NaN rows where
    the pixel is not the image of any ray inside the model's domain.

    >>> K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
    >>> unproject([320.0, 240.0], "equidistant", K, [0.01, 0.0, 0.0, 0.0])
    array([0., 0., 1.])
    >>> unproject([[820.0, 240.0]], "plumb_bob", K, None)  # 45 degrees off-axis
    array([[0.70710678, 0.        , 0.70710678]])
    """
    model, d = check_model(model, dist)
    K = _check_K(K)
    px = _check_points(pixels, 2, "pixels")
    shape = px.shape[:-1]
    a = ((px[..., 0] - K[0, 2]) / K[0, 0]).ravel()
    b = ((px[..., 1] - K[1, 2]) / K[1, 1]).ravel()
    return REGISTRY[model].unproject(a, b, d).reshape(shape + (3,))


def distortion_field(pixels, model: str, K, dist) -> tuple[np.ndarray, np.ndarray]:
    """Displacement from distorted pixels to their ideal pinhole image with the same K.

    pixels : (N, 2) px. Returns (field (N, 2) float64 px, ok (N,) bool) with
    ``field = K·(x/z, y/z) - pixel``; where ``ok`` is False (no ray, or z <= 1e-9: the ray is
    at or behind 90°) the field is NaN.
    """
    K = _check_K(K)
    px = _check_points(pixels, 2, "pixels").reshape(-1, 2)
    rays = unproject(px, model, K, dist)
    with np.errstate(invalid="ignore"):
        ok = np.all(np.isfinite(rays), axis=1) & (rays[:, 2] > 1e-9)
    z = np.where(ok, rays[:, 2], 1.0)
    ideal = np.stack([K[0, 0] * rays[:, 0] / z + K[0, 2], K[1, 1] * rays[:, 1] / z + K[1, 2]], axis=1)
    field = np.where(ok[:, None], ideal - px, np.nan)
    return field, ok


def field_of_view(model: str, K, dist, image_size, circle=None) -> dict:
    """Full fields of view in degrees: {"horizontal", "vertical", "diagonal", "beyond_model"}; never NaN.

    Each is the sum of the two half-angles from the optical axis of opposite edge rays (so it
    exceeds 180° for a wide fisheye): the image edges x = -0.5 and w - 0.5 at y = cy, likewise
    vertically through cx, and the larger of the two corner diagonals. ``circle`` (an image
    circle: (cx, cy, radius) px or an :class:`~aicalib_tf.geometry.image_circle.ImageCircle`): an
    edge point outside it is moved along the line from the principal point onto the circle, so a
    circular fisheye's field is that of its circle, not of the black corners. An edge pixel with
    no ray (beyond a circular fisheye's valid region, or a pinhole's monotonic radius) counts with
    the widest angle the model images (:func:`max_angle`); "beyond_model" is then True.
    """
    K = _check_K(K)
    w, h = _check_size(image_size)
    cx, cy = K[0, 2], K[1, 2]
    lo, hx, hy = -0.5, w - 0.5, h - 0.5
    pts = np.array([[lo, cy], [hx, cy], [cx, lo], [cx, hy], [lo, lo], [hx, hy], [hx, lo], [lo, hy]])
    if circle is not None:
        pts = into_circle(pts, (cx, cy), circle)
    rays = unproject(pts, model, K, dist)
    half = np.degrees(np.arctan2(np.hypot(rays[:, 0], rays[:, 1]), rays[:, 2]))
    beyond = bool(np.isnan(half).any())
    half = np.where(np.isnan(half), np.degrees(max_angle(model, dist)), half)
    diag = max(half[4] + half[5], half[6] + half[7])
    return {"horizontal": float(half[0] + half[1]), "vertical": float(half[2] + half[3]), "diagonal": float(diag),
            "beyond_model": beyond}


def undistort_maps(model: str, K, dist, image_size, *, new_K=None, R=None,
                   new_size=None, circle=None) -> tuple[np.ndarray, np.ndarray]:
    """Maps for ``cv2.remap`` from the distorted image to an ideal (rectified) pinhole image.

    For each output pixel (u, v) of the pinhole camera ``new_K`` (default K) of ``new_size``
    (default ``image_size``), rotated by ``R`` (3x3, default identity; the ray is
    Rᵀ·new_K⁻¹·(u, v, 1), as ``cv2.initUndistortRectifyMap``), where to sample the distorted
    image. Returns (map_x, map_y), float32 (H, W) px; -1 where the ray is not imaged, or where it
    lands outside ``circle`` (an image circle, as in :func:`field_of_view`; None: no circle).
    """
    model, d = check_model(model, dist)
    K = _check_K(K)
    w, h = _check_size(image_size if new_size is None else new_size, "new_size")
    P = K if new_K is None else _check_K(new_K, "new_K")
    Rm = np.eye(3) if R is None else np.asarray(R, dtype=np.float64)
    if Rm.shape != (3, 3):
        raise ValueError(f"R must be a 3x3 rotation matrix, got shape {Rm.shape}")
    maps = np.empty((2, h, w), np.float32)
    band = max(1, (1 << 18) // w)  # rows at a time: a 12 MP image's float64 rays and their temporaries took 1.5 GB at once
    for y0 in range(0, h, band):
        u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(y0, min(h, y0 + band), dtype=np.float64))
        rays = np.stack([(u - P[0, 2]) / P[0, 0], (v - P[1, 2]) / P[1, 1], np.ones_like(u)], axis=-1)
        uv = project(rays @ Rm, model, K, d)  # row vectors: (Rᵀ·p)ᵀ = pᵀ·R
        if circle is not None:
            ccx, ccy, r = circle_tuple(circle)
            with np.errstate(invalid="ignore"):
                uv[np.hypot(uv[..., 0] - ccx, uv[..., 1] - ccy) > r] = np.nan
        uv = np.where(np.isfinite(uv), uv, -1.0).astype(np.float32)
        maps[0, y0:y0 + band], maps[1, y0:y0 + band] = uv[..., 0], uv[..., 1]
    return maps[0], maps[1]


def projection_jacobian(points, model: str, K, dist) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels of :func:`project` and their analytic derivatives (vectorised).

    points : (N, 3) camera frame. Returns uv (N, 2) px, J_points (N, 2, 3) d(uv)/d(X, Y, Z)
    px per unit, and J_intr (N, 2, 4 + n) d(uv)/d[fx, fy, cx, cy, *dist]. NaN rows where
    :func:`project` gives NaN.
    """
    model, d = check_model(model, dist)
    K = _check_K(K)
    P = _check_points(points, 3, "points").reshape(-1, 3)
    a, b, valid, Jn, Jc = REGISTRY[model].project_jac(P, d)
    uv, J_points, J_intr = pixel_jacobians(a, b, Jn, Jc, K)
    bad = ~valid
    uv[bad], J_points[bad], J_intr[bad] = np.nan, np.nan, np.nan
    return uv, J_points, J_intr


# ----------------------------------------------------------------------------- the camera
@dataclass(frozen=True, eq=False)
class Lens:
    """An intrinsic camera: lens model, camera matrix, coefficients and image size.

    Attributes
    ----------
    model : one of :data:`MODELS`.
    K : (3, 3) float64 camera matrix, px (read-only).
    dist : (n,) float64 coefficients for ``model``, in OpenCV's (Kalibr's for ds, eucm) order (read-only).
    image_size : (width, height) px.
    """

    model: str
    K: np.ndarray
    dist: np.ndarray
    image_size: tuple[int, int]

    def __post_init__(self):
        model, d = check_model(self.model, self.dist)
        K = _check_K(self.K).copy()
        K.setflags(write=False)
        d.setflags(write=False)
        object.__setattr__(self, "model", model)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "dist", d)
        object.__setattr__(self, "image_size", _check_size(self.image_size))

    def __eq__(self, other):
        if not isinstance(other, Lens):
            return NotImplemented
        return (self.model == other.model and self.image_size == other.image_size
                and np.array_equal(self.K, other.K) and np.array_equal(self.dist, other.dist))

    def __hash__(self):
        return hash((self.model, self.K.tobytes(), self.dist.tobytes(), self.image_size))

    fx = property(lambda self: float(self.K[0, 0]), doc="Focal length x, px.")
    fy = property(lambda self: float(self.K[1, 1]), doc="Focal length y, px.")
    cx = property(lambda self: float(self.K[0, 2]), doc="Principal point x, px.")
    cy = property(lambda self: float(self.K[1, 2]), doc="Principal point y, px.")

    def project(self, points) -> np.ndarray:
        """(..., 3) camera points -> (..., 2) px; see :func:`project`."""
        return project(points, self.model, self.K, self.dist)

    def unproject(self, pixels) -> np.ndarray:
        """(..., 2) px -> (..., 3) unit rays; see :func:`unproject`."""
        return unproject(pixels, self.model, self.K, self.dist)

    def distortion_field(self, pixels) -> tuple[np.ndarray, np.ndarray]:
        """See :func:`distortion_field`."""
        return distortion_field(pixels, self.model, self.K, self.dist)

    def field_of_view(self, circle=None) -> dict:
        """See :func:`field_of_view`."""
        return field_of_view(self.model, self.K, self.dist, self.image_size, circle)

    def undistort_maps(self, *, new_K=None, R=None, new_size=None, circle=None) -> tuple[np.ndarray, np.ndarray]:
        """See :func:`undistort_maps`."""
        return undistort_maps(self.model, self.K, self.dist, self.image_size,
                              new_K=new_K, R=R, new_size=new_size, circle=circle)

    def projection_jacobian(self, points):
        """See :func:`projection_jacobian`."""
        return projection_jacobian(points, self.model, self.K, self.dist)

    def monotonic_limit(self) -> float:
        """See :func:`monotonic_limit`."""
        return monotonic_limit(self.model, self.dist)

    def max_angle(self) -> float:
        """See :func:`max_angle` (radians)."""
        return max_angle(self.model, self.dist)

    @property
    def spec(self) -> LensModel:
        """The lens model's implementation and attributes (:class:`~aicalib_tf.geometry.lens_model.LensModel`)."""
        return REGISTRY[self.model]

    def intrinsics(self) -> np.ndarray:
        """(4 + n,) float64 vector [fx, fy, cx, cy, *dist]."""
        return np.concatenate([[self.fx, self.fy, self.cx, self.cy], self.dist])

    @classmethod
    def from_intrinsics(cls, model: str, vector, image_size) -> "Lens":
        """Inverse of :meth:`intrinsics`."""
        v = np.asarray(vector, dtype=np.float64).ravel()
        if model in N_COEFFS and v.size != 4 + N_COEFFS[model]:
            raise ValueError(f"intrinsics for {model!r} must have {4 + N_COEFFS[model]} values "
                             f"[fx, fy, cx, cy, {', '.join(COEFF_NAMES[model])}], got {v.size}")
        K = np.array([[v[0], 0.0, v[2]], [0.0, v[1], v[3]], [0.0, 0.0, 1.0]]) if v.size >= 4 else v
        return cls(model, K, v[4:], image_size)

    def to_dict(self) -> dict:
        """JSON-able {"model", "K", "dist", "image_size"} (our model name, e.g. "thin_prism")."""
        return {"model": self.model, "K": self.K.tolist(), "dist": self.dist.tolist(),
                "image_size": list(self.image_size)}

    @classmethod
    def from_dict(cls, data: dict) -> "Lens":
        """Inverse of :meth:`to_dict`."""
        missing = {"model", "K", "dist", "image_size"} - set(data)
        if missing:
            raise ValueError(f"lens dict lacks keys {sorted(missing)}, got keys {sorted(data)}")
        return cls(data["model"], data["K"], data["dist"], data["image_size"])
