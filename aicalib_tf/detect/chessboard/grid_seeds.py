"""Grid seeds: a point and its near neighbours -> the 3×3 (or 3×2) block of a lattice, or None.

:func:`place_seed` tries pairs of steps along square edges (told from diagonals by
:func:`edge_contrast`, worked out lazily by :class:`SeedContrast`) and takes the block the compiled
search :func:`~aicalib_tf.detect.chessboard.grid_kernels.seed_block` finds;
:func:`place_bent_seed` seeds blocks that are no parallelogram, beside a fisheye's centre. The grid
then grows from the seed (:mod:`aicalib_tf.detect.chessboard.grid_growth`).
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.detect.chessboard.grid_growth import TOLERANCE, GrowingGrid
from aicalib_tf.detect.chessboard.grid_kernels import edge_contrasts, seed_block

__all__ = ["SeedContrast", "double_step", "edge_contrast", "place_bent_seed", "place_seed"]

MAX_STEP_RATIO = 4.5  # a seed's two steps may differ in length this much (a board tilted 60°+ halves one)
MAX_CELL_AREA = 1.5  # seed pairs spanning more than this of the smallest cell generate a sub-lattice
MAX_SPAN_RATIO = 1.15  # seed pairs longer than this times the shortest (|u| + |v|) are not tried
BENT_SEED_TOLERANCE = 0.45  # of the shorter step: a bent seed's opposite neighbours (see place_bent_seed)
BENT_CELL_AREA = 2.0  # MAX_CELL_AREA of bent seeds: beside a fisheye's centre, cells next to each other differ this much


def edge_contrast(gray: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """How strongly the segments p→q look like an edge between two squares.

    Between neighbouring corners along a grid line the board has a black square on one side and a
    white one on the other; along a diagonal both sides are the same square. Samples at 35%, 50%
    and 65% of the way, a quarter of the length to each side (a compiled loop,
    :func:`aicalib_tf.detect.chessboard.grid_kernels.edge_contrasts`).
    gray : (H, W) float32. p, q : (M, 2) px. Returns (M,) float32, |mean left − mean right|.
    """
    p = np.asarray(p, np.float64).reshape(-1, 2)
    q = np.asarray(q, np.float64).reshape(-1, 2)
    return edge_contrasts(np.asarray(gray, np.float32), p, q)


class SeedContrast:
    """:func:`edge_contrast` of each point's steps to its near points, worked out as seeds ask.

    A board's first seed usually grows the whole board, so the contrasts of the points it takes are
    never asked for: rows are computed for the point asked and the next free points in seed order,
    a batch twice as large each time (1, 2, 4, ...). Each row depends on its own point alone.
    gray : (H, W) float32. pts : (N, 2) px. near : (N, K) int. order : (N,) seed order. free : (N,) bool,
    the lattice's (read, not changed). ``row(k)`` : (K,) float64, seed_block's dtype.
    """

    def __init__(self, gray: np.ndarray, pts: np.ndarray, near: np.ndarray, order: np.ndarray, free: np.ndarray):
        self.gray, self.pts, self.near, self.order, self.free = gray, pts, near, order, free
        self.rows = np.full(near.shape, np.nan)
        self.done = np.zeros(len(pts), bool)
        self.rank = np.empty(len(order), int)
        self.rank[order] = np.arange(len(order))
        self.batch = 1

    def row(self, k: int) -> np.ndarray:
        if not self.done[k]:
            later = self.order[self.rank[k]:]
            ks = later[self.free[later] & ~self.done[later]][: self.batch]
            self.batch *= 2
            pairs = self.near[ks]
            got = edge_contrast(self.gray, np.repeat(self.pts[ks], pairs.shape[1], axis=0), self.pts[pairs.ravel()])
            self.rows[ks] = got.reshape(pairs.shape)
            self.done[ks] = True
        return self.rows[k]


_OFFS = np.array([(di, dj) for di in (-1, 0, 1) for dj in (-1, 0, 1) if (di, dj) != (0, 0)], np.float64)
# a 3×2 block about the middle of its long side, on either side of it (``strips`` seeds)
_STRIP_BLOCKS = np.array([[(di, dj) for di in (-1, 0, 1) for dj in (0, s) if (di, dj) != (0, 0)] for s in (1, -1)],
                         np.float64)
_NO_CONTRAST = np.zeros(0)  # seed_block's "no edge test"


def place_seed(lat: GrowingGrid, k: int, neighbours: np.ndarray, contrast: np.ndarray | None = None,
          strips: bool = False) -> bool:
    """Try to place a 3×3 lattice centred on point ``k``; True (and cells taken) on success.

    strips : place a 3×2 block instead, ``k`` in the middle of a long side (either step along it,
    the block on either side), for strips of a board 2 corners wide.

    Any two independent lattice steps generate the same points, so a diagonal step would give a
    sheared grid. With ``contrast`` (:func:`edge_contrast` of each step to a neighbour), only steps
    along square edges are used, and a step with a near point halfway along it (a double step) is
    not. Of the pairs of steps that are not nearly collinear, only these are tried, shortest
    (|u| + |v|) first:

    * pairs spanning a cell of at most ``MAX_CELL_AREA`` times the smallest pair's: a pair such as
      (row, row − 2·col) generates only every other point, its cell twice the board's;
    * pairs at most ``MAX_SPAN_RATIO`` times as long as the shortest such pair: of the pairs that
      generate the whole lattice, the board's own edges are the shortest once diagonals are out.
      A longer one such as (col, 2·col − row) is more orthogonal on a board tilted 60°, and it
      seeds where the board's own 3×3 is incomplete, as a sheared grid.

    A block that steps over a corner (:func:`double_step`) seeds nothing.
    """
    blocks, orders = (_OFFS[None], 1) if not strips else (_STRIP_BLOCKS, 2)
    b, _, _, found = seed_block(lat.pts, int(k), neighbours, _NO_CONTRAST if contrast is None else contrast, lat.free,
                                blocks, orders, TOLERANCE, MAX_STEP_RATIO, MAX_CELL_AREA, MAX_SPAN_RATIO)
    if b < 0:
        return False
    cells = {(0, 0): int(k), **{(di, dj): q for (di, dj), q in zip(blocks[b].astype(int).tolist(), found.tolist())}}
    if double_step(lat.pts, cells):
        return False
    for cell, q in cells.items():
        lat.take(cell, q)
    return True


def double_step(pts: np.ndarray, cells: dict) -> bool:
    """Whether a seed block steps over a corner: a point of ``pts`` (N, 2) px part-way (20–80%) along
    the step between two of its cells next to each other, off that step by under ``TOLERANCE`` of the
    point's own distance from the step's start (the test a seed's own steps pass, :func:`place_seed`).
    ``cells``: {(i, j): index into pts}.

    Neighbouring corners of a lattice have no corner between them. Where a board's squares shrink
    fast towards a fisheye's rim (steps 53, 36, then 22 px along a line), the parallelogram about a
    corner predicts its far neighbour one near step (36 px) on: the corner two steps on (at 44 px)
    lies within the tolerance, the one between (at 22 px) beyond it, and the block would seed a grid
    with a line missing, which then grows no further than half the board.
    """
    steps = np.array([(a, b) for (i, j), a in cells.items() for b in (cells.get((i + 1, j)), cells.get((i, j + 1)))
                      if b is not None])
    if len(steps) == 0:
        return False
    block = pts[np.array(list(cells.values()))]
    centre = block.mean(axis=0)
    # a point between two cells lies within 1.5 times the farthest cell's distance from the block's centre
    reach = 1.5**2 * float(((block - centre) ** 2).sum(axis=1).max())
    near = np.flatnonzero(((pts - centre) ** 2).sum(axis=1) <= reach)
    a = pts[steps[:, 0]]
    d = pts[steps[:, 1]] - a  # (E, 2): the block's steps
    l2 = (d * d).sum(axis=1)[:, None]
    rel = pts[near][None, :, :] - a[:, None, :]  # (E, M, 2)
    t = (rel[..., 0] * d[:, None, 0] + rel[..., 1] * d[:, None, 1]) / np.maximum(l2, 1e-12)
    off = np.abs(rel[..., 0] * d[:, None, 1] - rel[..., 1] * d[:, None, 0]) / np.sqrt(np.maximum(l2, 1e-12))
    between = (t > 0.2) & (t < 0.8) & (off < TOLERANCE * np.sqrt((rel * rel).sum(axis=2))) & (l2 >= 1e-12)
    between &= (near[None, :] != steps[:, :1]) & (near[None, :] != steps[:, 1:])  # not the step's own ends
    return bool(between.any())


def _bent_pairs(steps: np.ndarray, ln: np.ndarray, contrast: np.ndarray | None) -> list[tuple]:
    """Pairs of seed steps as :func:`place_seed` picks them, for :func:`place_bent_seed`, in the order tried.

    steps : (K, 2) px from the seed point to its near points; ln : (K,) their lengths; contrast : (K,)
    :func:`edge_contrast` or None. Returns [(span, cos, area, a, b)]: single steps along square
    edges, not nearly collinear, cells up to ``BENT_CELL_AREA`` times the smallest, spans up to
    ``MAX_SPAN_RATIO`` times the shortest; shortest span first.
    """
    keep = []
    for a in range(len(steps)):  # single steps along square edges, as place_seed's
        if ln[a] < 1.0 or (contrast is not None and contrast[a] < 0.5 * contrast.max()):
            continue
        t = steps @ steps[a] / ln[a] ** 2
        off = np.abs(steps[a, 0] * steps[:, 1] - steps[a, 1] * steps[:, 0]) / ln[a]
        if not np.any((t > 0.2) & (t < 0.8) & (off < TOLERANCE * ln)):
            keep.append(a)
    pairs = []
    for x, a in enumerate(keep):
        for b in keep[x + 1:]:
            cos = abs(steps[a] @ steps[b]) / (ln[a] * ln[b])
            if 1 / MAX_STEP_RATIO <= ln[a] / ln[b] <= MAX_STEP_RATIO and cos < 0.95:
                area = abs(steps[a, 0] * steps[b, 1] - steps[a, 1] * steps[b, 0])
                pairs.append((ln[a] + ln[b], cos, area, a, b))
    if not pairs:
        return []
    amin = min(p[2] for p in pairs)
    pairs = [p for p in pairs if p[2] <= BENT_CELL_AREA * amin]
    smin = min(p[0] for p in pairs)
    return [p for p in sorted(pairs) if p[0] <= MAX_SPAN_RATIO * smin]


def place_bent_seed(lat: GrowingGrid, k: int, neighbours: np.ndarray, contrast: np.ndarray | None) -> bool:
    """A 3×3 seed about point ``k`` for a block that is no parallelogram; True (and cells taken) on success.

    Close to a fisheye the squares on one side of a corner can be a third smaller than on the
    other, and a 3×3 block's corners bow out: :func:`place_seed`'s parallelogram misses them. Here the
    steps u and v (:func:`_bent_pairs`) predict the opposite neighbours at −u and −v within
    ``BENT_SEED_TOLERANCE`` of the shorter step, and each diagonal corner is predicted from the
    edge neighbours found (p(i, 0) + p(0, j) − p(0, 0)), a parallelogram of one cell, within
    ``TOLERANCE``.
    """
    p0 = lat.pts[k]
    steps = lat.pts[neighbours] - p0
    ln = np.sqrt((steps * steps).sum(axis=1))
    for _, _, _, a, b in _bent_pairs(steps, ln, contrast):
        u, v = steps[a], steps[b]
        tol = min(ln[a], ln[b])
        got = {(1, 0): int(neighbours[a]), (0, 1): int(neighbours[b])}
        opp = lat.find(np.array([p0 - u, p0 - v]), np.full(2, BENT_SEED_TOLERANCE * tol), allow_propose=False)
        if np.any(opp < 0):
            continue
        got[(-1, 0)], got[(0, -1)] = int(opp[0]), int(opp[1])
        diag = [(i, j) for i in (-1, 1) for j in (-1, 1)]
        preds = np.array([lat.point(got[(i, 0)]) + lat.point(got[(0, j)]) - p0 for i, j in diag])
        found = lat.find(preds, np.full(4, TOLERANCE * tol), allow_propose=False)
        if np.any(found < 0):
            continue
        got.update({c: int(q) for c, q in zip(diag, found)})
        if len(set(got.values()) | {k}) < 9 or double_step(lat.pts, {(0, 0): k, **got}):
            continue
        lat.take((0, 0), k)
        for cell, q in got.items():
            lat.take(cell, q)
        return True
    return False


