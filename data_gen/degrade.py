"""Image degradations that real cameras and scenes produce, each with a severity parameter.

Every function takes a float32 (H, W) image in [0, 1] (values above 1 are allowed before the
sensor clips) and returns a new float32 image. Random ones take an explicit
``rng: np.random.Generator``. Units: grey levels on the 0–255 scale for noise, px for blur,
fractions for shading. :data:`PIPELINE_ORDER` is the physical order in which
:func:`apply_degradations` applies them: scene lighting, optics, sensor, encoding.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from aicalib_tf.io import quantize

from .sensor import (astigmatism, bayer_demosaic, blend_blurred, circle_edge, field_defocus, lateral_ca, tone_curve,
                     unsharp)

__all__ = ["gaussian_noise", "shot_noise", "gaussian_blur", "motion_blur", "defocus", "contrast", "illumination_gradient", "vignetting", "shadow", "exposure", "jpeg", "salt_pepper", "circle_falloff", "rim_vignetting", "field_blur", "depth_blur", "glare", "apply_degradations", "DEGRADATIONS", "PIPELINE_ORDER", "CIRCLE_STEPS",
           "PLANE_STEPS"]


def illumination_gradient(img: np.ndarray, rng: np.random.Generator, *, strength: float) -> np.ndarray:
    """Multiply by a linear ramp from ``1 - strength`` to 1 across the image, at a random angle."""
    h, w = img.shape
    angle = rng.uniform(0.0, 2.0 * math.pi)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    proj = xx * math.cos(angle) + yy * math.sin(angle)
    ramp = (proj - proj.min()) / max(float(np.ptp(proj)), 1e-6)
    return img * (1.0 - strength * ramp).astype(np.float32)


def vignetting(img: np.ndarray, rng: np.random.Generator, *, strength: float) -> np.ndarray:
    """Radial fall-off: the image corners get ``1 - strength`` of the centre's light (cos⁴-like)."""
    del rng
    h, w = img.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    r2 = ((xx - (w - 1) / 2.0) ** 2 + (yy - (h - 1) / 2.0) ** 2) / (((w - 1) / 2.0) ** 2 + ((h - 1) / 2.0) ** 2)
    return img * (1.0 - strength * r2).astype(np.float32)


def _circle_rho(shape: tuple[int, int], cx: float, cy: float, radius: float) -> np.ndarray:
    """(H, W) float32: each pixel's distance from (cx, cy) px over ``radius`` px (1 on the circle)."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    return (np.hypot(xx - np.float32(cx), yy - np.float32(cy)) / np.float32(max(radius, 1e-6))).astype(np.float32)


def circle_falloff(img: np.ndarray, rng: np.random.Generator, *, strength: float, power: float, cx: float,
                   cy: float, radius: float) -> np.ndarray:
    """A fisheye's vignetting: light × ``max(0, 1 - strength·ρ^power)``, ρ = distance from the image
    circle's centre (cx, cy) px over its ``radius`` px; ``strength`` 1 falls to black at the circle.

    The circle comes from the camera (:func:`data_gen.sample.draw_scene` fills it in, see
    :data:`CIRCLE_STEPS`).

    >>> circle_falloff(np.ones((1, 3), np.float32), None, strength=1.0, power=2.0, cx=0.0, cy=0.0,
    ...                radius=2.0).round(2).tolist()
    [[1.0, 0.75, 0.0]]
    """
    del rng
    rho = _circle_rho(img.shape, cx, cy, radius)
    return (img * np.clip(1.0 - np.float32(strength) * rho ** np.float32(power), 0.0, 1.0)).astype(np.float32)


RIM_LAWS = ("cos4", "poly", "hard")


def rim_vignetting(img: np.ndarray, rng: np.random.Generator, *, law: str, strength: float, edge: float,
                   cx: float, cy: float, radius: float) -> np.ndarray:
    """A fisheye's light fall-off by one of three laws of ρ, the distance from the image circle's
    centre (cx, cy) px over its ``radius`` px; every law is black at ρ >= 1 when ``strength`` is 1.

    law "cos4": light × (1 - strength·(1 - cos⁴(ρ·π/2))) (the cos⁴ law with the rim at 90°);
    "poly": light × (1 - strength·(0.3ρ² + 0.7ρ⁶)) (flat centre, steep outer ring);
    "hard": light unchanged inside ``edge`` (0..1 of the radius), falling linearly to
    ``1 - strength`` over the rest (a hard black rim).

    >>> [round(float(v), 2) for v in rim_vignetting(np.ones((1, 3), np.float32), None, law="hard",
    ...  strength=1.0, edge=0.5, cx=0.0, cy=0.0, radius=2.0)[0]]
    [1.0, 1.0, 0.0]
    """
    del rng
    if law not in RIM_LAWS:
        raise ValueError(f"rim_vignetting law must be one of {RIM_LAWS}, got {law!r}")
    rho = np.minimum(_circle_rho(img.shape, cx, cy, radius), 1.0)
    if law == "cos4":
        loss = 1.0 - np.cos(rho * np.float32(math.pi / 2.0)) ** 4
    elif law == "poly":
        loss = 0.3 * rho ** 2 + 0.7 * rho ** 6
    else:
        loss = np.clip((rho - np.float32(edge)) / np.float32(max(1.0 - edge, 1e-6)), 0.0, 1.0)
    return (img * np.clip(1.0 - np.float32(strength) * loss, 0.0, 1.0)).astype(np.float32)


def field_blur(img: np.ndarray, rng: np.random.Generator, *, sigma_centre: float, sigma_rim: float, power: float,
               cx: float, cy: float, radius: float) -> np.ndarray:
    """Shallow focus across a fisheye's field: Gaussian blur whose σ (px) grows from ``sigma_centre`` at
    the image circle's centre (cx, cy) px to ``sigma_rim`` at its ``radius`` px, as ρ^``power``.

    Blends a few uniformly blurred copies pixel by pixel (linear in σ between neighbouring copies).
    """
    del rng
    rho = np.minimum(_circle_rho(img.shape, cx, cy, radius), 1.0)
    sigma = sigma_centre + (sigma_rim - sigma_centre) * rho ** np.float32(power)
    levels = np.linspace(min(sigma_centre, sigma_rim), max(sigma_centre, sigma_rim), 6)
    return blend_blurred(sigma, levels, lambda s: gaussian_blur(img, None, sigma=s))


def _blur_by(img: np.ndarray, sigma: np.ndarray, levels: int = 6) -> np.ndarray:
    """img (H, W) float32 blurred pixel by pixel by a Gaussian of σ ``sigma`` (H, W) px: a blend of ``levels``
    uniformly blurred copies (linear in σ between neighbouring copies)."""
    lo, hi = float(sigma.min()), float(sigma.max())
    if hi - lo < 1e-6:
        return gaussian_blur(img, None, sigma=lo)
    steps = np.linspace(lo, hi, levels)
    stack = [gaussian_blur(img, None, sigma=float(s)) for s in steps]
    pos = np.clip((sigma - lo) / (steps[1] - steps[0]), 0.0, levels - 1.0 - 1e-6)
    i = pos.astype(np.int32)
    frac = (pos - i).astype(np.float32)
    out = np.zeros_like(img, dtype=np.float32)
    for k in range(levels - 1):
        m = i == k
        out[m] = stack[k][m] * (1.0 - frac[m]) + stack[k + 1][m] * frac[m]
    return out


def depth_blur(img: np.ndarray, rng: np.random.Generator, *, focus: float, sigma_min: float, sigma_max: float,
               w0: float, wu: float, wv: float, w_near: float, w_far: float) -> np.ndarray:
    """Depth of field across a tilted board: Gaussian blur whose σ (px) grows as |1/z − 1/z_focus|.

    A thin lens's blur circle is proportional to the difference of inverse depths, so a board
    tilted away from the camera is sharp at the focus distance and blurs towards both its near and
    its far end. The scene's inverse depth is the board's plane, w(x, y) = w0 + wu·x + wv·y (1/board
    units, x, y px; exact for a pinhole lens, a least-squares fit under distortion; see
    :data:`PLANE_STEPS`), ranging from ``w_far`` to ``w_near`` over the board. The focus sits at
    w_f = w_far + ``focus``·(w_near − w_far) (0: the far end sharp, 1: the near end); σ is
    ``sigma_min`` there and ``sigma_max`` at the board's end farther from it in 1/z, capped there off the board.

    >>> v = depth_blur(np.eye(5, dtype=np.float32), None, focus=0.0, sigma_min=0.5, sigma_max=0.5, w0=1.0,
    ...                wu=0.0, wv=0.0, w_near=1.0, w_far=1.0)
    >>> bool(np.allclose(v, gaussian_blur(np.eye(5, dtype=np.float32), None, sigma=0.5)))
    True
    """
    del rng
    h, w = img.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    inv = np.float32(w0) + np.float32(wu) * xx + np.float32(wv) * yy
    wf = w_far + focus * (w_near - w_far)
    reach = max(abs(w_near - wf), abs(w_far - wf), 1e-12)
    share = np.minimum(np.abs(inv - np.float32(wf)) / np.float32(reach), 1.0)
    return _blur_by(img, (sigma_min + (sigma_max - sigma_min) * share).astype(np.float32))


def shadow(img: np.ndarray, rng: np.random.Generator, *, strength: float, softness: float = 1.0) -> np.ndarray:
    """A hard-edged shadow: a random polygon whose light is reduced by ``strength``.

    ``softness`` is the penumbra width (Gaussian σ, px).
    """
    h, w = img.shape
    n = int(rng.integers(3, 7))
    centre = rng.uniform([0.0, 0.0], [w, h])
    radius = rng.uniform(0.3, 0.8) * max(w, h)
    angles = (np.arange(n) + rng.uniform(0.0, 1.0, size=n)) * (2.0 * math.pi / n)  # encloses the centre
    radii = radius * rng.uniform(0.5, 1.0, size=n)
    poly = np.stack([centre[0] + radii * np.cos(angles), centre[1] + radii * np.sin(angles)], axis=1)
    mask = np.zeros((h, w), np.uint8)
    cv2.fillPoly(mask, [np.round(poly * 16).astype(np.int32)], 255, lineType=cv2.LINE_AA, shift=4)
    m = mask.astype(np.float32) / 255.0
    if softness > 0:
        m = cv2.GaussianBlur(m, (0, 0), softness)
    return img * (1.0 - strength * m)


def glare(img: np.ndarray, rng: np.random.Generator, *, strength: float, radius: float) -> np.ndarray:
    """A specular sheen (a light's reflection on glossy paper): light added as ``strength``·exp(−r²/2s²),
    s = ``radius`` of the image's diagonal, about a point drawn over the middle 80% of the image. Added
    light, not multiplied: it lifts black and white alike (the board's contrast falls under it) and may
    clip white."""
    h, w = img.shape
    cx, cy = rng.uniform(0.1, 0.9) * (w - 1), rng.uniform(0.1, 0.9) * (h - 1)
    s = radius * math.hypot(w, h)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    r2 = (xx - np.float32(cx)) ** 2 + (yy - np.float32(cy)) ** 2
    return (img + np.float32(strength) * np.exp(-r2 / np.float32(2.0 * s * s))).astype(np.float32)


def contrast(img: np.ndarray, rng: np.random.Generator, *, factor: float, mid: float = 0.5) -> np.ndarray:
    """Compress intensities towards ``mid``: ``mid + factor·(img - mid)``; factor < 1 lowers contrast."""
    del rng
    return (mid + factor * (img - mid)).astype(np.float32)


def exposure(img: np.ndarray, rng: np.random.Generator, *, gain: float) -> np.ndarray:
    """Scale the light by ``gain``: > 1 over-exposes (clips at white), < 1 under-exposes."""
    del rng
    return (img * gain).astype(np.float32)


def gaussian_blur(img: np.ndarray, rng: np.random.Generator, *, sigma: float) -> np.ndarray:
    """Optical blur, Gaussian with standard deviation ``sigma`` px."""
    del rng
    if sigma <= 0:
        return img.copy()
    return cv2.GaussianBlur(img, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)


def motion_blur(img: np.ndarray, rng: np.random.Generator, *, length: float, angle: float | None = None) -> np.ndarray:
    """Linear motion blur over ``length`` px at ``angle`` degrees (random if None)."""
    if length <= 1:
        return img.copy()
    if angle is None:
        angle = rng.uniform(0.0, 180.0)
    size = int(math.ceil(length)) | 1
    size += 2
    kernel = np.zeros((size * 8, size * 8), np.uint8)
    c = (size * 8 - 1) / 2.0
    dx = math.cos(math.radians(angle)) * length * 4.0
    dy = math.sin(math.radians(angle)) * length * 4.0
    p0 = (round((c - dx) * 16), round((c - dy) * 16))
    p1 = (round((c + dx) * 16), round((c + dy) * 16))
    cv2.line(kernel, p0, p1, 255, thickness=8, lineType=cv2.LINE_AA, shift=4)
    k = cv2.resize(kernel.astype(np.float32), (size, size), interpolation=cv2.INTER_AREA)
    k /= k.sum()
    return cv2.filter2D(img, -1, k, borderType=cv2.BORDER_REFLECT)


def defocus(img: np.ndarray, rng: np.random.Generator, *, radius: float) -> np.ndarray:
    """Defocus blur: convolution with an anti-aliased disk of ``radius`` px."""
    del rng
    if radius <= 0.5:
        return img.copy()
    size = 2 * int(math.ceil(radius)) + 1
    ss = 8
    big = np.zeros((size * ss, size * ss), np.uint8)
    c = (size * ss - 1) / 2.0
    cv2.circle(big, (round(c * 16), round(c * 16)), round(radius * ss * 16), 255, -1, cv2.LINE_AA, shift=4)
    k = cv2.resize(big.astype(np.float32), (size, size), interpolation=cv2.INTER_AREA)
    k /= k.sum()
    return cv2.filter2D(img, -1, k, borderType=cv2.BORDER_REFLECT)


def shot_noise(img: np.ndarray, rng: np.random.Generator, *, photons: float) -> np.ndarray:
    """Poisson photon noise; ``photons`` is the count collected at white (1.0). Fewer = noisier."""
    lam = np.clip(img, 0.0, None).astype(np.float64) * photons
    return (rng.poisson(lam) / photons).astype(np.float32)


def gaussian_noise(img: np.ndarray, rng: np.random.Generator, *, sigma: float) -> np.ndarray:
    """Additive white Gaussian read noise with standard deviation ``sigma`` grey levels (0–255)."""
    noise = rng.standard_normal(img.shape, dtype=np.float32) * np.float32(sigma / 255.0)
    return img + noise


def jpeg(img: np.ndarray, rng: np.random.Generator, *, quality: int) -> np.ndarray:
    """JPEG round trip at ``quality`` (1–100) on the 8-bit image."""
    del rng
    ok, buf = cv2.imencode(".jpg", quantize(img), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    return cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE).astype(np.float32) / 255.0


def salt_pepper(img: np.ndarray, rng: np.random.Generator, *, fraction: float) -> np.ndarray:
    """Set ``fraction`` of the pixels to 0 or 1 (half each)."""
    out = img.copy()
    u = rng.random(img.shape)
    out[u < fraction / 2.0] = 0.0
    out[(u >= fraction / 2.0) & (u < fraction)] = 1.0
    return out


DEGRADATIONS = {
    "illumination_gradient": illumination_gradient,
    "vignetting": vignetting,
    "circle_falloff": circle_falloff,
    "rim_vignetting": rim_vignetting,
    "circle_edge": circle_edge,
    "shadow": shadow,
    "glare": glare,
    "contrast": contrast,
    "exposure": exposure,
    "defocus": defocus,
    "gaussian_blur": gaussian_blur,
    "field_blur": field_blur,
    "field_defocus": field_defocus,
    "lateral_ca": lateral_ca,
    "astigmatism": astigmatism,
    "depth_blur": depth_blur,
    "motion_blur": motion_blur,
    "shot_noise": shot_noise,
    "gaussian_noise": gaussian_noise,
    "bayer_demosaic": bayer_demosaic,  # after the noise: it lands on the raw samples
    "tone_curve": tone_curve,
    "unsharp": unsharp,
    "jpeg": jpeg,
    "salt_pepper": salt_pepper,
}

# Scene light, then lens, then sensor, then encoding and transmission.
PIPELINE_ORDER = tuple(DEGRADATIONS)
# Steps that follow a fisheye's image circle: the scene gives them ``cx``, ``cy`` and ``radius`` (px).
CIRCLE_STEPS = ("circle_falloff", "rim_vignetting", "field_blur", "circle_edge", "field_defocus", "lateral_ca",
                "astigmatism")
# Steps that follow the board's depth: the scene gives them its inverse-depth plane ``w0``, ``wu``, ``wv`` and
# its range over the board ``w_near``, ``w_far`` (:func:`depth_blur`).
PLANE_STEPS = ("depth_blur",)


def apply_degradations(img: np.ndarray, steps: list[dict], rng: np.random.Generator) -> np.ndarray:
    """Apply ``steps`` (each ``{"name": ..., **params}``) in :data:`PIPELINE_ORDER`, then quantize.

    Returns (H, W) uint8. Unknown names raise ``ValueError``.
    """
    for step in steps:
        if step["name"] not in DEGRADATIONS:
            raise ValueError(f"unknown degradation {step['name']!r}; known: {', '.join(DEGRADATIONS)}")
    ordered = sorted(steps, key=lambda s: PIPELINE_ORDER.index(s["name"]))
    out = img.astype(np.float32, copy=True)
    for step in ordered:
        params = {k: v for k, v in step.items() if k != "name"}
        if step["name"] in ("jpeg", "salt_pepper"):
            out = quantize(out).astype(np.float32) / 255.0  # the sensor has clipped by now
        out = DEGRADATIONS[step["name"]](out, rng, **params)
    return quantize(out)
