"""The chessboard corners of a ChArUco board: CNN points -> saddle refinement -> grids of corners.

The stages are the chessboard pipeline's (:mod:`aicalib_tf.cnn.inference`, :mod:`aicalib_tf.detect.corners.refine`,
:mod:`aicalib_tf.detect.chessboard.grid`), with three changes that the markers ask for:

* the network also fires on the X-junctions between a marker's own bits; its points inside a
  marker that OpenCV reads (the marker's quad enlarged by :data:`MARKER_GROW`, which takes in the
  junctions of its outline) are dropped before anything else;
* the refinement window must stay in the white margin between a board corner and the markers
  beside it: its half-size is 0.8 of that margin, from the size of the nearest read marker (2 px
  at least, 5 at most; 2 px again where that fit fails), or from the spacing of the points where
  no marker is read;
* a window is never point-symmetric (the two markers beside a corner differ), so the fit that
  allows a shadow edge is not asked: the saddle stands.

Grids are assembled as for chessboards and corners off their neighbours' lattice dropped.
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.detect.chessboard.grid import MIN_CORNERS, assemble_grids
from aicalib_tf.detect.corners.junctions import dedupe, nearest_spacing, proposer, typical_amplitude
from aicalib_tf.detect.chessboard.lattice import drop_outliers
from aicalib_tf.detect.corners.refine import Smoothed, refine_windowed
from aicalib_tf.geometry.points import BLOCK, nearest_index

__all__ = ["MARKER_GROW", "outside_markers", "corner_candidates", "lattices"]

MARKER_GROW = 1.15
MAX_CANDIDATES = 3000


def outside_markers(points: np.ndarray, marker_corners: np.ndarray, grow: float = MARKER_GROW) -> np.ndarray:
    """(N,) bool: points (N, 2) px outside every marker (corners (M, 4, 2) px, each scaled by
    ``grow`` about its centre; a point on an outline is inside). A marker's bits make X-junctions of
    their own; none is a board corner. The outlines are convex: a point is inside when it lies on
    the same side of all four sides."""
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    quads = np.asarray(marker_corners, np.float64).reshape(-1, 4, 2)
    if not len(quads) or not len(pts):
        return np.ones(len(pts), bool)
    c = quads.mean(axis=1, keepdims=True)
    q = c + grow * (quads - c)  # (M, 4, 2)
    side = np.roll(q, -1, axis=1) - q
    out = np.ones(len(pts), bool)
    step = max(1, BLOCK // (8 * len(pts)))  # markers at a time: memory bounded whatever M is
    for m in range(0, len(q), step):
        rel = pts[None, None] - q[m:m + step, :, None]  # (step, 4, N, 2)
        cross = side[m:m + step, :, None, 0] * rel[..., 1] - side[m:m + step, :, None, 1] * rel[..., 0]
        out &= ~((cross >= 0).all(axis=1) | (cross <= 0).all(axis=1)).any(axis=0)
    return out


def _window_spacing(pts: np.ndarray, quads: np.ndarray, margin_ratio: float) -> np.ndarray:
    """(N,) px: the 'spacing' whose refinement window (0.45 of it) is the white margin beside each point.

    margin_ratio : (square − marker) / (2 · marker), the margin in marker sides.
    """
    spacing = nearest_spacing(pts).astype(np.float64)
    if len(quads):
        centres = quads.mean(axis=1)
        side = np.linalg.norm(np.diff(np.concatenate([quads, quads[:, :1]], axis=1), axis=1), axis=2).mean(axis=1)
        near = nearest_index(pts, centres)  # in row blocks: any number of markers
        spacing = np.maximum(side[near] * margin_ratio * 0.8, 2.0) / 0.45
    return spacing


def corner_candidates(model, gray: np.ndarray, threshold: float, quads: np.ndarray, margin_ratio: float,
                      smoothed: Smoothed) -> tuple[np.ndarray, np.ndarray]:
    """Refined corner candidates of a ChArUco image: (N, 2) float32 px and (N,) float32 weights.

    gray : (H, W) float32. quads : (M, 4, 2) px, the markers OpenCV read.
    """
    from aicalib_tf.cnn.inference import corner_points

    pts, scores = corner_points(model, gray, threshold)
    pts, scores = pts[:MAX_CANDIDATES], scores[:MAX_CANDIDATES]
    ok = outside_markers(pts, quads)
    pts, scores = pts[ok], scores[ok]
    if len(pts) < MIN_CORNERS:
        return np.zeros((0, 2), np.float32), np.zeros(0, np.float32)
    spacing = _window_spacing(pts.astype(np.float64), quads, margin_ratio)
    no_shadow = lambda idx, saddles: np.zeros(len(idx), bool)  # noqa: E731 - the saddle stands
    refined, ok = refine_windowed(smoothed, pts, spacing, max_shift=0.5 * spacing, shadow_gate=no_shadow)
    if (~ok).any():  # the smallest window (2 px) where the margin's failed
        small = np.full(int((~ok).sum()), 2.0 / 0.45)
        again, ok2 = refine_windowed(smoothed, pts[~ok], small, max_shift=0.5 * spacing[~ok], shadow_gate=no_shadow)
        refined[~ok], ok[~ok] = again, ok2
    ok &= outside_markers(refined, quads)
    refined, scores = refined[ok], scores[ok]
    keep = dedupe(refined, scores)
    return refined[keep].astype(np.float32), scores[keep].astype(np.float32)


def lattices(model, gray: np.ndarray, threshold: float, quads: np.ndarray, margin_ratio: float,
             limit: int, smoothed: Smoothed | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Every grid of ChArUco corners in gray (H, W) float32: [(lattice ids (N, 2) int64, pts (N, 2) px)].

    limit : the largest grid side to grow (one more than the board's). smoothed : gray's smoothed
    copies, when the caller shares them.
    """
    smoothed = Smoothed(gray) if smoothed is None else smoothed
    refined, scores = corner_candidates(model, gray, threshold, quads, margin_ratio, smoothed)
    if len(refined) < MIN_CORNERS:
        return []
    smooth = smoothed.sigma(1.0)
    propose = proposer(smoothed, smooth, typical_amplitude(smooth, refined, MIN_CORNERS))
    grids = assemble_grids(refined, scores, gray=smooth, propose=propose, limit=limit)
    if not grids:
        grids = assemble_grids(refined, scores, gray=smooth, limit=limit, strips=True)
    out = []
    for grid in grids:
        kept = drop_outliers(grid.ij, grid.points, grid.index)
        if kept is not None:
            out.append((np.asarray(kept[0], np.int64), np.asarray(kept[1], np.float64)))
    return out
