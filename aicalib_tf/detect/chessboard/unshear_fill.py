"""The last few corners of a steeply tilted board, placed on its unsheared view.

On an unsheared view (:mod:`aicalib_tf.detect.chessboard.unshear`) of a board tilted 60–80°, its far
squares were 1.5–3 px thick on the image: enlarged, they are blurred across, and the search there can
come back with all but a few of the board's corners, those few too blurred for the network and the
grid's own look-ups. When the found corners span the whole pattern (``cols`` × ``rows`` lattice
positions, either way round) and at most ``MAX_FILL`` of those positions are empty, each empty one is
predicted by the homography of the ``NEAREST`` found corners nearest it on the lattice (a planar board:
over a few squares even a strong lens leaves it nearly projective); where those corners are more than
``MAX_RESIDUAL`` of a step off that homography the lens bends the board too much there, and the board is
left incomplete (a strong barrel lens put a far corner 2 px off, the board wrong, with the whole board's
homography). Each must
show a junction there (its chequer contrast at least ``MIN_CONTRAST`` of the found corners' median; one
that does not leaves the board incomplete); it is moved by a saddle fit where one lands within
``MAX_SHIFT`` px of the prediction, else kept at the prediction (on the blurred far rows the fit mostly
fails: tilt-steep seeds 41 and 97 filled 4 boards, 12 of 14 positions from the prediction, every board
within 0.52 px of the truth after the board's refinement on its rectified view). The found corners span the pattern, so the ids are the pattern's up to
its symmetry, decided as for a full board (:func:`aicalib_tf.detect.chessboard.board_order.order_full_board`,
on the view, where the squares' colours can be read).

Coordinates are (x, y) px, pixel (0, 0) centred at (0.0, 0.0).
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from aicalib_tf.detect.chessboard.board_order import full_board_ids, handed, reading
from aicalib_tf.detect.corners.sampling import sample_bilinear

__all__ = ["MAX_FILL", "MAX_SHIFT", "NEAREST", "MAX_RESIDUAL", "pattern_indices", "filled_board", "local_guesses"]

MAX_FILL = 5  # empty lattice positions a board's found corners may leave and still be completed (under a tenth of 9×6)
MAX_SHIFT = 1.0  # px on the view (squares of unshear.STEP px): an empty position moves to its saddle this near
MIN_CONTRAST = 0.5  # of the found corners' median junction contrast: an empty position's least
NEAREST = 12  # found corners, nearest on the lattice, that predict an empty position
MAX_RESIDUAL = 0.1  # of the found corners' median step: the most a near corner may be off its local lattice


def pattern_indices(ids: np.ndarray, points: np.ndarray, pattern_size: tuple[int, int]) -> np.ndarray | None:
    """Row-major pattern indices (c + r·cols) of a grid that spans the pattern, or None.

    ids : (K, 2) int lattice positions of one grid (relative or placed); points : (K, 2) px, to read
    its handedness (:func:`~aicalib_tf.detect.chessboard.board_order.handed`: x right, y down kept).
    A grid spanning (rows, cols) positions is read turned by a quarter (handedness kept).
    Returns (K,) int64, or None when the span is not the pattern's or two ids coincide.
    """
    cols, rows = pattern_size
    ij = np.asarray(ids, np.int64).reshape(-1, 2)
    ij = handed(ij - ij.min(axis=0), np.asarray(points, np.float64).reshape(-1, 2))
    span = tuple(int(s) for s in ij.max(axis=0) + 1)
    if span == (cols, rows):
        c, r = ij[:, 0], ij[:, 1]
    elif span == (rows, cols):  # a quarter turn: (a, b) -> (b, rows - 1 - a)
        c, r = ij[:, 1], rows - 1 - ij[:, 0]
    else:
        return None
    idx = r * cols + c
    return idx if len(np.unique(idx)) == len(idx) else None


def junction_contrast(view: np.ndarray, lat: np.ndarray, ij: np.ndarray) -> np.ndarray:
    """The chequer contrast around lattice positions ij (M, 2) (col, row) on ``view`` (H, W) float32.

    lat : (3, 3) the lattice's homography, (col, row) -> view px. The four squares about a corner are
    sampled at their centres, (col ± ½, row ± ½) through lat; the value is the grey of the diagonal
    pair (+½, +½), (−½, −½) less that of the other pair, times (−1)^(col + row): of one sign (the
    board's colours decide which) and about twice the board's contrast on every corner of a chessboard. Returns (M,) float32.
    """
    ij = np.asarray(ij, np.float64).reshape(-1, 2)
    offsets = np.array([[0.5, 0.5], [-0.5, -0.5], [0.5, -0.5], [-0.5, 0.5]])
    at = (ij[:, None, :] + offsets[None]).reshape(-1, 1, 2)
    grey = sample_bilinear(view, cv2.perspectiveTransform(at, lat).reshape(-1, 2)).reshape(-1, 4)
    sign = 1.0 - 2.0 * (ij.sum(axis=1) % 2)
    return ((grey[:, 0] + grey[:, 1] - grey[:, 2] - grey[:, 3]) * sign).astype(np.float32)


def filled_board(det, pattern_size: tuple[int, int], view: np.ndarray, refine):
    """A full board from a partial one found on an unsheared view, its empty positions found again; or None.

    det : the search's detection on ``view`` (H, W) float32 (``ids`` (K, 2) int placed on the pattern,
    ``corners`` (K, 2) px on the view, ``scores`` (K,), ``relative``; a dataclass). refine :
    ``refine(view, points (M, 2), max_shift) -> (refined (M, 2), ok (M,) bool)``, a saddle fit
    (:func:`aicalib_tf.detect.pyramid.refine_full`). Returns ``det`` complete: corners (cols·rows, 2)
    float32 px on the view in the rule's order, the pattern's ids, scores 0 at the positions filled;
    or None when its ids are relative, the grid does not span the pattern, leaves more than
    ``MAX_FILL`` positions empty, or one of them shows no junction (``MIN_CONTRAST``). A filled position is the
    saddle fit's where ``refine`` succeeds, else the homography's prediction.
    """
    cols, rows = pattern_size
    n = cols * rows
    pts = np.asarray(det.corners, np.float64).reshape(-1, 2)
    idx = pattern_indices(det.ids, pts, pattern_size) if n - MAX_FILL <= len(pts) < n and not det.relative else None
    if idx is None:
        return None
    full_ij = full_board_ids(pattern_size).astype(np.float64)
    lat, _ = cv2.findHomography(full_ij[idx], pts, 0)
    if lat is None or not np.all(np.isfinite(lat)):
        return None
    empty = np.setdiff1d(np.arange(n), idx)
    seen = junction_contrast(view, lat, full_ij[idx])
    typical = float(np.median(seen))
    if typical == 0 or not np.all(junction_contrast(view, lat, full_ij[empty]) / typical >= MIN_CONTRAST):
        return None
    guess = local_guesses(full_ij[idx], pts, full_ij[empty])
    if guess is None:
        return None
    found, ok = refine(view, guess, MAX_SHIFT)
    corners, scores = np.zeros((n, 2), np.float32), np.zeros(n, np.float32)
    corners[idx], scores[idx] = pts, np.asarray(det.scores, np.float32).reshape(-1)
    corners[empty] = np.where(np.asarray(ok)[:, None], found, guess)
    perm = reading(corners, pattern_size, view)
    return replace(det, corners=corners[perm], ids=full_board_ids(pattern_size), scores=scores[perm], complete=True,
                   reason="")


def local_guesses(ij: np.ndarray, pts: np.ndarray, empty: np.ndarray) -> np.ndarray | None:
    """Where the empty lattice positions ``empty`` (M, 2) lie: (M, 2) float32 px, or None when one cannot be trusted.

    ij (K, 2) lattice positions and pts (K, 2) px of the found corners. Each empty position is predicted by the
    homography of the ``NEAREST`` found corners nearest it on the lattice (a board bent by the lens is nearly
    projective over a few squares, not over the whole view); None when they do not span 2 steps both ways, or
    when one of them is further than ``MAX_RESIDUAL`` of the median step off that local lattice (the lens bends
    the board even there).
    """
    ij, pts = np.asarray(ij, np.float64), np.asarray(pts, np.float64)
    step = float(np.median(np.linalg.norm(pts[:, None] - pts[None], axis=2)[
        np.abs(ij[:, None] - ij[None]).sum(axis=2) == 1]))
    out = np.zeros((len(empty), 2), np.float32)
    for k, target in enumerate(np.asarray(empty, np.float64).reshape(-1, 2)):
        d = ij - target
        near = np.lexsort((np.hypot(d[:, 0], d[:, 1]), np.abs(d).max(axis=1)))[:NEAREST]
        if len(near) < 6 or min(np.ptp(ij[near], axis=0)) < 2:
            return None
        lat, _ = cv2.findHomography(ij[near], pts[near], 0)
        if lat is None or not np.all(np.isfinite(lat)):
            return None
        fit = cv2.perspectiveTransform(ij[near].reshape(-1, 1, 2), lat).reshape(-1, 2)
        if np.linalg.norm(fit - pts[near], axis=1).max() > MAX_RESIDUAL * step:
            return None
        out[k] = cv2.perspectiveTransform(target.reshape(1, 1, 2), lat).reshape(2)
    return out
