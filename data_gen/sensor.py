"""Optical and sensor laws of real cameras and other renderers that the plain grey pipeline lacks.

Each function has :mod:`data_gen.degrade`'s signature: a float32 (H, W) image in [0, 1] (values
above 1 allowed before the sensor clips), an explicit ``rng`` (unused by these deterministic laws),
keyword parameters; it returns a new float32 (H, W) image. The scene is grey, so a colour law
splits it into R, G, B channels that differ only as the law makes them, and turns them back
into grey with the Rec. 601 weights (:data:`GREY_WEIGHTS`), as an RGB camera's image turned
grey does. Units: px for shifts and blur radii; fractions of the image circle's radius for ρ.

- :func:`circle_edge`: the lens barrel's soft cut of the image circle (light falls to black at
  ``black_at``·radius over a cosine ramp), e.g. a soft edge, or a rim that is black before the circle;
- :func:`field_defocus`: defocus by a disc (pillbox) kernel whose radius grows towards the rim;
- :func:`lateral_ca`: lateral chromatic aberration, R and B imaged at radially scaled positions;
- :func:`bayer_demosaic`: an RGGB colour filter mosaic, demosaiced (bilinear or edge-aware), white balanced;
- :func:`tone_curve`: the sRGB transfer curve or a power law, applied to linear light;
- :func:`unsharp`: an image processor's sharpening (unsharp mask), with its halo at edges.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = ["circle_edge", "field_defocus", "lateral_ca", "bayer_demosaic", "tone_curve", "unsharp", "disc_kernel",
           "GREY_WEIGHTS", "DEMOSAIC_METHODS", "TONE_LAWS"]

GREY_WEIGHTS = (0.299, 0.587, 0.114)  # R, G, B (Rec. 601, OpenCV's BGR2GRAY)
# OpenCV names a mosaic by its second row: its "BG" codes read R at even rows and columns (RGGB)
DEMOSAIC_METHODS = {"bilinear": cv2.COLOR_BayerBG2BGR, "edge": cv2.COLOR_BayerBG2BGR_EA}
TONE_LAWS = ("srgb", "gamma")
_RAW_OFFSET = 0.125  # black level of the 16-bit raw: noise below black survives the mosaic
_RAW_SCALE = 32768.0  # raw counts per unit of light (1.0 = the clip at full well)


def _rho(shape: tuple[int, int], cx: float, cy: float, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(dx, dy, ρ) (H, W) float32: each pixel's offset from (cx, cy) px and its distance over ``radius`` px."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    dx, dy = xx - np.float32(cx), yy - np.float32(cy)
    return dx, dy, (np.hypot(dx, dy) / np.float32(max(radius, 1e-6))).astype(np.float32)


def circle_edge(img: np.ndarray, rng: np.random.Generator, *, black_at: float, width: float, cx: float, cy: float,
                radius: float) -> np.ndarray:
    """The lens barrel's cut of the image circle: light × 1 inside ρ = ``black_at`` - ``width``, × 0 from
    ρ = ``black_at`` on, a cosine ramp between (ρ: distance from (cx, cy) px over ``radius`` px).

    ``black_at`` 1 with a small ``width`` is a soft circle edge; ``black_at`` < 1 a rim black before the circle.

    >>> [round(float(v), 2) for v in circle_edge(np.ones((1, 5), np.float32), None, black_at=1.0, width=0.5,
    ...  cx=0.0, cy=0.0, radius=4.0)[0]]
    [1.0, 1.0, 1.0, 0.5, 0.0]
    """
    del rng
    if not 0.0 < width <= black_at:
        raise ValueError(f"circle_edge needs 0 < width <= black_at, got width={width}, black_at={black_at}")
    _, _, rho = _rho(img.shape, cx, cy, radius)
    t = np.clip((rho - np.float32(black_at - width)) / np.float32(width), 0.0, 1.0)
    return (img * (0.5 + 0.5 * np.cos(np.float32(math.pi) * t))).astype(np.float32)


def disc_kernel(radius: float, supersample: int = 8) -> np.ndarray:
    """(2k+1, 2k+1) float32 summing to 1, k = ceil(``radius``): a disc of ``radius`` px, its rim pixels
    weighted by the share of their area inside (``supersample``² samples a pixel)."""
    k = int(math.ceil(radius))
    n = (2 * k + 1) * supersample
    c = (np.arange(n) + 0.5) / supersample - (k + 0.5)
    inside = (c[None, :] ** 2 + c[:, None] ** 2 <= radius * radius).astype(np.float32)
    ker = inside.reshape(2 * k + 1, supersample, 2 * k + 1, supersample).mean(axis=(1, 3))
    return (ker / ker.sum()).astype(np.float32)


def field_defocus(img: np.ndarray, rng: np.random.Generator, *, radius_centre: float, radius_rim: float,
                  power: float, cx: float, cy: float, radius: float) -> np.ndarray:
    """Defocus by a disc (pillbox) kernel, the blur of a lens' aperture, whose radius (px) grows from
    ``radius_centre`` at the image circle's centre (cx, cy) px to ``radius_rim`` at its ``radius`` px as
    ρ^``power``. A disc of radius r has the spread (σ per axis) of a Gaussian of σ = r/2 but a flat top
    and a hard edge. Blends six uniformly blurred copies pixel by pixel (linear between neighbours)."""
    del rng
    _, _, rho = _rho(img.shape, cx, cy, radius)
    r = radius_centre + (radius_rim - radius_centre) * np.minimum(rho, 1.0) ** np.float32(power)
    levels = np.linspace(min(radius_centre, radius_rim), max(radius_centre, radius_rim), 6)

    def blurred(rad: float) -> np.ndarray:
        if rad <= 0.5:
            return img.astype(np.float32, copy=True)
        return cv2.filter2D(img.astype(np.float32), -1, disc_kernel(rad), borderType=cv2.BORDER_REFLECT)

    if levels[-1] - levels[0] < 1e-6:
        return blurred(float(levels[0]))
    stack = [blurred(float(v)) for v in levels]
    pos = np.clip((r - levels[0]) / (levels[1] - levels[0]), 0.0, len(levels) - 1.0 - 1e-6)
    i = pos.astype(np.int32)
    frac = (pos - i).astype(np.float32)
    out = np.zeros_like(img, dtype=np.float32)
    for k in range(len(levels) - 1):
        m = i == k
        out[m] = stack[k][m] * (1.0 - frac[m]) + stack[k + 1][m] * frac[m]
    return out


def lateral_ca(img: np.ndarray, rng: np.random.Generator, *, shift: float, power: float, cx: float, cy: float,
               radius: float) -> np.ndarray:
    """Lateral chromatic aberration: the red image lies ``shift``·ρ^``power`` px further out from the image
    circle's centre (cx, cy) px than the green, the blue as far further in (ρ: distance over ``radius`` px;
    ``power`` 1 is a pure difference of magnification); the three are turned into grey (:data:`GREY_WEIGHTS`)."""
    del rng
    dx, dy, rho = _rho(img.shape, cx, cy, radius)
    src = img.astype(np.float32)
    grey = GREY_WEIGHTS[1] * src
    dist = np.maximum(rho * np.float32(max(radius, 1e-6)), 1e-3)
    for sign, weight in ((1.0, GREY_WEIGHTS[0]), (-1.0, GREY_WEIGHTS[2])):
        scale = 1.0 - np.float32(sign * shift) * rho ** np.float32(power) / dist  # seen at r - d(r), to first order
        mx = (np.float32(cx) + dx * scale).astype(np.float32)
        my = (np.float32(cy) + dy * scale).astype(np.float32)
        grey += weight * cv2.remap(src, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    return grey.astype(np.float32)


def bayer_demosaic(img: np.ndarray, rng: np.random.Generator, *, gain_r: float, gain_b: float,
                   method: str = "bilinear") -> np.ndarray:
    """An RGGB colour filter mosaic: each pixel keeps one channel, the R and B ones at ``gain_r`` and ``gain_b``
    of the green response (the raw colour cast of the light), clipped at full well (1.0); demosaiced by
    ``method`` ("bilinear" or "edge", OpenCV's edge-aware), white balanced (÷ gain), each channel clipped
    at white again (as a camera's processor clips), and turned into grey.

    Noise steps before this one land on the raw samples, so the demosaic correlates them as a camera does.
    A flat grey field below the clip comes back as it was.
    """
    del rng
    if method not in DEMOSAIC_METHODS:
        raise ValueError(f"bayer_demosaic method must be one of {tuple(DEMOSAIC_METHODS)}, got {method!r}")
    if gain_r <= 0 or gain_b <= 0:
        raise ValueError(f"bayer_demosaic gains must be > 0, got gain_r={gain_r}, gain_b={gain_b}")
    h, w = img.shape
    gain = np.ones((h, w), np.float32)
    gain[0::2, 0::2] = gain_r  # R at even rows and columns, B at odd ones (RGGB)
    gain[1::2, 1::2] = gain_b
    raw = np.clip(img * gain, -_RAW_OFFSET, 1.0)
    raw16 = np.round((raw + _RAW_OFFSET) * _RAW_SCALE).astype(np.uint16)
    bgr = cv2.cvtColor(raw16, DEMOSAIC_METHODS[method]).astype(np.float32) / np.float32(_RAW_SCALE) - _RAW_OFFSET
    bgr = np.minimum(bgr / np.array([gain_b, 1.0, gain_r], np.float32), 1.0)
    b, g, r = bgr[..., 0], bgr[..., 1], bgr[..., 2]
    return (GREY_WEIGHTS[0] * r + GREY_WEIGHTS[1] * g + GREY_WEIGHTS[2] * b).astype(np.float32)


def tone_curve(img: np.ndarray, rng: np.random.Generator, *, law: str = "srgb", gamma: float = 2.2) -> np.ndarray:
    """Encode linear light (clipped to [0, 1], as the sensor clips) by the sRGB transfer curve (``law``
    "srgb") or the power 1/``gamma`` ("gamma"): dark tones are lifted, so a vignetted rim is brighter and
    its noise larger than in linear light.

    >>> [round(float(v), 3) for v in tone_curve(np.array([[0.0, 0.0031308, 0.18, 1.0]], np.float32), None)[0]]
    [0.0, 0.04, 0.461, 1.0]
    """
    del rng
    if law not in TONE_LAWS:
        raise ValueError(f"tone_curve law must be one of {TONE_LAWS}, got {law!r}")
    x = np.clip(img, 0.0, 1.0).astype(np.float32)
    if law == "gamma":
        return (x ** np.float32(1.0 / gamma)).astype(np.float32)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** np.float32(1.0 / 2.4) - 0.055).astype(np.float32)


def unsharp(img: np.ndarray, rng: np.random.Generator, *, amount: float, sigma: float) -> np.ndarray:
    """An image processor's sharpening: img + ``amount``·(img - Gaussian(img, ``sigma`` px)); edges gain a
    bright and a dark halo (clipped later, when the image is quantized)."""
    del rng
    src = img.astype(np.float32)
    return (src + np.float32(amount) * (src - cv2.GaussianBlur(src, (0, 0), sigma,
                                                                 borderType=cv2.BORDER_REFLECT))).astype(np.float32)
