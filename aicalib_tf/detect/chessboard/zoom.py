"""A second look at a thin board: its region cut out and enlarged (pure numpy/OpenCV).

At the edge of a wide-angle lens a board's squares are squeezed to 2–4 px across; the CNN then
finds only some of their corners, and the grid it starts cannot be placed or completed. Enlarged
3× (bilinear), the same squares are 6–12 px across, in the network's range. So when the full-size
search gives no complete board but starts a grid of closely spaced corners, the region around
that grid is enlarged and searched again (:func:`aicalib_tf.detect.pipeline.detect_corners`). On evaluate's
``barrel`` images this finds 3 more full boards and 2 partial ones of 46–52 corners; it costs
about a second 640×480-sized search on the few images that ask for it (13 of the 2634).

Coordinates are (x, y) px, OpenCV's convention: the centre of pixel (0, 0) is at (0.0, 0.0). A
region ``box = (x0, y0, x1, y1)`` holds pixels x0 … x1 − 1 and y0 … y1 − 1; enlarged by f, pixel
centre x of the enlarged image lies at x0 + (x + 0.5) / f − 0.5 in the image (cv2.resize's
pixel-area alignment).
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from aicalib_tf.detect.chessboard.grid import MIN_CORNERS
from aicalib_tf.detect.corners.junctions import nearest_spacing
from aicalib_tf.detect.chessboard.lattice import predict_ids

__all__ = ["FACTOR", "MAX_SPACING", "zoom_box", "zoom_in", "from_zoom", "zoomed_look"]

FACTOR = 3  # enlargement: 2–4 px squares become 6–12 px
MAX_SPACING = 6.0  # px: a grid none of whose corners is nearer than this to another is not thin (no second look)
MARGIN = 10.0  # px around the region the board could cover: its outer squares and paper margin
PAD_STEPS = 2.0  # grid steps (median corner spacing) beyond the board's evidence: corners the CNN missed there
MAX_PIXELS = 240_000  # the enlarged region's most pixels (600×400): a larger region is not thin all over, and
# its search would cost more than a 640×480 image's


def zoom_box(ij: np.ndarray, points: np.ndarray, pattern_size: tuple[int, int],
             size: tuple[int, int], others: np.ndarray | None = None) -> tuple[int, int, int, int] | None:
    """The region to enlarge around a grid, or None when the grid is not thin.

    ij : (K, 2) int lattice positions of the grid's corners; points : (K, 2) px.
    pattern_size : (cols, rows). size : (width, height) px of the image. others : (M, 2) px or
    None, the image's other corner candidates.
    The grid may be any part of the board, so the board can lie wherever the grid's lattice (a
    homography of all its corners) puts positions up to ``max(cols, rows)`` steps in all on each
    axis, the grid's span included; that reach plus ``MARGIN`` px bounds the region. With
    ``others``, the region is narrowed to the grid and the candidates within that reach, plus
    ``PAD_STEPS`` steps and ``MARGIN`` px (homography extrapolation under a strong lens is only
    a bound: evaluate barrel #70's was 4 times the board's area). The region is clipped to the
    image. Returns (x0, y0, x1, y1) int, or None for fewer than ``MIN_CORNERS`` corners, no corner
    spacing (distance to the nearest corner) under ``MAX_SPACING``, or a region ``FACTOR``² times
    larger than ``MAX_PIXELS``.
    """
    ij = np.asarray(ij, np.int64).reshape(-1, 2)
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    if len(pts) < MIN_CORNERS or not nearest_spacing(pts).min() <= MAX_SPACING:
        return None
    w, h = size
    reach = max(pattern_size) - (ij.max(axis=0) - ij.min(axis=0) + 1)  # (2,) steps the board may extend
    lo, hi = ij.min(axis=0) - np.maximum(reach, 0), ij.max(axis=0) + np.maximum(reach, 0)
    edge = np.array([(i, j) for i in range(lo[0], hi[0] + 1) for j in (lo[1], hi[1])]
                    + [(i, j) for j in range(lo[1], hi[1] + 1) for i in (lo[0], hi[0])], np.float64)
    far = predict_ids(ij, pts, edge, k=len(ij))
    far = np.concatenate([pts, far[np.all(np.isfinite(far), axis=1)]])
    a, b = far.min(axis=0) - MARGIN, far.max(axis=0) + MARGIN
    if others is not None:  # the board's own evidence inside that reach: the grid and the candidates there
        o = np.asarray(others, np.float64).reshape(-1, 2)
        o = np.concatenate([pts, o[np.all((o >= a) & (o <= b), axis=1)]])
        pad = MARGIN + PAD_STEPS * float(np.median(nearest_spacing(pts)))
        a, b = np.maximum(a, o.min(axis=0) - pad), np.minimum(b, o.max(axis=0) + pad)
    a, b = np.maximum(a, 0.0), np.minimum(b, [w - 1.0, h - 1.0])
    x0, y0 = np.floor(a).astype(int)
    x1, y1 = np.ceil(b).astype(int) + 1
    if x1 - x0 < 8 or y1 - y0 < 8 or (x1 - x0) * (y1 - y0) * FACTOR**2 > MAX_PIXELS:
        return None
    return int(x0), int(y0), int(x1), int(y1)


def zoom_in(gray: np.ndarray, box: tuple[int, int, int, int], factor: int = FACTOR) -> np.ndarray:
    """The region ``box`` of gray (H, W) enlarged ``factor`` times (bilinear): float32 (f·h, f·w)."""
    x0, y0, x1, y1 = box
    crop = np.ascontiguousarray(gray[y0:y1, x0:x1], dtype=np.float32)
    return cv2.resize(crop, ((x1 - x0) * factor, (y1 - y0) * factor), interpolation=cv2.INTER_LINEAR)


def from_zoom(points: np.ndarray, box: tuple[int, int, int, int], factor: int = FACTOR) -> np.ndarray:
    """Points (N, 2) px on a :func:`zoom_in` image -> the same places on the image: (N, 2) float32."""
    f = float(factor)
    return ((np.asarray(points, np.float64) + 0.5) / f - 0.5 + np.array(box[:2], np.float64)).astype(np.float32)


def zoomed_look(gray: np.ndarray, pattern_size: tuple[int, int], seen, others: np.ndarray | None, search):
    """The search again on the region of a thin grid, enlarged ``FACTOR`` times.

    gray : (H, W) float32, full size. seen : the largest grid assembled on it (a
    :class:`~aicalib_tf.detect.chessboard.grid.Grid`). others : (M, 2) px, the corner candidates
    found on it (they narrow the region, :func:`zoom_box`), or None. search : ``search(image,
    partial_above=n) -> Detection`` (the detector's one-scale search; partial boards only looked
    for when the enlarged grid outgrows the one seen: the partial search is the costly part, and a
    grid no larger adds nothing). Returns the detection in gray's coordinates, or None when the grid
    is not thin, its region too large, or nothing is found there.
    """
    h, w = gray.shape
    box = zoom_box(seen.ij, seen.points, pattern_size, (w, h), others)
    if box is None:
        return None
    det = search(zoom_in(gray, box), partial_above=len(seen))
    if not det.found:
        return None
    return replace(det, corners=from_zoom(det.corners, box), image_size=(w, h))
