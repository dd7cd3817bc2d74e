"""Corners of a full board that an object in front has replaced: the sector test.

A chessboard corner joins four squares, and the board's parity fixes their colours: the square
(i + ½, j + ½) beside corner (i, j) is dark for one parity of i + j and light for the other. A
shadow or vignetting multiplies the intensities, so in log intensity each light square stays
brighter than the two dark squares beside it, even where a shadow edge crosses the corner (the
contrast shrinks by the shadow's log ratio, it does not change sign). An object in front replaces
two or more of the squares with its own colour: next to a point on its edge at least one pair of
adjacent sectors loses its contrast, or turns the wrong way round.

:func:`sector_contrast` reads each corner's four sectors on the board's own lines (the bisectors
of the grid directions, on an arc at 0.3 of the corner's smallest step) and returns the least of
its four adjacent-sector log contrasts, signed by the board's parity. :func:`occluded_corners`
flags the corners whose least contrast is below ``LEAST_SHARE`` of the median of their grid
neighbours' (the rim's darkening, blur and squeeze change it slowly across the board).

:func:`object_in_front` takes a full board's corner as an object's edge only where this test and
:func:`aicalib_tf.detect.chessboard.rim.unlike_neighbours` (ring amplitude and lopsidedness) both
flag it: a shadow edge can make a ring lopsided but leaves the sectors' order, and a near-black rim
leaves the sectors' order to noise but its ring like its neighbours'.
"""

from __future__ import annotations

import cv2
import numpy as np

from aicalib_tf.detect.chessboard.rim import grid_directions, neighbour_median, unlike_neighbours

__all__ = ["sector_contrast", "occluded_corners", "object_in_front", "LEAST_SHARE", "ARC"]

LEAST_SHARE = 0.3  # a corner's least sector contrast over its neighbours' median: the least
ARC = np.deg2rad(np.array([-20.0, -10.0, 0.0, 10.0, 20.0]))  # sample directions about each bisector
RADIUS = 0.3  # of the corner's smallest step: the arc's radius (at least 1.5 px)
FLOOR = 0.05  # of the board's bright level: added before the log (dark rims near black, noise)
CROP_SIGMA = 1.0  # px: the Gaussian that smooths an unsmoothed image's board crop before the test


def sector_contrast(points: np.ndarray, ring_image: np.ndarray) -> np.ndarray:
    """(a, b) float: each corner's least adjacent-sector contrast in log intensity, parity-signed.

    points : (a, b, 2) px, every position of a full grid (a, b ≥ 2). ring_image : (H, W) float32,
    smoothed (σ ≈ 1 px). The four sectors (+i+j, +j−i, −i−j, −i+j, in turn about the corner) are
    each the mean of ``ARC`` samples about the bisector of their two grid directions, at
    ``RADIUS`` of the corner's smallest step. The sign makes a corner of the board's majority
    parity positive; a value near 0 or below means two adjacent sectors of one colour.
    """
    a, b = points.shape[:2]
    d = grid_directions(points)  # (4, a, b, 2)
    length = np.hypot(d[..., 0], d[..., 1])
    unit = d / np.maximum(length, 1e-9)[..., None]
    radius = np.maximum(1.5, RADIUS * length.min(axis=0))  # (a, b)
    mid = unit + np.roll(unit, -1, axis=0)  # (4, a, b, 2): sector k between directions k and k + 1
    ang = np.arctan2(mid[..., 1], mid[..., 0])[..., None] + ARC  # (4, a, b, n)
    x = (points[..., 0, None] + radius[..., None] * np.cos(ang)).astype(np.float32).reshape(1, -1)
    y = (points[..., 1, None] + radius[..., None] * np.sin(ang)).astype(np.float32).reshape(1, -1)
    v = cv2.remap(np.ascontiguousarray(ring_image, np.float32), x, y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    s = v.reshape(4, a, b, -1).mean(axis=3)  # (4, a, b)
    s = np.log(np.maximum(s, 0) + FLOOR * max(float(np.percentile(s, 90)), 1e-6))
    diag = s[0] + s[2] - s[1] - s[3]
    parity = np.where((np.add.outer(np.arange(a), np.arange(b)) % 2) == 0, 1.0, -1.0)
    sign = parity * (1.0 if np.sum(np.sign(diag) * parity) >= 0 else -1.0)
    adjacent = np.stack([s[0] - s[1], s[2] - s[1], s[2] - s[3], s[0] - s[3]])
    return (adjacent * sign).min(axis=0)


def occluded_corners(points: np.ndarray, ring_image: np.ndarray) -> np.ndarray:
    """(a, b) bool: the corners whose sectors do not alternate like their neighbours' (an object in front).

    points, ring_image : as :func:`sector_contrast`. A corner is flagged when its least contrast is
    below ``LEAST_SHARE`` of the median over its (up to 8) grid neighbours.
    """
    a, b = points.shape[:2]
    m = sector_contrast(points, ring_image)
    if m.min() >= LEAST_SHARE * m.max():  # no neighbours' median can reach it: the usual, clean board
        return np.zeros((a, b), bool)
    return m < LEAST_SHARE * np.maximum(neighbour_median(m), 1e-6)


def object_in_front(corners: np.ndarray, pattern_size: tuple[int, int], ring_image: np.ndarray) -> bool:
    """Whether a full board holds a corner that is an object's edge, not an X-junction.

    corners : (cols·rows, 2) px in OpenCV order. pattern_size : (cols, rows). ring_image : (H, W)
    float32, smoothed (σ = 1 px). True when one corner is both :func:`occluded_corners` and
    :func:`~aicalib_tf.detect.chessboard.rim.unlike_neighbours`.
    """
    cols, rows = (int(v) for v in pattern_size)
    if cols < 2 or rows < 2:
        return False
    points = np.asarray(corners, np.float64).reshape(rows, cols, 2)
    flagged = occluded_corners(points, ring_image)
    return bool(flagged.any() and (flagged & unlike_neighbours(points, ring_image)).any())


def object_in_front_at(region, size: tuple[int, int], corners: np.ndarray, pattern_size: tuple[int, int]) -> bool:
    """:func:`object_in_front` on an unsmoothed image, read about the board only.

    region : ``region(x0, y0, x1, y1)`` -> (y1 − y0, x1 − x0) float32 grey of pixels x0 … x1 − 1,
    y0 … y1 − 1 (:meth:`aicalib_tf.detect.pyramid.Frame.region`). size : (W, H) px. corners :
    (cols·rows, 2) px, OpenCV order. The board's bounding box is read with a margin that holds every
    ring (``RADIUS`` of the board's largest step, plus 8 px for the smoothing) and smoothed (Gaussian
    ``CROP_SIGMA`` px).
    """
    pts = np.asarray(corners, np.float64).reshape(-1, 2)
    w, h = size
    cols, rows = (int(v) for v in pattern_size)
    grid = pts.reshape(rows, cols, 2)
    step = max(np.linalg.norm(np.diff(grid, axis=a), axis=-1).max(initial=0.0) for a in (0, 1))
    pad = 8 + int(np.ceil(RADIUS * step))
    x0, y0 = (max(0, int(np.floor(v)) - pad) for v in pts.min(axis=0))
    x1, y1 = min(w, int(np.ceil(pts[:, 0].max())) + pad + 1), min(h, int(np.ceil(pts[:, 1].max())) + pad + 1)
    if x1 - x0 < 2 or y1 - y0 < 2:
        return False
    crop = cv2.GaussianBlur(np.asarray(region(x0, y0, x1, y1), np.float32), (0, 0), CROP_SIGMA)
    return object_in_front(pts - [x0, y0], pattern_size, crop)
