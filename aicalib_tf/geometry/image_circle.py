"""The image circle of a circular fisheye: where the lens puts light, estimated from the photos.

A circular fisheye (a 185° lens on a 4:3 sensor) images a disk; outside it the photo is black.
Nothing outside that disk is a ray of the lens, so no board can reach it, no coverage is missing
there and no uncertainty or undistortion means anything there.

* :class:`ImageCircle`: centre (x, y) and radius, px (pixel (0, 0)'s centre at 0.0).
* :func:`estimate_image_circle`: the circle from the mean of the photos (a dark ring around a
  bright disk), or None for photos that fill the frame; :func:`find_image_circle` also says why
  none was found where the frame's corners are dark (the calibration then uses the full frame).
* :func:`circle_fov_deg`: the circle's diameter in degrees, through a lens model (past the boards'
  reach, :func:`boards_reach_deg`, the model's own extrapolation; :mod:`aicalib_tf.calib.circle_fov`
  chooses the terms an equidistant model extrapolates with).
* :func:`circle_problem`: whether a lens model and a circle agree (a sentence when they do not).

Pure numpy/OpenCV.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["ImageCircle", "boards_reach_deg", "circle_fov_deg", "circle_problem", "circle_tuple", "estimate_image_circle", "find_image_circle",
           "into_circle",
           "rim_angles_deg", "rim_points", "thumbnail"]

THUMB_SIDE = 640  # px: the longest side the photos are averaged at (the circle is scaled back)
DARK_FRACTION = 0.25  # the threshold, from the black level towards the disk's median brightness
MIN_DARK_CORNERS = 3  # of the frame's 4 corners, how many must be black for a circle
MAX_BLACK = 0.2  # the black level (1st percentile) is at most this share of the disk's median brightness
MAX_RESIDUAL = 1.5  # px at the averaged size: the boundary's median distance from the fitted circle
CONSENSUS_TRIALS = 300  # three-point circles drawn (fixed seed) for the consensus start
MIN_ON_CIRCLE = 0.5  # the least share of the boundary's points that must lie on the circle


@dataclass(frozen=True)
class ImageCircle:
    """The image circle: centre ``(cx, cy)`` and ``radius``, px, in the photo's pixel coordinates."""

    cx: float
    cy: float
    radius: float

    def __post_init__(self):
        vals = (self.cx, self.cy, self.radius)
        if not all(math.isfinite(float(v)) for v in vals) or not float(self.radius) > 0:
            raise ValueError(f"an image circle needs a finite centre and a radius > 0, got {vals}")

    def contains(self, pixels, margin: float = 0.0) -> np.ndarray:
        """(...,) bool: pixels (..., 2) (x, y) px at most ``radius + margin`` from the centre."""
        p = np.asarray(pixels, np.float64)
        return np.hypot(p[..., 0] - self.cx, p[..., 1] - self.cy) <= self.radius + float(margin)

    def inside_frame(self, image_size) -> bool:
        """True when the whole circle lies in the (width, height) frame (a circle, not a cropped one)."""
        w, h = image_size
        return (self.cx - self.radius >= -0.5 and self.cy - self.radius >= -0.5
                and self.cx + self.radius <= w - 0.5 and self.cy + self.radius <= h - 0.5)

    def to_dict(self) -> dict:
        """{"cx", "cy", "radius"} px (``camera.json``'s ``image_circle``)."""
        return {"cx": float(self.cx), "cy": float(self.cy), "radius": float(self.radius)}


def circle_tuple(circle) -> tuple[float, float, float]:
    """(cx, cy, radius) px of an image circle given as such a tuple or an :class:`ImageCircle`."""
    if hasattr(circle, "radius"):
        return float(circle.cx), float(circle.cy), float(circle.radius)
    cx, cy, r = (float(v) for v in circle)
    return cx, cy, r


def into_circle(pts: np.ndarray, origin, circle) -> np.ndarray:
    """(N, 2) px: each of ``pts`` (N, 2) px outside ``circle`` (:func:`circle_tuple`) moved along the
    line from ``origin`` (x, y) px, inside the circle, onto the circle (unchanged when ``origin`` is not inside)."""
    cx, cy, r = circle_tuple(circle)
    o = np.asarray(origin, np.float64)
    d, q = pts - o, o - (cx, cy)
    a, b, c = np.sum(d * d, axis=1), 2 * d @ q, float(q @ q) - r * r
    if c >= 0:
        return pts
    t = (-b + np.sqrt(np.maximum(b * b - 4 * a * c, 0.0))) / np.maximum(2 * a, 1e-300)  # where the line leaves it, t > 0
    return np.where((t < 1)[:, None], o + t[:, None] * d, pts)


def thumbnail(gray: np.ndarray, max_side: int = THUMB_SIDE) -> np.ndarray:
    """(h, w) float32: ``gray`` (H, W) shrunk (area average) so that its longest side is at most ``max_side``."""
    g = np.asarray(gray, np.float32)
    if g.ndim != 2:
        raise ValueError(f"thumbnail takes an (H, W) grey image, got shape {g.shape}")
    s = max(g.shape) / float(max_side)
    if s <= 1.0:
        return g
    size = (max(1, round(g.shape[1] / s)), max(1, round(g.shape[0] / s)))
    return cv2.resize(g, size, interpolation=cv2.INTER_AREA)


def _fit_circle(pts: np.ndarray) -> tuple[float, float, float]:
    """(cx, cy, r) least-squares (Kåsa) circle through (N, 2) points."""
    x, y = pts[:, 0], pts[:, 1]
    A = np.stack([2 * x, 2 * y, np.ones_like(x)], axis=1)
    (cx, cy, c), *_ = np.linalg.lstsq(A, x * x + y * y, rcond=None)
    return float(cx), float(cy), float(np.sqrt(max(c + cx * cx + cy * cy, 0.0)))


def _robust_circle(pts: np.ndarray) -> tuple[float, float, float, float] | None:
    """(cx, cy, r, median |residual|) of the circle most of the (N, 2) boundary points ``pts`` agree on,
    or None with fewer than 20 points.

    A consensus start, then three least-squares fits, each on the points the previous circle left
    within 3 MADs (at least 1 px): the start is the circle through three of the points (``CONSENSUS_TRIALS``
    draws from a fixed seed, and the least-squares circle of them all) that has the most points within
    :data:`MAX_RESIDUAL` px. Dark things inside the disk that touch the dark outside (a chair's legs
    at the rim) dent the boundary; a fit of all points follows the dents, the consensus does not.
    The median is over the points the last fit kept; a boundary that agrees with no circle keeps few
    of its points (:data:`MIN_ON_CIRCLE`, :func:`_no_circle`)."""
    if len(pts) < 20:
        return None
    x, y = pts[:, 0], pts[:, 1]
    cands = np.array([_fit_circle(pts)] + [_fit_circle(pts[t])
                                           for t in np.random.default_rng(0).integers(0, len(pts), (CONSENSUS_TRIALS, 3))])
    with np.errstate(invalid="ignore"):
        res = np.abs(np.hypot(x[None] - cands[:, :1], y[None] - cands[:, 1:2]) - cands[:, 2:])
    cx, cy, r = cands[int(np.argmax(np.sum(res <= MAX_RESIDUAL, axis=1)))]
    keep = np.abs(np.hypot(x - cx, y - cy) - r) <= 2 * MAX_RESIDUAL
    for _ in range(3):
        if keep.sum() < 20:
            return None
        cx, cy, r = _fit_circle(pts[keep])
        res = np.abs(np.hypot(x - cx, y - cy) - r)
        mad = float(np.median(res[keep]))
        keep = res <= max(1.0, 3.0 * 1.4826 * mad)
    if keep.mean() < MIN_ON_CIRCLE:
        return cx, cy, r, float("inf")
    return cx, cy, r, float(np.median(res[keep]))


def _refine(g: np.ndarray, circle: tuple[float, float, float], black: float, bright: float, n: int = 360,
            reach: float = 6.0) -> np.ndarray:
    """(k, 2) px: where the image ``g`` crosses halfway from ``black`` to its level just inside the
    rim, along ``n`` radial lines from the coarse ``circle`` (cx, cy, r), ±``reach`` px around r
    (sub-pixel: an edge an area average blurs keeps its 50% crossing). Lines that leave the
    frame or show no step (less than a fifth of ``bright`` − ``black``) are left out."""
    cx, cy, r = circle
    h, w = g.shape
    a = 2 * np.pi * np.arange(n) / n
    t = np.arange(-reach, reach + 1e-9, 0.25)  # outward offsets from r
    rad = r + t[None, :]
    xs, ys = cx + rad * np.cos(a)[:, None], cy + rad * np.sin(a)[:, None]
    ok = np.all((xs >= 0) & (xs <= w - 1) & (ys >= 0) & (ys <= h - 1), axis=1)
    prof = cv2.remap(g, xs.astype(np.float32), ys.astype(np.float32), cv2.INTER_LINEAR)
    inner = prof[:, : len(t) // 4].mean(axis=1)
    half = 0.5 * (black + inner)
    above = prof >= half[:, None]
    i = len(t) - 1 - np.argmax(above[:, ::-1], axis=1)  # the last sample at or above half
    ok &= (inner - black > 0.2 * (bright - black)) & above.any(axis=1) & (i < len(t) - 1)
    i = np.minimum(i, len(t) - 2)
    rows = np.arange(n)
    p0, p1 = prof[rows, i], prof[rows, i + 1]
    frac = np.clip((p0 - half) / np.maximum(p0 - p1, 1e-9), 0.0, 1.0)
    edge = r + t[i] + 0.25 * frac
    return np.stack([cx + edge * np.cos(a), cy + edge * np.sin(a)], axis=1)[ok]


def estimate_image_circle(image, full_size=None) -> ImageCircle | None:
    """The image circle of a circular fisheye from its photos, or None when the photos fill the frame.

    image : (h, w) float grey, the mean of the photos (or one photo), e.g. of their
        :func:`thumbnail`\\ s. full_size : (W, H) px of the photos when ``image`` is a shrunk copy
        (the circle is scaled back to it); None: ``image``'s own size.

    The image is smoothed, thresholded a quarter of the way from its black level (1st percentile)
    to the median of its central half (a black level above a fifth of that median is no black ring:
    None), and the dark pixels connected to the frame's border form the outside. With at least three of the four frame corners outside, the boundary of the inside
    (less the points on the frame's edge, where a cropped circle is cut) is fitted with the circle most
    of its points agree on (:func:`_robust_circle`: dark things inside the disk that touch the rim
    dent the boundary), points more than 3 MADs off dropped; a boundary that is no circle (less than
    half of it on the circle, or a median residual above 1.5 px), a radius under a tenth of the
    frame or a flat image give None. The rim is then found to
    a fraction of a pixel on radial lines of the unsmoothed image (:func:`_refine`) and fitted again.

    >>> yy, xx = np.mgrid[:120, :160]
    >>> disk = (np.hypot(xx - 80.0, yy - 60.0) <= 50.0).astype(np.float32)
    >>> c = estimate_image_circle(disk)
    >>> round(c.cx), round(c.cy), round(c.radius)
    (80, 60, 50)
    >>> estimate_image_circle(np.full((120, 160), 0.5, np.float32)) is None
    True
    """
    return find_image_circle(image, full_size)[0]


def find_image_circle(image, full_size=None) -> tuple[ImageCircle | None, str]:
    """(circle or None, why none): :func:`estimate_image_circle`, with a sentence when the frame's
    corners are dark (at least three of four: a circular fisheye, it seems) but no circle fits the
    boundary of the bright area; "" when a circle is found or the photos fill the frame.

    >>> yy, xx = np.mgrid[:120, :160]
    >>> square = ((abs(xx - 80.0) <= 45) & (abs(yy - 60.0) <= 45)).astype(np.float32)
    >>> find_image_circle(square)[1].startswith("the frame's corners are dark but")
    True
    """
    raw = np.asarray(image, np.float32)
    if raw.ndim != 2 or min(raw.shape) < 16:
        raise ValueError(f"estimate_image_circle takes an (h, w) grey image of at least 16x16, got shape {raw.shape}")
    if not np.all(np.isfinite(raw)):
        raise ValueError("estimate_image_circle: the image holds NaN or infinite values")
    h, w = raw.shape
    g = cv2.GaussianBlur(raw, (0, 0), 1.0)
    black = float(np.percentile(g, 1))
    bright = float(np.median(g[h // 4: h - h // 4, w // 4: w - w // 4]))
    if not (bright > 0 and black <= MAX_BLACK * bright):  # no black ring (a vignetted corner stays grey)
        return None, ""
    below = (g <= black + DARK_FRACTION * (bright - black)).astype(np.uint8)
    _, labels = cv2.connectedComponents(below, connectivity=4)
    edge = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    outside = np.isin(labels, edge[edge > 0])
    p = max(1, round(0.03 * min(h, w)))
    corners = [outside[:p, :p], outside[:p, -p:], outside[-p:, :p], outside[-p:, -p:]]
    if sum(c.mean() > 0.5 for c in corners) < MIN_DARK_CORNERS:
        return None, ""
    contours, _ = cv2.findContours((~outside).astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    pts = max(contours, key=cv2.contourArea).reshape(-1, 2).astype(np.float64) if contours else np.zeros((0, 2))
    pts = pts[(pts[:, 0] > 0) & (pts[:, 1] > 0) & (pts[:, 0] < w - 1) & (pts[:, 1] < h - 1)]
    fit = _robust_circle(pts) if len(pts) >= 20 else None
    why = _no_circle(fit, max(h, w))
    if why:
        return None, "the frame's corners are dark but " + why
    fine = _refine(raw, (fit[0], fit[1], fit[2] + 0.5), black, bright)  # the contour runs through inside pixels' centres
    refined = _robust_circle(fine)
    fit = refined if refined is not None and np.isfinite(refined[3]) else fit
    cx, cy, r = fit[0], fit[1], fit[2]
    W, H = (w, h) if full_size is None else (float(full_size[0]), float(full_size[1]))
    sx, sy = W / w, H / h
    return ImageCircle((cx + 0.5) * sx - 0.5, (cy + 0.5) * sy - 0.5, r * 0.5 * (sx + sy)), ""


def _no_circle(fit, side: int) -> str:
    """Why a coarse ``fit`` (cx, cy, r, median residual) px of the bright area's boundary, or None,
    is no image circle ("" when it is one); side : the averaged image's longer side, px."""
    if fit is None:
        return "the bright area's boundary is too short to fit a circle to"
    if not np.isfinite(fit[3]):
        return (f"the bright area's boundary is no circle (less than {MIN_ON_CIRCLE:.0%} of it lies on any one "
                f"circle in the photos' shrunk mean)")
    if fit[3] > MAX_RESIDUAL:
        return (f"the bright area's boundary is no circle (median distance {fit[3]:.1f} px from the best circle in "
                f"the photos' shrunk mean, at most {MAX_RESIDUAL:g} px allowed)")
    if fit[2] < 0.1 * side:
        return f"the bright area is too small for an image circle (radius {fit[2]:.0f} px of a {side} px frame)"
    return ""


def rim_points(circle: ImageCircle, n: int = 72) -> np.ndarray:
    """(n, 2) px: points evenly spaced on the circle, point k at angle 2πk/n (n even: k and k + n/2 opposite)."""
    a = 2 * np.pi * np.arange(int(n)) / int(n)
    return np.stack([circle.cx + circle.radius * np.cos(a), circle.cy + circle.radius * np.sin(a)], axis=1)


def rim_angles_deg(lens, circle: ImageCircle, n: int = 72) -> np.ndarray:
    """(n,) degrees off-axis of the rays ``lens`` gives the rim (NaN where it has none)."""
    rays = lens.unproject(rim_points(circle, n))
    return np.degrees(np.arctan2(np.hypot(rays[:, 0], rays[:, 1]), rays[:, 2]))


def boards_reach_deg(lens, corners) -> float:
    """Degrees: the largest off-axis angle of the rays ``lens`` gives the detected ``corners``
    ((N, 2) px), how far the boards reach; NaN when there are none."""
    pts = np.asarray(corners, np.float64).reshape(-1, 2)
    if not len(pts):
        return math.nan
    rays = lens.unproject(pts)
    theta = np.degrees(np.arctan2(np.hypot(rays[:, 0], rays[:, 1]), rays[:, 2]))
    return float(np.nanmax(theta)) if np.isfinite(theta).any() else math.nan


def circle_fov_deg(lens, circle: ImageCircle) -> float:
    """Degrees: the image circle's diameter through ``lens`` (a :class:`~aicalib_tf.geometry.lens.Lens`),
    the mean over diameters of the two rim rays' off-axis angles; never NaN: a rim point the model
    gives no ray counts with the widest angle the model images. Past the boards' reach
    (:func:`boards_reach_deg`) this is the model's own extrapolation; the calibration's report reads an
    equidistant model there through the fewest terms the held-out views support
    (:mod:`aicalib_tf.calib.circle_fov`), which ``benchmarks/circle_fov.py`` scores on synthetic truth.
    """
    theta = rim_angles_deg(lens, circle)
    theta = np.where(np.isfinite(theta), theta, math.degrees(lens.max_angle()))
    half = len(theta) // 2
    return float(np.mean(theta[:half] + theta[half:2 * half]))


def circle_problem(lens, circle: ImageCircle, corners=None, tolerance_px: float = 3.0) -> str | None:
    """Why ``lens`` and ``circle`` disagree (a sentence), or None.

    * the rim lies beyond the rays the lens model images (its largest valid angle): the model
      cannot describe the photo out to its circle;
    * detected ``corners`` ((N, 2) px) lie more than ``tolerance_px`` outside the circle: the
      circle is wrong (or the corners are).
    """
    theta = rim_angles_deg(lens, circle)
    bad = ~np.isfinite(theta)
    if bad.any():
        return (f"the image circle (radius {circle.radius:.0f} px) reaches beyond the rays the {lens.model} model "
                f"images (up to {math.degrees(lens.max_angle()):.0f}°) on {100 * bad.mean():.0f}% of its rim")
    if corners is not None and len(corners):
        out = ~circle.contains(np.asarray(corners, np.float64).reshape(-1, 2), tolerance_px)
        if out.any():
            return (f"{int(out.sum())} detected corners lie outside the image circle (centre {circle.cx:.0f}, "
                    f"{circle.cy:.0f}, radius {circle.radius:.0f} px)")
    return None
