"""Exact bilinear image samples inside compiled loops (numba), shared by the refinement kernels.

Images are (H, W) float32; points are (x, y) px with the centre of pixel (0, 0) at (0.0, 0.0);
samples outside the image take the nearest edge pixel (OpenCV's BORDER_REPLICATE). The fits sample
here, in float64 at float64 positions: ``cv2.remap`` (:func:`sample_bilinear`) takes float32
positions, and OpenCV 4 rounded them to 1/32 px.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from aicalib_tf.kernels import helper, kernel

__all__ = ['sample_bilinear', 'sample_windows']


@helper
def _along_x(img, r, c0, c1, fx):
    """Row r's value between pixels (r, c0) and (r, c1) at fraction fx (float32 difference, float64 result)."""
    return img[r, c0] + fx * (img[r, c1] - img[r, c0])


@helper
def _lerp(img, r0, r1, c0, c1, fx, fy):
    """Bilinear value between pixels (r0, c0), (r0, c1), (r1, c0), (r1, c1) at fractions fx, fy."""
    top = _along_x(img, r0, c0, c1, fx)
    bot = _along_x(img, r1, c0, c1, fx)
    return top + fy * (bot - top)


@helper
def _sample_grid(img, x, y, lo, side, out):
    """Bilinear samples at (x + i, y + j) for i, j in lo .. lo + side − 1, row-major into out (side²,)."""
    h, w = img.shape
    x0, y0 = math.floor(x), math.floor(y)
    fx, fy = x - x0, y - y0
    c, r = x0 + lo, y0 + lo  # the first pixel read
    if c >= 0 and r >= 0 and c + side < w and r + side < h:
        _sample_inside(img, c, r, fx, fy, side, out)
        return
    k = 0
    for j in range(side):
        r0 = min(max(y0 + lo + j, 0), h - 1)
        r1 = min(max(y0 + lo + j + 1, 0), h - 1)
        for i in range(side):
            c0 = min(max(x0 + lo + i, 0), w - 1)
            c1 = min(max(x0 + lo + i + 1, 0), w - 1)
            out[k] = _lerp(img, r0, r1, c0, c1, fx, fy)
            k += 1


@helper
def _sample_inside(img, c, r, fx, fy, side, out):
    """:func:`_sample_grid` where every pixel read lies inside the image (no clamping), with the same
    arithmetic: a pixel row's interpolation along x is the bottom of one row of samples and the top
    of the next, so it is worked out once (kept in the next row's slots of ``out`` until used).
    c, r : the first column and row read."""
    for i in range(side):
        out[i] = _along_x(img, r, c + i, c + i + 1, fx)
    for j in range(side):
        row = r + j + 1
        base = j * side
        for i in range(side):
            top = out[base + i]
            bot = _along_x(img, row, c + i, c + i + 1, fx)
            out[base + i] = top + fy * (bot - top)
            if j + 1 < side:
                out[base + side + i] = bot


@kernel("f4[:, ::1], f8[:, ::1], i8")
def sample_windows(img, pts, radius):
    """(P, (2r+1)²) float64: bilinear samples of img about each point, offsets row-major (dy outer)."""
    side = 2 * radius + 1
    out = np.empty((pts.shape[0], side * side))
    for p in range(pts.shape[0]):
        _sample_grid(img, pts[p, 0], pts[p, 1], -radius, side, out[p])
    return out


@helper
def _bilinear(img, x, y):
    """The image at (x, y) px, bilinear, the nearest edge pixel outside."""
    h, w = img.shape
    x0, y0 = math.floor(x), math.floor(y)
    fx, fy = x - x0, y - y0
    c0, c1 = min(max(x0, 0), w - 1), min(max(x0 + 1, 0), w - 1)
    r0, r1 = min(max(y0, 0), h - 1), min(max(y0 + 1, 0), h - 1)
    return _lerp(img, r0, r1, c0, c1, fx, fy)


_REMAP_COLS = 4096  # cv2.remap needs maps of fewer than 32767 rows and columns


def sample_bilinear(g: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Bilinear grey values (M,) float32 of g (H, W) float32 at xy (M, 2) px, border replicated, any M.

    The points go to cv2.remap as rows of at most ``_REMAP_COLS`` (its maps hold fewer than 32767 rows
    and columns, so one row of every point would fail past that). A few points make one short row
    (each sample depends on its own point alone, so the layout changes no value).
    """
    m = len(xy)
    if m == 0:
        return np.zeros(0, np.float32)
    cols = min(m, _REMAP_COLS)
    rows = -(-m // cols)
    flat = np.zeros((rows * cols, 2), np.float32)
    flat[:m] = xy
    flat = flat.reshape(rows, cols, 2)
    return cv2.remap(g, flat[..., 0], flat[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).ravel()[:m]
