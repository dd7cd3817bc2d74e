"""Reading order of a full board, and of a placed partial board's symmetric readings.

Order of a full board (OpenCV's, row-major: index = r·cols + c). A board read from the front
keeps its handedness (:func:`handed`), so only its rotations are ambiguous: 180°, and 90° too for
a square pattern. They are resolved like ``cv2.findChessboardCorners`` (measured on data_gen
boards); see :mod:`aicalib_tf.detect.pipeline` for the rules. :func:`reading` applies them to a full board,
:func:`choose_reading` applies the geometric rule to a partial board's mean steps.
"""

from __future__ import annotations

import functools

import numpy as np

from aicalib_tf.detect.chessboard.grid import Grid
from aicalib_tf.detect.corners.sampling import sample_bilinear

__all__ = ["choose_reading", "full_board", "full_board_ids", "handed", "order_full_board", "reading", "symmetric_ids"]


def _parity_contrast(corners: np.ndarray, pattern_size: tuple[int, int], gray: np.ndarray) -> float:
    """Mean grey of the inner squares of odd parity minus that of even parity.

    corners : (cols·rows, 2) in a row-major reading. Inner square (c, r), between corners (c−1, r−1)
    and (c, r), has the colour of board square (c, r): black when c + r is even (the square
    outside corner 0 is black). So the reading that puts corner 0 at the black outer square gives
    a positive value. Every sampled square lies inside the board, hence inside the image.
    """
    cols, rows = pattern_size
    g = corners.reshape(rows, cols, 2)
    centres = 0.25 * (g[:-1, :-1] + g[1:, :-1] + g[:-1, 1:] + g[1:, 1:])  # (rows-1, cols-1, 2)
    return float(sample_bilinear(gray, centres.reshape(-1, 2)) @ _parity_weights(cols, rows))


@functools.lru_cache(maxsize=32)
def _parity_weights(cols: int, rows: int) -> np.ndarray:
    """((rows−1)·(cols−1),) float32, row-major over the inner squares (c, r), c, r ≥ 1: 1/n_odd where
    c + r is odd, −1/n_even where even, so that a dot product is the two means' difference (read-only)."""
    rr, cc = np.meshgrid(np.arange(1, rows), np.arange(1, cols), indexing="ij")
    even = ((rr + cc) % 2 == 0).ravel()
    weights = np.where(even, -1.0 / max(even.sum(), 1), 1.0 / max((~even).sum(), 1)).astype(np.float32)
    weights.flags.writeable = False
    return weights


def order_full_board(corners: np.ndarray, pattern_size: tuple[int, int], gray: np.ndarray) -> np.ndarray:
    """Reorder a full board's corners (any admissible reading) by the module's rule.

    corners : (cols·rows, 2) in some row-major reading of the board with the right handedness.
    Returns the (cols·rows, 2) corners in the rule's order.
    """
    return corners[reading(corners, pattern_size, gray)]


def reading(corners: np.ndarray, pattern_size: tuple[int, int], gray: np.ndarray) -> np.ndarray:
    """The board symmetry (a (cols·rows,) index permutation) that puts ``corners`` in the rule's order."""
    from aicalib_tf.geometry.pattern import board_symmetries

    cols, rows = pattern_size
    perms = board_symmetries(pattern_size)
    if (cols + rows) % 2 == 1:
        # the colour rule: turned by 180°, every inner square's parity flips and the contrast changes
        # sign, so the given reading's contrast decides (the turned one wins only where it is negative)
        return perms[1] if _parity_contrast(corners, pattern_size, gray) < 0 else perms[0]
    best, best_key = None, None
    for perm in perms:
        c = corners[perm]
        dy = c[(rows - 1) * cols, 1] - c[0, 1]
        dx = c[cols - 1, 0] - c[0, 0]
        key = (float(dx + dy), 0.0) if cols == rows else (float(dy), float(dx))
        if best_key is None or key > best_key:
            best, best_key = perm, key
    return best


def handed(grid_ij: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Flip j if needed so that the i and j directions have the image's handedness (x right, y down).

    A board seen from the front keeps its handedness, so the board's (col, row) axes must too.
    grid_ij : (K, 2) int. pts : (K, 2) px. Returns (K, 2) int.
    """
    u, v = _steps(grid_ij, pts)
    if u[0] * v[1] - u[1] * v[0] < 0:
        return np.stack([grid_ij[:, 0], grid_ij[:, 1].max() - grid_ij[:, 1]], 1)
    return grid_ij


def full_board(grid: Grid, scores: np.ndarray, pattern_size: tuple[int, int] | None, gray: np.ndarray):
    """A grid as a full board of ``pattern_size`` (None: the grid's own size), in the rule's order.

    scores : (N,) weights of the candidate points that ``grid.index`` refers to. gray : (H, W)
    float32, smoothed, for the colour rule. Returns (corners (cols·rows, 2) float32, ids
    (cols·rows, 2) int32, scores (cols·rows,) float32, (cols, rows)), or None when the grid is
    not a full board of that size (a bigger board is never cut to size).
    """
    ij = handed(grid.ij, grid.points)
    a, b = grid.shape
    if pattern_size is None:
        # the grid's own size, columns counted along the grid direction nearer the image's x axis
        u, v = _steps(ij, grid.points)
        cols, rows = (b, a) if abs(v[0]) * np.hypot(*u) > abs(u[0]) * np.hypot(*v) else (a, b)
    else:
        cols, rows = pattern_size
    if (a, b) == (rows, cols) and a != b:
        # the grid's i runs along the board's rows: swap roles, keeping handedness
        ij = np.stack([ij[:, 1], ij[:, 0]], 1)
        ij = np.stack([ij[:, 0], ij[:, 1].max() - ij[:, 1]], 1)
        a, b = b, a
    if (a, b) != (cols, rows):
        return None  # a different (e.g. bigger) board, or a partial one: never cut to size
    full = len(grid) == cols * rows
    if not full:
        return None
    corners = np.zeros((cols * rows, 2), np.float32)
    sc = np.zeros(cols * rows, np.float32)
    idx = ij[:, 1] * cols + ij[:, 0]
    corners[idx] = grid.points
    sc[idx] = np.where(grid.index >= 0, scores[grid.index], 0.0)
    perm = reading(corners, (cols, rows), gray)
    return corners[perm], full_board_ids((cols, rows)), sc[perm], (cols, rows)


def full_board_ids(pattern_size) -> np.ndarray:
    """(cols·rows, 2) int32 (col, row) of every corner of a full board, in OpenCV order (r·cols + c):
    a new array each call."""
    return _board_ids(*(int(v) for v in pattern_size)).copy()


@functools.lru_cache(maxsize=32)
def _board_ids(cols: int, rows: int) -> np.ndarray:
    return np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), -1).reshape(-1, 2).astype(np.int32)


def _steps(ids: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean image displacement (px) per +1 column and per +1 row, by an affine fit.

    ids : (N, 2) (col, row); pts : (N, 2) px. The least-squares fit's normal equations about the
    means, solved in closed form (2×2); ids on one line leave it undetermined, then the
    minimum-norm solution (``lstsq``).
    """
    a = ids.astype(np.float64)
    a -= a.mean(axis=0)
    p = pts.astype(np.float64)
    p -= p.mean(axis=0)
    (sxx, sxy), (_, syy) = (a.T @ a).tolist()
    det = sxx * syy - sxy * sxy
    if not det > 1e-9 * max(sxx * syy, 1e-300):
        (u, v), *_ = np.linalg.lstsq(a, p, rcond=None)
        return u, v
    b = a.T @ p  # (2, 2): rows the ids' axes
    return (syy * b[0] - sxy * b[1]) / det, (sxx * b[1] - sxy * b[0]) / det


def choose_reading(ids: np.ndarray, pts: np.ndarray, pattern_size) -> np.ndarray:
    """Of the symmetric readings of a placement, the one the full-board geometric rule prefers.

    Only used when colours cannot tell them apart (cols + rows even): the reading whose rows run
    most nearly downwards (largest y step per row; then x step per column); for square patterns,
    the largest x step per column + y step per row.
    """
    cols, rows = pattern_size

    def key(f):
        u, v = _steps(f, pts)
        return (float(u[0] + v[1]), 0.0) if cols == rows else (float(v[1]), float(u[0]))

    return max(symmetric_ids(ids, pattern_size), key=key)


def symmetric_ids(ids: np.ndarray, pattern_size) -> list[np.ndarray]:
    """The (col, row) ids (N, 2) under each board symmetry: identity, 180° (and 90°, 270° if square)."""
    cols, rows = pattern_size
    c, r = ids[:, 0], ids[:, 1]
    forms = [np.stack([c, r], 1), np.stack([cols - 1 - c, rows - 1 - r], 1)]
    if cols == rows:
        forms += [np.stack([rows - 1 - r, c], 1), np.stack([r, cols - 1 - c], 1)]
    return forms
