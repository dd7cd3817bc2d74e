"""Sampling realistic cameras (the lens model itself is :class:`aicalib_tf.geometry.camera.Camera`).

The camera model, its conventions and its exact inverse live in :mod:`aicalib_tf.geometry.camera`.
"""

from __future__ import annotations

import math

import numpy as np

from aicalib_tf.geometry.camera import Camera

__all__ = ["sample_camera", "DISTORTION_LEVELS"]

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
