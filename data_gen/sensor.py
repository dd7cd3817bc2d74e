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
- :func:`astigmatism`: blur along the radius and along the circle of different σ, growing towards the rim
  (a fisheye's sagittal and tangential foci part at wide angles; a renderer's radial "lens blur");
- :func:`bayer_demosaic`: an RGGB colour filter mosaic, demosaiced (bilinear or edge-aware), white balanced;
- :func:`tone_curve`: the sRGB transfer curve or a power law, applied to linear light;
- :func:`unsharp`: an image processor's sharpening (unsharp mask), with its halo at edges.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = ["circle_edge", "field_defocus", "lateral_ca", "astigmatism", "bayer_demosaic", "tone_curve", "unsharp",
           "disc_kernel",
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

    return blend_blurred(r, levels, blurred)


def blend_blurred(value: np.ndarray, levels: np.ndarray, blurred) -> np.ndarray:
    """(H, W) float32: an image blurred pixel by pixel by a varying amount ``value`` (H, W), as a blend of uniformly
    blurred copies ``blurred(level) -> (H, W) float32`` at ``levels`` (L,), evenly spaced and increasing, linear
    between the two copies about each pixel's value (clipped to the levels' range); one copy when they are equal."""
    if levels[-1] - levels[0] < 1e-6:
        return blurred(float(levels[0]))
    stack = [blurred(float(v)) for v in levels]
    pos = np.clip((value - levels[0]) / (levels[1] - levels[0]), 0.0, len(levels) - 1.0 - 1e-6)
    i = pos.astype(np.int32)
    frac = (pos - i).astype(np.float32)
    out = np.zeros_like(stack[0], dtype=np.float32)
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


def _blur_by_column(polar: np.ndarray, sigma: np.ndarray, axis: int, levels: int = 6) -> np.ndarray:
    """(A, R) float32 ``polar`` blurred along ``axis`` (0: the angle, wrapping round; 1: the radius) by a Gaussian
    whose σ (in rows or columns) is ``sigma`` (R,) per column: a blend of ``levels`` uniform blurs."""
    top = float(sigma.max())
    if top < 0.05:
        return polar
    steps = np.linspace(0.0, top, levels)
    pad = int(math.ceil(4.0 * top)) + 1 if axis == 0 else 0
    src = np.concatenate([polar[-pad:], polar, polar[:pad]]) if pad else polar
    stack = [polar]
    for sg in steps[1:]:
        # along one axis only (a σ of 0 would take the other's, so the other gets a negligible one)
        sx, sy = (float(sg), 1e-6) if axis == 1 else (1e-6, float(sg))
        b = cv2.GaussianBlur(src, (0, 0), sigmaX=sx, sigmaY=sy, borderType=cv2.BORDER_REFLECT)
        stack.append(b[pad:pad + polar.shape[0]] if pad else b)
    pos = np.clip(sigma / (steps[1] - steps[0]), 0.0, levels - 1.0 - 1e-6)
    i = pos.astype(np.int32)
    frac = (pos - i).astype(np.float32)
    out = np.empty_like(polar)
    for k in range(levels - 1):
        cols = i == k
        out[:, cols] = stack[k][:, cols] * (1.0 - frac[cols]) + stack[k + 1][:, cols] * frac[cols]
    return out


def astigmatism(img: np.ndarray, rng: np.random.Generator, *, sigma_radial: float, sigma_tangential: float,
                power: float, cx: float, cy: float, radius: float) -> np.ndarray:
    """Blur along the radius from the image circle's centre (cx, cy) px of σ ``sigma_radial`` px at the circle
    (``radius`` px) and along the circle of σ ``sigma_tangential`` px, both growing from 0 at the centre as
    ρ^``power``: a fisheye's astigmatism at wide angles, or a renderer's radial blur (``sigma_tangential`` 0).

    Blurs in polar coordinates (1 px along the radius, ≤ 1 px along the circle at its rim) and maps back; where
    the larger σ is under 1 px this blends towards the image as it was (0.25 px: unchanged), so that the
    polar resampling's own softening (about 0.4 px) stays out of the sharp centre.
    """
    del rng
    h, w = img.shape
    r_max = int(math.ceil(min(max(radius, 1.0), math.hypot(w, h)) * 1.02)) + 2
    n_ang = int(math.ceil(2.0 * math.pi * r_max))
    r = np.arange(r_max, dtype=np.float32)
    ang = np.arange(n_ang, dtype=np.float32) * np.float32(2.0 * math.pi / n_ang)
    mx = (np.float32(cx) + np.cos(ang)[:, None] * r[None, :]).astype(np.float32)
    my = (np.float32(cy) + np.sin(ang)[:, None] * r[None, :]).astype(np.float32)
    src = img.astype(np.float32)
    polar = cv2.remap(src, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    grow = (np.minimum(r / np.float32(max(radius, 1e-6)), 1.0) ** np.float32(power)).astype(np.float32)
    rows_per_px = n_ang / (2.0 * math.pi * np.maximum(r, 1.0))  # rows of the polar image per px of arc
    blurred = _blur_by_column(polar, sigma_radial * grow, axis=1)
    blurred = _blur_by_column(blurred, np.minimum(sigma_tangential * grow * rows_per_px, n_ang / 8.0), axis=0)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    dx, dy = xx - np.float32(cx), yy - np.float32(cy)
    back_r = np.minimum(np.hypot(dx, dy), np.float32(r_max - 1))
    back_a = (np.mod(np.arctan2(dy, dx), np.float32(2.0 * math.pi)) * np.float32(n_ang / (2.0 * math.pi)))
    back = cv2.remap(np.concatenate([blurred, blurred[:1]]), back_r, back_a, cv2.INTER_LINEAR)  # the angle wraps
    rho = np.minimum(back_r / np.float32(max(radius, 1e-6)), 1.0)
    reach = max(sigma_radial, sigma_tangential) * rho ** np.float32(power)
    share = np.clip((reach - 0.25) / 0.75, 0.0, 1.0).astype(np.float32)
    return (src + share * (back - src)).astype(np.float32)


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
