"""Where the views' corners fall in the image: cell counts, uncovered regions, the image circle's rim.

The calibration report, its verdict (:mod:`aicalib_tf.calib.quality`), the guided loop's guidance
and the live page's coverage map all count corners per image cell here. With a circular
fisheye's image circle (:mod:`aicalib_tf.geometry.image_circle`), a region wholly outside it is not
"uncovered" (no board can reach it); the circle's rim is checked by sectors instead. Pure numpy.
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.calib.diff import cell_counts, grid_points

__all__ = ["coverage_counts", "covered_mask", "in_circle", "rim_gaps", "uncovered_regions"]


def coverage_counts(views, image_size, cells=(16, 12)) -> np.ndarray:
    """(cells_y, cells_x) int64: how many detected corners of ``views`` fall in each image cell."""
    pts = np.concatenate([np.asarray(v.corners, np.float64).reshape(-1, 2) for v in views]) if len(views) else np.zeros((0, 2))
    return cell_counts(pts, image_size, cells)


_REGIONS = {"top-left": (0, 0), "top": (0, 1), "top-right": (0, 2), "left": (1, 0), "centre": (1, 1),
            "right": (1, 2), "bottom-left": (2, 0), "bottom": (2, 1), "bottom-right": (2, 2)}


def in_circle(image_size, grid, circle) -> np.ndarray:
    """(gy·gx,) bool over :func:`grid_points`: the cell centres inside the image ``circle`` (all True
    for None: the lens fills the frame)."""
    pts = grid_points(image_size, grid)
    return np.ones(len(pts), bool) if circle is None else circle.contains(pts)


def _reachable(image_size, circle, cells=(4, 4), min_share: float = 0.25) -> np.ndarray:
    """(cells_y, cells_x) bool: the cells of which at least ``min_share`` lies inside ``circle`` (a
    board can reach them; a cell the circle's edge only clips is left to :func:`rim_gaps`); all
    True without a circle."""
    cx, cy = (int(v) for v in cells)
    inside = in_circle(image_size, (16 * cx, 16 * cy), circle).reshape(16 * cy, 16 * cx)
    return inside.reshape(cy, 16, cx, 16).mean(axis=(1, 3)) >= min_share


def uncovered_regions(views, image_size, circle=None) -> list[str]:
    """Names of the image's nine regions (a 4 × 4 split: corners are the corner cells, "top" the two
    top middle cells, "centre" the middle four, ...) that no detected corner falls in; a region
    mostly outside the image ``circle`` (less than a quarter of each of its cells inside) does not count."""
    c = coverage_counts(views, image_size, (4, 4))
    reach = _reachable(image_size, circle)
    spans = (slice(0, 1), slice(1, 3), slice(3, 4))
    return [name for name, (r, k) in _REGIONS.items()
            if c[spans[r], spans[k]].sum() == 0 and reach[spans[r], spans[k]].any()]


_SECTORS = ("right", "bottom-right", "bottom", "bottom-left", "left", "top-left", "top", "top-right")  # y down


def rim_gaps(views, image_size, circle, rim: float = 0.8) -> list[str]:
    """Names of the eight 45° sectors of the image ``circle``'s rim (the ring from ``rim``·radius to the
    radius; "right" centred on +x, "bottom" on +y) that lie in the frame and hold no detected corner."""
    w, h = (int(v) for v in image_size)
    pts = np.concatenate([np.asarray(v.corners, np.float64).reshape(-1, 2) for v in views]) if len(views) else np.zeros((0, 2))
    d = np.hypot(pts[:, 0] - circle.cx, pts[:, 1] - circle.cy)
    sector = np.round(np.arctan2(pts[:, 1] - circle.cy, pts[:, 0] - circle.cx) / (np.pi / 4)).astype(int) % 8
    hit = set(sector[d >= rim * circle.radius].tolist())
    a = np.radians(np.arange(8) * 45.0)
    r = 0.5 * (1 + rim) * circle.radius  # a sector counts when the middle of its ring is in the frame
    mx, my = circle.cx + r * np.cos(a), circle.cy + r * np.sin(a)
    in_frame = (mx >= -0.5) & (mx <= w - 0.5) & (my >= -0.5) & (my <= h - 0.5)
    return [_SECTORS[k] for k in range(8) if in_frame[k] and k not in hit]


def covered_mask(views, image_size, grid) -> np.ndarray:
    """(M,) bool over :func:`grid_points`: the grid cells with at least one detected corner."""
    return coverage_counts(views, image_size, grid).ravel() > 0
