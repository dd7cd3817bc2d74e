"""Corners of a full board off the smooth grid of their neighbours: the interpolation test.

Any lens maps the board's plane smoothly, so along each of its lines a board's corners follow a
smooth curve: a corner is interpolated from four others on its line (two on each side, or one on
one side and three on the other: a cubic in the id, ``STENCILS``). On the true corners of
close-ups near a fisheye's image circle the interpolation misses by under 0.06 of the corner's
smallest step (the lens's own bend, squares up to 60 px), elsewhere by far less. A point on an
object's edge taken for a hidden corner, or a corner pulled by that edge, lies 2–5 px off those
curves while its four squares may still alternate as a corner's do.

Every interpolation (a row of ``C``: −1 at its target corner, the stencil's weights at the four it
is interpolated from) leaves a residual r = C·p (px). One corner k off by e moves every residual
by C[:, k]·e: its own interpolations by −e, those it serves in by its weight times e. Weighting
each residual by its expected spread (the corners' σ of :mod:`aicalib_tf.detect.corners.sigma`,
with a share of the step for the lens's bend: ``MODEL_SHARE``, or more on a board whose
interpolations all miss by more, :func:`bend_share`, or where it is more, the least of ``NEAR_BEND``
times the share by which the same interpolation misses on each of the two parallel lines either side
(:func:`beside`: the bend grows towards a fisheye's rim, its share of the step 1.4-1.7× a line on a
203° lens's outer rows; the least of four, so that an object over two lines does not hide its own
corners), the offset that best explains them is
ê_k = C_k·r / C_k·C_k (weighted), and its significance z_k = |C_k·r| / √(C_k·C_k). The corner of
the largest z is off the grid when z ≥ ``Z_MIN``, |ê| ≥ ``MIN_PX`` and |ê| ≥ ``MIN_SHARE`` of its
smallest step (a corner of high z but a smaller offset ends the search: a board bent beyond its
interpolations' reach); it is set aside (its interpolations with it) and the test repeated. A
neighbour of an off corner, interpolated through it, is not taken for it: the off corner explains
every residual it touches, the neighbour only its own. Next to an object, a corner may be left
with no interpolation (a board corner is never interpolated), or only across the gap (``GAPPED``,
weights up to 2.25): such a corner is set aside too when one of its 8 neighbours on the grid is (none
left) or two are (only across the gap).

:func:`without_off_grid` turns a full board with such corners into a partial board without them
(at most ``MAX_OFF``; a board with more is no board).
"""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import numpy as np

from aicalib_tf.detect.chessboard.rim import grid_directions

__all__ = ["STENCILS", "interpolations", "off_grid", "without_off_grid", "Z_MIN", "MIN_PX", "MIN_SHARE", "MAX_OFF",
           "bend_share", "beside", "LINES", "NEAR_BEND"]

# along a line, offsets from the target and weights: exact for a cubic in the id
STENCILS = (
    ((-2, -1, 1, 2), (-1 / 6, 4 / 6, 4 / 6, -1 / 6)),  # centred: 2 corners on each side
    ((-1, 1, 2, 3), (0.25, 1.5, -1.0, 0.25)),  # second corner of a line
    ((1, -1, -2, -3), (0.25, 1.5, -1.0, 0.25)),  # second-last
)
# where a neighbour or two of the target on its line are set aside: four others within 4 of it, one at least
# on each side (and their mirror images); used for a target that has none of ``STENCILS`` left
_GAPPED = ((-3, -2, -1, 2), (-2, -1, 2, 3), (-1, 2, 3, 4), (-3, -2, 1, 2), (-3, -1, 1, 2), (-2, -1, 1, 3),
           (-3, 1, 2, 3), (-4, -3, 1, 2))
GAPPED = _GAPPED + tuple(tuple(-o for o in offs) for offs in _GAPPED)
MODEL_SHARE = 0.01  # of the target's smallest step: an interpolation's least expected miss from the lens's bend
BEND_MEDIAN = 1.5  # times the board's median miss over its step: the expected miss on a board bent beyond the least
SIGMA_FLOOR = 0.05  # px: the least σ a corner is taken to have
Z_MIN = 5.0  # an off corner's offset over its standard error: the least
MIN_PX = 1.5  # px: the least offset taken as off the grid (a wrong corner is over 2 px off)
MIN_SHARE = 0.1  # of the corner's smallest step: the least offset (the lens's bend misses by up to 0.06)
MAX_OFF = 3  # corners off the grid a board may lose; with more it is no board
LINES = (-2, -1, 1, 2)  # the parallel lines an interpolation's twins lie on (lines across)
NEAR_BEND = (2.0, 1.5, 1.5, 2.0)  # times each twin's miss share (1.4-1.7x a line at a rim): the least is the expected


def cubic_weights(offs) -> tuple[float, ...]:
    """The weights that interpolate a cubic at 0 from its values at the four ``offs``."""
    return tuple(float(np.prod([-b / (a - b) for b in offs if b != a])) for a in offs)


def interpolations(rows: int, cols: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every interpolation of a full rows × cols grid along its lines.

    Returns at (S, 5) int, each interpolation's target and its four corners (row-major positions);
    weights (S, 5) float64, −1 for the target and the form's weights; and gapped (S,) bool, the
    interpolations of ``GAPPED`` offsets (the others are ``STENCILS``').
    """
    r, c = (v.ravel() for v in np.mgrid[:rows, :cols])
    forms = [(offs, wts, False) for offs, wts in STENCILS] + [(offs, cubic_weights(offs), True) for offs in GAPPED]
    at, weights, gapped = [], [], []
    for dr, dc in ((0, 1), (1, 0)):
        for offs, wts, gap in forms:
            o = np.array((0,) + tuple(offs))
            rr, cc = r[:, None] + o * dr, c[:, None] + o * dc  # (rows·cols, 5)
            inside = ((rr >= 0) & (rr < rows) & (cc >= 0) & (cc < cols)).all(axis=1)
            at.append((rr * cols + cc)[inside])
            weights.append(np.tile((-1.0,) + tuple(wts), (int(inside.sum()), 1)))
            gapped.append(np.full(int(inside.sum()), gap))
    return np.concatenate(at), np.concatenate(weights), np.concatenate(gapped)


@lru_cache(maxsize=8)
def _interpolations(rows: int, cols: int):
    at, weights, gapped = interpolations(rows, cols)
    return at, weights, gapped, beside(at, rows, cols)


def beside(at: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """(S, 4) int: for each interpolation ``at`` (S, 5) of :func:`interpolations` (row-major positions on a
    rows × cols grid), the same one on the parallel lines ``LINES`` across from it (every position moved that
    many lines across), or -1 where that line is off the grid. The lens bends neighbouring lines alike; a
    corner off the grid moves none of its own line's interpolations' twins."""
    r, c = np.divmod(at, cols)
    along_row = (r == r[:, :1]).all(axis=1)
    index = {tuple(row): k for k, row in enumerate(at.tolist())}
    out = np.full((len(at), len(LINES)), -1, np.int64)
    for side, d in enumerate(LINES):
        rr, cc = np.where(along_row[:, None], r + d, r), np.where(along_row[:, None], c, c + d)
        inside = ((rr >= 0) & (rr < rows) & (cc >= 0) & (cc < cols)).all(axis=1)
        moved = (rr * cols + cc).tolist()
        out[:, side] = [index.get(tuple(m), -1) if ok else -1 for m, ok in zip(moved, inside)]
    return out


def smallest_steps(points: np.ndarray) -> np.ndarray:
    """(rows·cols,) px: each corner's distance to its nearest neighbour along a grid line; points (rows, cols, 2),
    rows and cols ≥ 2 (:func:`~aicalib_tf.detect.chessboard.rim.grid_directions`' four steps)."""
    return np.hypot(*np.moveaxis(grid_directions(points), -1, 0)).min(axis=0).ravel()


def bend_share(flat: np.ndarray, steps: np.ndarray, at: np.ndarray, w: np.ndarray) -> float:
    """The expected interpolation miss over the target's smallest step on this board: ``MODEL_SHARE``, or
    ``BEND_MEDIAN`` times the median miss of the interpolations ``at``, ``w`` (rows of :func:`interpolations`)
    when that is more. flat : (N, 2) px; steps : (N,) px (:func:`smallest_steps`). One corner off moves
    a few of a board's interpolations, its lens's bend all of them: a real 185° fisheye's close board, its
    steps 39-150 px across, missed by a median 0.039 of the step, and up to 8 px."""
    miss = np.hypot(*np.einsum("sj,sjd->sd", w, flat[at]).T) / steps[at[:, 0]]
    return max(MODEL_SHARE, BEND_MEDIAN * float(np.median(miss))) if len(miss) else MODEL_SHARE


def off_grid(points: np.ndarray, sigmas: np.ndarray | None) -> np.ndarray | None:
    """(rows, cols) bool: the corners of a full grid off the smooth grid of their neighbours, and
    those beside them (of their 8 neighbours on the grid) that no interpolation is left to test;
    None when more than ``MAX_OFF`` are off (the search stops there).

    points : (rows, cols, 2) px, every position filled. sigmas : (rows, cols) px, each corner's σ
    (None: ``SIGMA_FLOOR``).
    """
    rows, cols = points.shape[:2]
    flat = np.asarray(points, np.float64).reshape(-1, 2)
    sig = np.full(len(flat), SIGMA_FLOOR) if sigmas is None else np.maximum(np.ravel(sigmas), SIGMA_FLOOR)
    steps = smallest_steps(np.asarray(points, np.float64))
    at_all, w_all, gapped, twins = _interpolations(rows, cols)
    share = bend_share(flat, steps, at_all[~gapped], w_all[~gapped])
    miss = np.hypot(*np.einsum("sj,sjd->sd", w_all, flat[at_all]).T) / steps[at_all[:, 0]]  # (S,) of the step
    n = len(flat)
    off = np.zeros(n, bool)
    plain, tested = np.zeros(n, bool), np.zeros(n, bool)
    while True:
        if off.sum() > MAX_OFF:
            return None
        keep = ~off[at_all].any(axis=1)
        plain = np.zeros(n, bool)  # the corners a form of STENCILS still interpolates
        plain[at_all[keep & ~gapped, 0]] = True
        keep &= ~gapped | ~plain[at_all[:, 0]]  # a gapped interpolation only where no other is left
        at, w = at_all[keep], w_all[keep]
        tested = np.zeros(n, bool)
        tested[at[:, 0]] = True
        if len(at) == 0:
            break
        clear = (twins >= 0) & ~off[at_all[np.maximum(twins, 0)]].any(axis=2)  # twins touching no corner set aside
        near = np.where(clear, np.asarray(NEAR_BEND) * miss[np.maximum(twins, 0)], np.inf).min(axis=1)[keep]  # (S,)
        bend = np.maximum(share, np.where(np.isfinite(near), near, 0.0)) * steps[at[:, 0]]
        spread = np.sqrt(((w * sig[at]) ** 2).sum(axis=1) + bend ** 2)  # (S,) px
        ww = w / spread[:, None]
        res = np.einsum("sj,sjd->sd", w, flat[at]) / spread[:, None]  # (S, 2): each residual, weighted
        served = np.stack([np.bincount(at.ravel(), (ww * res[:, d, None]).ravel(), n) for d in (0, 1)], 1)  # C_k·r
        norm = np.bincount(at.ravel(), (ww ** 2).ravel(), n)  # C_k·C_k, weighted
        z = np.zeros(n)
        tested &= norm > 0
        z[tested] = np.hypot(*served[tested].T) / np.sqrt(norm[tested])
        k = int(np.argmax(z))
        offset = float(np.hypot(*served[k])) / norm[k] if tested[k] else 0.0
        if z[k] < Z_MIN or offset < max(MIN_PX, MIN_SHARE * steps[k]):
            break
        off[k] = True
    off = off.reshape(rows, cols)
    pad = np.pad(off, 1)
    near = np.sum([pad[1 + di:rows + 1 + di, 1 + dj:cols + 1 + dj] for di in (-1, 0, 1) for dj in (-1, 0, 1)], axis=0)
    untested, gapped_only = (~v.reshape(rows, cols) for v in (tested, plain))
    return off | (untested & (near >= 1)) | (gapped_only & (near >= 2))


def without_off_grid(det, refused: str):
    """A complete detection (:class:`~aicalib_tf.detect.detection.Detection`, its corners in OpenCV order)
    without its corners :func:`off_grid`: as it is when none is, a partial board (complete False)
    without them (and the corners beside them left untested, :func:`off_grid`) when at most
    ``MAX_OFF`` are, and no board (no corners, reason ``refused``) with more."""
    if not det.complete or det.pattern_size is None:
        return det
    cols, rows = det.pattern_size
    sig = None if det.sigmas is None else np.asarray(det.sigmas).reshape(rows, cols)
    off = off_grid(np.asarray(det.corners, np.float64).reshape(rows, cols, 2), sig)
    if off is not None and not off.any():
        return det
    keep = np.zeros(len(det.corners), bool) if off is None else ~off.ravel()
    return replace(det, corners=det.corners[keep], ids=det.ids[keep], scores=det.scores[keep], complete=False,
                   sigmas=None if det.sigmas is None else det.sigmas[keep], reason="" if keep.any() else refused)
