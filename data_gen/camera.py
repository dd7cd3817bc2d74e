"""Sampling realistic cameras: pinhole lenses with OpenCV's 5 coefficients, and fisheyes (equidistant,
Double Sphere, Extended Unified).

The lens maths lives in :mod:`aicalib_tf.geometry.lens`; :class:`aicalib_tf.geometry.camera.Camera`
wraps it with the image circle the renderer needs.
"""

from __future__ import annotations

import math

import numpy as np

from aicalib_tf.geometry.camera import Camera

__all__ = ["sample_camera", "sample_fisheye", "sample_unified_fisheye", "DISTORTION_LEVELS", "UNIFIED_MODELS"]

DISTORTION_LEVELS = ("none", "mild", "strong", "pincushion")


def _sample_distortion(rng: np.random.Generator, level: str) -> np.ndarray:
    if level == "none":
        return np.zeros(5)
    if level == "mild":
        k1 = rng.uniform(-0.15, 0.05)
        k2 = rng.uniform(0.0, 0.6) * k1 * k1 + rng.uniform(-0.01, 0.01)
        k3 = 0.0
    elif level == "strong":
        k1 = rng.uniform(-0.45, -0.25)
        # k2 > 0.45·k1² keeps 1 + 3k1·u + 5k2·u² > 0 for all u (a monotonic radial map); the
        # margin to 0.55 leaves room for a small negative k3, as real wide-angle fits have.
        k2 = rng.uniform(0.55, 0.9) * k1 * k1
        k3 = rng.uniform(-0.002, 0.0)
    elif level == "pincushion":
        k1 = rng.uniform(0.05, 0.25)
        k2 = rng.uniform(-0.02, 0.05)
        k3 = 0.0
    else:
        raise ValueError(f"distortion level must be one of {DISTORTION_LEVELS}, got {level!r}")
    p1, p2 = rng.normal(0.0, 4e-4, size=2)
    return np.array([k1, k2, p1, p2, k3], dtype=np.float64)


def sample_camera(
    rng: np.random.Generator,
    image_size: tuple[int, int],
    *,
    hfov_deg: tuple[float, float] = (40.0, 120.0),
    distortion: str | tuple[str, ...] = DISTORTION_LEVELS,
    max_tries: int = 100,
) -> Camera:
    """Draw a realistic camera for an image of ``image_size`` = (width, height) px.

    The horizontal field of view is drawn from ``hfov_deg`` (full angle, degrees); the focal
    length is solved so that the image edge sees exactly that angle *through the distortion*.
    ``distortion`` is a level or a tuple of levels to choose from (see ``DISTORTION_LEVELS``).
    Narrow lenses get at most mild distortion and pincushion is limited to HFOV <= 75 degrees,
    as with real optics. The model is guaranteed monotonic out to 1.1x the image corners.
    """
    w, h = (int(v) for v in image_size)
    levels = (distortion,) if isinstance(distortion, str) else tuple(distortion)
    for _ in range(max_tries):
        hfov = rng.uniform(*hfov_deg)
        level = levels[int(rng.integers(len(levels)))]
        if level == "strong" and hfov < 70.0:
            level = "mild"
        if level == "pincushion" and hfov > 75.0:
            level = "mild"
        dist = _sample_distortion(rng, level)
        k1, k2, _, _, k3 = dist
        r_edge = math.tan(math.radians(hfov) / 2.0)
        rd_edge = r_edge * (1.0 + k1 * r_edge**2 + k2 * r_edge**4 + k3 * r_edge**6)
        if rd_edge <= 0:
            continue
        fx = (w / 2.0) / rd_edge
        fy = fx * (1.0 + rng.normal(0.0, 0.002))
        cx = (w - 1) / 2.0 + rng.normal(0.0, 0.01 * w)
        cy = (h - 1) / 2.0 + rng.normal(0.0, 0.01 * h)
        K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        cam = Camera(K, dist, (w, h))
        # Require a monotonic model (with margin) over the whole image, corners included.
        corners = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [-0.5, h - 0.5], [w - 0.5, h - 0.5]])
        norm = cam.pixel_to_normalized(corners)
        if not np.all(np.isfinite(norm)):
            continue
        if np.max(np.hypot(norm[:, 0], norm[:, 1])) * 1.1 > cam.r_mono:
            continue
        return cam
    raise RuntimeError(f"could not sample a monotonic camera for size {image_size} in {max_tries} tries")


def _sample_kb(rng: np.random.Generator) -> np.ndarray:
    """Small Kannala–Brandt coefficients [k1, k2, k3, k4] of the size real fisheye fits give."""
    return np.array([rng.uniform(-0.04, 0.04), rng.uniform(-0.01, 0.01), rng.uniform(-0.003, 0.003),
                     rng.uniform(-0.001, 0.001)])


def sample_fisheye(
    rng: np.random.Generator,
    image_size: tuple[int, int],
    *,
    fov_deg: tuple[float, float] = (150.0, 200.0),
    circular_from_deg: float = 175.0,
    max_tries: int = 100,
) -> Camera:
    """Draw an equidistant (Kannala–Brandt) fisheye for an image of ``image_size`` = (w, h) px.

    The lens' full field of view is drawn from ``fov_deg`` (degrees; up to 200°, i.e. 100°
    off-axis, beyond the pinhole's 90°). Below ``circular_from_deg`` the lens is full-frame: the
    image diagonal sees exactly that angle and the image circle passes just outside the
    corners. From it on the lens is circular: the whole image circle (radius 0.90–0.97 of half
    the shorter side) lies inside the frame and pixels outside it see nothing. k1..k4 are small
    (:func:`_sample_kb`); the model is monotonic to 1.05x the circle's angle.
    Returns a :class:`Camera` with ``model="equidistant"`` and ``max_theta`` = half the FOV.
    """
    w, h = (int(v) for v in image_size)
    lo, hi = fov_deg
    if not 0.0 < lo <= hi <= 360.0:
        raise ValueError(f"fov_deg must be (lo, hi) with 0 < lo <= hi <= 360, got {fov_deg}")
    for _ in range(max_tries):
        fov = rng.uniform(lo, hi)
        theta_max = math.radians(fov) / 2.0
        k = _sample_kb(rng)
        lim = Camera(np.eye(3), k, (w, h), model="equidistant").r_mono
        if min(lim, math.pi) < 1.05 * theta_max and lim < math.pi:
            continue
        td = theta_max * (1.0 + sum(k[i] * theta_max ** (2 * i + 2) for i in range(4)))
        cx = (w - 1) / 2.0 + rng.normal(0.0, 0.003 * w)
        cy = (h - 1) / 2.0 + rng.normal(0.0, 0.003 * h)
        if fov >= circular_from_deg:
            radius = rng.uniform(0.90, 0.97) * (min(w, h) / 2.0)
        else:
            radius = math.hypot(w / 2.0, h / 2.0)
        if td <= 0:
            continue
        fx = radius / td
        fy = fx * (1.0 + rng.normal(0.0, 0.002))
        K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        if fov >= circular_from_deg:
            if not (cx - fx * td >= -0.5 and cx + fx * td <= w - 0.5 and cy - fy * td >= -0.5 and cy + fy * td <= h - 0.5):
                continue
            return Camera(K, k, (w, h), model="equidistant", max_theta=theta_max)
        # Full frame: the circle just clears the (off-centre) image corners.
        cam = Camera(K, k, (w, h), model="equidistant")
        corners = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [-0.5, h - 0.5], [w - 0.5, h - 0.5]])
        rays = cam.lens.unproject(corners)
        if not np.all(np.isfinite(rays)):
            continue
        edge = float(np.max(np.arctan2(np.hypot(rays[:, 0], rays[:, 1]), rays[:, 2]))) + 1e-3
        if edge >= min(lim, math.pi):
            continue
        return Camera(K, k, (w, h), model="equidistant", max_theta=edge)
    raise RuntimeError(f"could not sample a fisheye for size {image_size} and fov {fov_deg} in {max_tries} tries")


UNIFIED_MODELS = ("ds", "eucm")


def _sample_unified(rng: np.random.Generator, model: str) -> np.ndarray:
    """Coefficients of the size real fits give: DS [ξ, α] (ξ −0.3..0, α 0.5..0.65), EUCM [α, β] (α 0.55..0.7, β 0.9..1.3)."""
    if model == "ds":
        return np.array([rng.uniform(-0.3, 0.0), rng.uniform(0.5, 0.65)])
    if model == "eucm":
        return np.array([rng.uniform(0.55, 0.7), rng.uniform(0.9, 1.3)])
    raise ValueError(f"model must be one of {UNIFIED_MODELS}, got {model!r}")


def sample_unified_fisheye(
    rng: np.random.Generator,
    image_size: tuple[int, int],
    model: str = "ds",
    *,
    fov_deg: tuple[float, float] = (150.0, 200.0),
    circular_from_deg: float = 175.0,
    max_tries: int = 100,
) -> Camera:
    """Draw a Double Sphere (``model="ds"``) or EUCM (``"eucm"``) fisheye for an image of (w, h) px.

    As :func:`sample_fisheye`: the full field of view from ``fov_deg`` (degrees), full-frame below
    ``circular_from_deg`` (the image corners see the edge of the field) and circular from it on
    (the circle's radius 0.90–0.97 of half the shorter side, inside the frame). The coefficients
    (:func:`_sample_unified`) must image 1.02× the field's half-angle. Returns a :class:`Camera`
    with ``max_theta`` = half the field of view.
    """
    w, h = (int(v) for v in image_size)
    for _ in range(max_tries):
        fov = rng.uniform(*fov_deg)
        theta_max = math.radians(fov) / 2.0
        d = _sample_unified(rng, model)
        probe = Camera(np.eye(3), d, (w, h), model=model)
        if probe.lens.max_angle() < 1.02 * theta_max:
            continue
        rd = probe.lens.spec.radius(theta_max, d)
        circular = fov >= circular_from_deg
        radius = rng.uniform(0.90, 0.97) * (min(w, h) / 2.0) if circular else math.hypot(w / 2.0, h / 2.0)
        fx = radius / rd
        fy = fx * (1.0 + rng.normal(0.0, 0.002))
        cx = (w - 1) / 2.0 + rng.normal(0.0, 0.003 * w)
        cy = (h - 1) / 2.0 + rng.normal(0.0, 0.003 * h)
        if circular and not (cx - fx * rd >= -0.5 and cx + fx * rd <= w - 0.5 and cy - fy * rd >= -0.5
                             and cy + fy * rd <= h - 0.5):
            continue
        K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        return Camera(K, d, (w, h), model=model, max_theta=theta_max)
    raise RuntimeError(f"could not sample a {model} fisheye for size {image_size} and fov {fov_deg} in {max_tries} tries")
