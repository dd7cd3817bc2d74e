"""Which views a calibration may use: the checks made before any fit.

A view is refused, with its reason, when its corners cannot constrain a camera: too few, ids off
the pattern or repeated, corners on one line (in board ids or in the image), non-finite, or
outside the image. A view whose corners repeat an earlier view's (the same ids, every corner
within :data:`DUPLICATE_PX`) counts once: 13 copies of one photo are one view, not thirteen, and
must not make the fit look thirteen times as sure.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MIN_VIEW_CORNERS", "DUPLICATE_PX", "view_problem", "duplicates"]

MIN_VIEW_CORNERS = 6  # and spanning ≥ 2 rows and ≥ 2 columns: a homography needs a 2-D spread
DUPLICATE_PX = 1.0  # two views whose corners all lie within this distance (px) are one view
MIN_SPREAD_PX = 1.0  # corners whose spread across their main line is below this (px) are on one line
MIN_SPREAD_RATIO = 0.01  # ... or whose spread across is below this fraction of the spread along
OUTSIDE_MARGIN_PX = 1.0  # how far past the image border (px) a corner may lie before the view is refused


def view_problem(corners: np.ndarray, ids: np.ndarray, pattern_size: tuple[int, int],
                 image_size: tuple[int, int] | None = None) -> str | None:
    """Why a view cannot be used, or None.

    corners : (N, 2) float64 (x, y) px. ids : (N, 2) int (col, row). pattern_size : (cols, rows).
    image_size : (width, height) px, to refuse corners outside the image (None: not checked).
    """
    cols, rows = pattern_size
    if len(ids) < MIN_VIEW_CORNERS:
        return f"only {len(ids)} corners (need {MIN_VIEW_CORNERS})"
    if (ids < 0).any() or (ids[:, 0] >= cols).any() or (ids[:, 1] >= rows).any():
        return f"corner ids outside the {cols}x{rows} pattern"
    if len(np.unique(ids, axis=0)) != len(ids):
        return "duplicate corner ids"
    if len(np.unique(ids[:, 0])) < 2 or len(np.unique(ids[:, 1])) < 2:
        return "corners on a single line"
    if not np.isfinite(corners).all():
        return "non-finite corner coordinates"
    centred = corners - corners.mean(axis=0)
    along, across = np.linalg.svd(centred, compute_uv=False) / np.sqrt(len(corners))
    if across < MIN_SPREAD_PX or across < MIN_SPREAD_RATIO * along:
        return f"corners (nearly) on one line in the image (spread {across:.2g} px across it)"
    if image_size is not None:
        w, h = image_size
        lo, hi = -0.5 - OUTSIDE_MARGIN_PX, np.array([w, h], np.float64) - 0.5 + OUTSIDE_MARGIN_PX
        out = np.any((corners < lo) | (corners > hi), axis=1)
        if out.any():
            return f"{int(out.sum())} corners outside the {w}x{h} image"
    return None


def duplicates(views) -> dict[str, str]:
    """{name: name of the earlier view it repeats} for views that repeat an earlier one.

    views : objects with ``name``, ``corners`` (N, 2) px and ``ids`` (N, 2), in order. Two views
    repeat each other when they have the same ids and every corner moved less than
    :data:`DUPLICATE_PX`.
    """
    kept: dict[bytes, list] = {}
    out: dict[str, str] = {}
    for v in views:
        order = np.lexsort((v.ids[:, 0], v.ids[:, 1]))
        key = np.ascontiguousarray(v.ids[order]).tobytes()
        corners = v.corners[order]
        for name, other in kept.get(key, []):
            if np.max(np.linalg.norm(corners - other, axis=1)) < DUPLICATE_PX:
                out[v.name] = name
                break
        else:
            kept.setdefault(key, []).append((v.name, corners))
    return out
