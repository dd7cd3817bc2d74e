"""Coarse-to-fine detection on large images: which scales to try, and the way back to full size.

A board in a large photo usually has large squares, and the CNN finds X-junctions with squares
down to about 6 px. So a large image is first searched at a reduced scale (each pixel the mean of
an f×f block), where the network, refinement and grid assembly cost about 1/f² as much, and the
corners found are then refined once more on the full image. Only when that finds no complete
board is the next finer scale tried, down to full size (see :func:`aicalib_tf.detect.pipeline.detect_corners`).

Memory. A scale is searched whole only up to ``MAX_SEARCH_PIXELS`` (16 MP): a larger photo's
finest whole search is at f = 2, a quarter of its pixels, and full resolution is only reached in
windows about the corners found (:func:`refine_full`). With the network run in windows
(:mod:`aicalib_tf.cnn.inference`), a 48 MP photo peaks at 0.3–0.7 GB (docs/benchmark.md).
ChArUco photos go coarse to fine as well (:func:`charuco_scales`, :func:`boards_coarse_to_fine`).

Coordinates are (x, y) px, OpenCV's convention: the centre of pixel (0, 0) is at (0.0, 0.0). Block
(i, j) of factor f covers full pixels f·i … f·i + f − 1, so its centre is at f·i + (f − 1)/2.
Pure numpy/OpenCV.
"""

from __future__ import annotations

import cv2
import numpy as np

from aicalib_tf.detect.corners.junctions import nearest_spacing
from aicalib_tf.detect.pyramid_kernels import block_mean_colour, block_mean_grey
from aicalib_tf.detect.corners.refine import Smoothed, refine_windowed, window_radius
from aicalib_tf.geometry.pose import in_frame
from aicalib_tf.io import as_gray_float

__all__ = ["MIN_SIDE", "MAX_SEARCH_PIXELS", "QUICK_SIDE", "QUICK_LEVELS", "Frame", "scales", "quick_scales", "quick_shift", "downscale",
           "to_full", "refine_full", "charuco_scales", "boards_to_full", "boards_coarse_to_fine"]

MIN_SIDE = 800  # px: a reduced scale keeps at least this many pixels along the image's longer side
MAX_SEARCH_PIXELS = 16_000_000  # px: the most pixels of a scale searched whole (a 48 MP photo's finest is f = 2)
MAX_REFINE_PIXELS = 4_000_000  # px: a board's region refined at once; larger ones in windows about their corners
REFINE_TILE = 1024  # px: the side of those windows' cells
QUICK_SIDE = 240  # px: a quick pass keeps at least this many pixels along the image's longer side
QUICK_LEVELS = 2  # quick passes at most (measured on evaluate --quick: 640x480 at 160x120 found no clean board,
# 1920x1080 at 240x135 found all)


def scales(width: int, height: int, min_side: int = MIN_SIDE, max_pixels: int = MAX_SEARCH_PIXELS) -> list[int]:
    """Reduction factors to try, coarsest first, ending with the finest searched whole.

    The coarsest is the largest power of two that leaves ``min_side`` px along the longer side:
    [1] up to 1599 px, [2, 1] for 1920×1080, [4, 2, 1] for 4000×3000. The finest is 1 (full
    size) unless that has more than ``max_pixels`` px: then the finest power of two within them
    (never coarser than the coarsest): [8, 4, 2] for 8000×6000, whose corners are refined on the
    full image in windows about them (:func:`refine_full`). Memory and time then stay bounded, and
    a board any scale finds is one a quarter of the photo (f = 2) shows as well.
    """
    f = 1
    while max(int(width), int(height)) // (2 * f) >= min_side:
        f *= 2
    out = []
    while f >= 1:
        out.append(f)
        f //= 2
    whole = [f for f in out if (int(width) // f) * (int(height) // f) <= max_pixels]
    return whole or out[:1]


def quick_scales(width: int, height: int, min_side: int = QUICK_SIDE, levels: int = QUICK_LEVELS) -> list[int]:
    """The factors of the quick passes, coarsest first: up to ``levels`` powers of two beyond the
    coarsest of :func:`scales`, each keeping at least ``min_side`` px along the longer side and 8
    along the shorter.

    Only a complete board found by a quick pass counts (the caller goes on to :func:`scales`
    otherwise): a board's squares are mostly large enough for the CNN (about 4 px and more) at a
    coarser scale, where it costs 1/f² as much. [2] for 640×480, [4, 2] for 1280×720, [8, 4] for
    1920×1080, [] for 320×240.
    """
    w, h = int(width), int(height)
    f = scales(w, h)[0]
    out = []
    while len(out) < levels and max(w, h) // (2 * f) >= min_side and min(w, h) // (2 * f) >= 8:
        f *= 2
        out.insert(0, f)
    return out


def quick_shift(factor: int) -> float:
    """px: the furthest a quick pass's corner may move when it is refined on the full image
    (:func:`refine_full`): 0.6·f, at most 2.

    A corner found at factor f is good to about 0.3 of a reduced pixel, 0.6 px at f = 2 (evaluate's
    640×480 boards: 90% within 0.5 px, 99% within 1.3). One that moves further was placed
    poorly there or is pulled on the full image (heavy noise, a shadow edge), so the board is
    left to the finer scales: data_gen ``hard`` seed 5 #39 had one corner moved 1.6 px, to 2.1
    px from the truth, where the full-size search finds a partial board without it.
    """
    return min(2.0, 0.6 * float(factor))


class Frame:
    """The image searched, converted to float32 grey only where a stage needs it.

    raw : an array the image gate has checked (:func:`aicalib_tf.io.read_image`). A uint8 image
    stays as it is: its reduced scales come from its bytes (:func:`downscale`) and a region is
    converted alone (:meth:`region`), so a large frame whose board a quick pass finds is never
    converted whole. Any other type is converted at once. Every value is the same pixel's of
    :func:`aicalib_tf.io.as_gray_float` of the whole image (within 1e-7 for colour).
    """

    def __init__(self, raw: np.ndarray):
        self.raw = raw
        self._gray = None if raw.dtype == np.uint8 else as_gray_float(raw)

    @classmethod
    def of_gray(cls, gray: np.ndarray) -> Frame:
        """A frame of (H, W) grey in [0, 1], already converted (float32 taken as it is)."""
        frame = cls.__new__(cls)
        frame.raw, frame._gray = gray, np.asarray(gray, np.float32)
        return frame

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) px."""
        return int(self.raw.shape[1]), int(self.raw.shape[0])

    @property
    def gray(self) -> np.ndarray:
        """(H, W) float32 grey in [0, 1], the whole image (converted on first use)."""
        if self._gray is None:
            self._gray = as_gray_float(self.raw)
        return self._gray

    def region(self, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
        """Pixels x0 … x1 − 1, y0 … y1 − 1 as (y1 − y0, x1 − x0) float32 grey, a C-ordered array of its own."""
        if self._gray is not None:
            return np.ascontiguousarray(self._gray[y0:y1, x0:x1])
        return as_gray_float(self.raw[y0:y1, x0:x1])

    def reduced(self, factor: int) -> np.ndarray:
        """The image at 1/``factor`` scale (:func:`downscale`); the whole image at factor 1."""
        if int(factor) == 1:
            return self.gray
        return downscale(self.raw if self._gray is None else self._gray, factor)


def downscale(gray: np.ndarray, factor: int) -> np.ndarray:
    """Each f×f block's mean: (H // f, W // f) float32 (the last H % f rows and W % f columns are dropped).

    gray : (H, W) float32 grey in [0, 1], or a uint8 image as the image gate takes it ((H, W) or
    (H, W, 3|4) BGR(A)), whose means come from its bytes in one pass
    (:mod:`aicalib_tf.detect.pyramid_kernels`), in the gate's grey levels.
    Empty where a side is shorter than f (an 8000×1 image at f = 8: (0, 1000)).
    """
    f = int(factor)
    if gray.dtype == np.uint8:
        if f == 1:
            return as_gray_float(gray)
        return block_mean_grey(gray, f) if gray.ndim == 2 else block_mean_colour(gray, f)
    g = np.asarray(gray, np.float32)
    if f == 1:
        return g
    h, w = g.shape[0] // f, g.shape[1] // f
    if h == 0 or w == 0:  # cv2.resize refuses an empty size
        return np.zeros((h, w), np.float32)
    # INTER_AREA at an integer factor is the block mean
    return cv2.resize(g[: h * f, : w * f], (w, h), interpolation=cv2.INTER_AREA)


def to_full(points: np.ndarray, factor: int) -> np.ndarray:
    """Points (N, 2) (x, y) px on a :func:`downscale`\\ d image -> the same places on the full image."""
    f = float(factor)
    return (np.asarray(points, np.float64) * f + (f - 1.0) / 2.0).astype(np.float32)


def refine_full(image, points: np.ndarray, max_shift: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """Refine corners found at a reduced scale on the full image (saddle fit, :mod:`aicalib_tf.detect.corners.refine`).

    image : a :class:`Frame`, or (H, W) float32 grey, the full image. points : (N, 2) px on it (from
    :func:`to_full`), N ≥ 2, of one board. Only the board's bounding box (plus the largest window)
    is converted and smoothed. Returns refined (N, 2) float32 and ok (N,) bool; a point whose refinement fails, moves more than ``max_shift`` px or would
    leave the image keeps its given position, with ok False (at a factor f that position is only good
    to a fraction of f px, so the caller should not trust the board).
    """
    pts = np.asarray(points, np.float32).reshape(-1, 2)
    frame = image if isinstance(image, Frame) else Frame.of_gray(image)
    w, h = frame.size
    spacing = nearest_spacing(pts)
    margin = int(window_radius(spacing).max()) + 8
    refined, ok = pts.copy(), np.zeros(len(pts), bool)
    for sel in _refine_groups(pts, margin, (w, h)):
        p = pts[sel]
        x0, y0 = np.maximum(np.floor(p.min(axis=0)).astype(int) - margin, 0)
        x1, y1 = np.minimum(np.ceil(p.max(axis=0)).astype(int) + margin + 1, [w, h])
        offset = np.array([x0, y0], np.float32)
        got, got_ok = refine_windowed(Smoothed(frame.region(x0, y0, x1, y1)), p - offset, spacing[sel],
                                      max_shift=np.full(len(p), float(max_shift)))
        refined[sel], ok[sel] = got + offset, got_ok
    ok &= in_frame(refined, (w, h))
    return np.where(ok[:, None], refined, pts).astype(np.float32), ok


def _refine_groups(pts: np.ndarray, margin: int, size: tuple[int, int]) -> list[np.ndarray]:
    """Index sets of pts (N, 2) px refined together: all of them when their region (bounding box
    plus ``margin``) holds at most ``MAX_REFINE_PIXELS``, else those in each ``REFINE_TILE`` cell
    (a board filling a 48 MP photo: a few dozen small windows, only where its corners are). Each
    point's window keeps ``margin`` px of its own image about it either way, so its fit is the same
    (to the float32 rounding of the window's offset, under 1e-3 px)."""
    lo = np.floor(pts.min(axis=0)) - margin
    hi = np.ceil(pts.max(axis=0)) + margin + 1
    area = np.prod(np.minimum(hi, size) - np.maximum(lo, 0))
    if not np.all(np.isfinite(pts)) or area <= MAX_REFINE_PIXELS:
        return [np.arange(len(pts))]
    cell = np.floor(pts / REFINE_TILE).astype(np.int64)
    _, group = np.unique(cell, axis=0, return_inverse=True)
    group = group.ravel()
    return [np.flatnonzero(group == g) for g in range(int(group.max()) + 1)]


CHARUCO_WHOLE_PIXELS = 4_200_000  # px: a ChArUco search up to this size runs on the full image alone
CHARUCO_MIN_SIDE = 640  # px: the coarsest ChArUco scale keeps at least this many along the longer side


def charuco_scales(width: int, height: int) -> list[int]:
    """The reduction factors of a ChArUco search, coarsest first: [1] up to ``CHARUCO_WHOLE_PIXELS``
    (2560×1600, 2048×2048), else :func:`scales` down to ``CHARUCO_MIN_SIDE`` px (12 MP: [4, 2, 1];
    24 MP: [8, 4, 2]; 48 MP: [8, 4, 2]). The search
    stops at the first scale where a board is complete: its markers and corners are read at 1/f² of
    the cost, and its corners refined on the full image (:func:`boards_to_full`)."""
    if int(width) * int(height) <= CHARUCO_WHOLE_PIXELS:
        return [1]
    return scales(width, height, CHARUCO_MIN_SIDE)


def boards_to_full(frame: Frame, found: list, factor: int) -> list:
    """ChArUco detections (:class:`aicalib_tf.detect.charuco.detector.CharucoDetection`) made on the image
    reduced by ``factor``, brought to the full image (a :class:`Frame`).

    Corners go through :func:`to_full` and :func:`refine_full` (windows about them, at most 2 px
    moved); a corner whose refinement fails is left out (its id stays decided by the markers),
    and a board left without corners is dropped. Marker corners are scaled as points.
    """
    from dataclasses import replace

    f = int(factor)
    if f == 1:
        return list(found)
    out = []
    for det in found:
        pts = to_full(det.corners, f)
        refined, ok = refine_full(frame, pts) if len(pts) >= 2 else (pts, np.zeros(len(pts), bool))
        markers = np.asarray(det.marker_corners, np.float64) * f + (f - 1.0) / 2.0
        if ok.any():
            out.append(replace(det, corners=refined[ok], ids=det.ids[ok], marker_corners=markers,
                               complete=bool(det.complete and ok.all()), image_size=frame.size))
    return out


def boards_coarse_to_fine(frame: Frame, search) -> list:
    """ChArUco boards by ``search(gray (h, w) float32) -> [CharucoDetection]`` at each of
    :func:`charuco_scales`, coarsest first, brought to the full image (:func:`boards_to_full`).
    Stops at the first scale with a complete board; else the scale whose boards hold the most
    corners (the coarsest of equal ones)."""
    best = []
    for f in charuco_scales(*frame.size):
        found = boards_to_full(frame, search(frame.reduced(f)), f)
        best = max(best, found, key=lambda dets: sum(len(d.corners) for d in dets))
        if any(d.complete for d in found):
            break
    return best
