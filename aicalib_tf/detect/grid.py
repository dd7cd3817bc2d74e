"""Grid assembly: unordered corner points -> a lattice of (i, j) grid positions (pure numpy).

A chessboard's inner corners form a lattice that perspective and lens distortion bend but keep
locally regular: each corner's neighbours along a grid line sit about one step away, and the
step changes slowly. :func:`assemble_grids` finds such lattices among the candidate points:

1. Seed: a point, two of its near neighbours at an angle (steps u and v), and all 8 points of
   the 3×3 lattice they predict, each found within a tolerance (with ``strips``: the 5 other
   points of a 3×2 block, for boards of which only strips 2 corners wide are in view).
2. Grow: extrapolate every grid line one step outwards (quadratically when three points are
   known, so barrel distortion's curvature is followed), accept a new row or column when most
   of its predictions find a point, and repeat in all four directions.
3. Fill holes: predict missing inside cells from their neighbours.

Grids are returned largest first, each point used by at most one grid. Which grid is the board,
and the ids of its corners, is decided later (see :mod:`aicalib_tf.detect.pipeline`).
"""

# size: grid assembly is one algorithm (seed, grow side by side, fill holes) over one private
# lattice state; split, that state and its helpers would have to become public across modules.
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aicalib_tf.detect.grid_kernels import edge_contrasts, grow_lines, seed_block
from aicalib_tf.detect.junctions import SAME_CORNER
from aicalib_tf.geometry.points import nearest_k, sq_distances

MIN_CORNERS = 9  # fewest corners of a grid, and so of any board returned: a grid grows from a 3x3 seed

__all__ = ["Grid", "assemble_grids", "edge_contrast", "full_subgrid"]

TOLERANCE = 0.3  # of the local step: how far a predicted corner may be from the point it takes
MAX_STEP_RATIO = 4.5  # a seed's two steps may differ in length this much (a board tilted 60°+ halves one)
MAX_CELL_AREA = 1.5  # seed pairs spanning more than this of the smallest cell generate a sub-lattice
MAX_SPAN_RATIO = 1.15  # seed pairs longer than this times the shortest (|u| + |v|) are not tried
BENT_SEED_TOLERANCE = 0.45  # of the shorter step: a bent seed's opposite neighbours (see _bent_seed)
BENT_CELL_AREA = 2.0  # MAX_CELL_AREA of bent seeds: beside a fisheye's centre, cells next to each other differ this much
DOUBLE_STEP_REACH = 1.7  # tolerances from a prediction within which a skipped corner is taken instead


@dataclass(frozen=True)
class Grid:
    """A lattice of points.

    index : (K,) int, rows into the candidate points, or -1 for a point the ``propose`` callback
    found. ij : (K, 2) int, (i, j) lattice positions with min 0 along each axis (i counts steps
    along one grid direction, j along the other). points : (K, 2) float (x, y) px.
    """

    index: np.ndarray
    ij: np.ndarray
    points: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        """(number of i positions, number of j positions)."""
        return (int(self.ij[:, 0].max()) + 1, int(self.ij[:, 1].max()) + 1)

    def __len__(self) -> int:
        return len(self.index)


def full_subgrid(grid: Grid, min_side: int = 3) -> Grid | None:
    """The largest sub-rectangle of a grid with a point at every (i, j), as a grid of its own.

    A grid with every position of its extent filled is returned as it is. Otherwise, e.g. when a
    line cut by the image frame kept only a few of its corners, the filled rectangle with the most
    points (ties: the first with the smallest i, then j) is cut out and its ij shifted to start at
    0. None when no filled rectangle has ``min_side`` positions along both axes.
    """
    a, b = grid.shape
    if len(grid) == a * b:
        return grid if min(a, b) >= min_side else None
    filled = np.zeros((a, b), bool)
    filled[grid.ij[:, 0], grid.ij[:, 1]] = True
    best, best_n = None, 0
    for i0 in range(a):
        along = np.ones(b, bool)
        for i1 in range(i0, a):
            along &= filled[i1]
            if i1 - i0 + 1 < min_side:
                continue
            run = 0
            for j in range(b):  # the longest run of j filled for every i in [i0, i1]
                run = run + 1 if along[j] else 0
                if run >= min_side and run * (i1 - i0 + 1) > best_n:
                    best, best_n = (i0, i1, j - run + 1, j), run * (i1 - i0 + 1)
    if best is None:
        return None
    i0, i1, j0, j1 = best
    sel = (grid.ij[:, 0] >= i0) & (grid.ij[:, 0] <= i1) & (grid.ij[:, 1] >= j0) & (grid.ij[:, 1] <= j1)
    return Grid(index=grid.index[sel], ij=grid.ij[sel] - np.array([i0, j0]), points=grid.points[sel])


class _Lattice:
    """Mutable (i, j) -> point index map while a grid grows.

    propose : optional callable (pred (M, 2), step (M,)) -> (M, 2) points with NaN rows where no
    corner is there; asked for predictions that no free candidate point matches.
    limit : the largest extent (number of i or j positions) a grid may reach.
    """

    def __init__(self, pts: np.ndarray, free: np.ndarray, propose=None, limit: int | None = None, bend: bool = False):
        self.pts, self.free, self.n0 = pts, free, len(pts)
        self.bend = bend  # lines that bend strongly (assemble_grids' ``bend``)
        self.cells: dict[tuple[int, int], int] = {}
        self.at: dict[tuple[int, int], np.ndarray] = {}  # the cells' points: (2,) float64 px
        self.coords: tuple[set, set] = (set(), set())  # the i and the j positions taken
        self.propose, self.limit = propose, limit
        self.extra: list[np.ndarray] = []
        self.version = 0  # counts cells taken: what was worked out at one version holds until the next
        self.sides: dict = {}  # (axis, sign) -> (version, that side's next line), see _side
        self.free_idx = (-1, None)  # (version, np.flatnonzero(free) at that version)

    def point(self, k: int) -> np.ndarray:
        return self.pts[k] if k < self.n0 else self.extra[k - self.n0]

    def _nearest_free(self, pred: np.ndarray, tol: np.ndarray):
        """(M,) index of the nearest free candidate within tol of each prediction, or -1; and the misses."""
        # while a lattice grows only its take() changes free: the list holds until the next version
        if self.free_idx[0] != self.version:
            self.free_idx = (self.version, np.flatnonzero(self.free))
        idx = self.free_idx[1]
        if len(idx) == 0:
            return np.full(len(pred), -1), np.arange(len(pred))
        d2 = sq_distances(pred, self.pts[idx])
        best = np.argmin(d2, axis=1)
        ok = d2[np.arange(len(pred)), best] <= tol**2
        return np.where(ok, idx[best], -1), np.flatnonzero(~ok)

    def ask_ahead(self, pred: np.ndarray, tol: np.ndarray) -> None:
        """Ask ``propose`` in one batch about predictions that no free candidate matches.

        Nothing is taken: a ``propose`` that remembers its answers then answers :meth:`find`'s
        later asks for the same predictions at no cost.
        """
        _, miss = self._nearest_free(pred, tol)
        if self.propose is not None and len(miss):
            self.propose(pred[miss], tol[miss] / TOLERANCE)

    def find(self, pred: np.ndarray, tol: np.ndarray, allow_propose: bool = True) -> np.ndarray:
        """For predictions (M, 2) and tolerances (M,), a point index within tol, or -1."""
        found, miss = self._nearest_free(pred, tol)
        if self.propose is not None and allow_propose and len(miss):
            got = self.propose(pred[miss], tol[miss] / TOLERANCE)
            near = np.isfinite(got).all(axis=1)
            near[near] = ((got[near] - pred[miss[near]]) ** 2).sum(axis=1) <= tol[miss[near]] ** 2
            taken = None
            for m, q in zip(miss[near], got[near]):
                # a squeezed corner's fit can slide onto its neighbour: one corner is never two cells
                taken = np.array(list(self.at.values())).reshape(-1, 2) if taken is None else taken
                if len(taken) and np.min(((taken - q) ** 2).sum(axis=1)) < SAME_CORNER**2:
                    continue
                self.extra.append(np.asarray(q, np.float64))
                found[m] = self.n0 + len(self.extra) - 1
        return found

    def take(self, cell: tuple[int, int], k: int) -> None:
        self.cells[cell] = int(k)
        self.at[cell] = self.point(k)
        self.coords[0].add(int(cell[0]))
        self.coords[1].add(int(cell[1]))
        self.version += 1
        if k < self.n0:
            self.free[k] = False

    def p(self, cell) -> np.ndarray | None:
        return self.at.get(cell)

    def extent(self, axis: int) -> int:
        return max(self.coords[axis]) - min(self.coords[axis]) + 1


def _norm(d: np.ndarray) -> float:
    """Length of one (2,) vector, as ``np.linalg.norm`` computes it, without its overhead."""
    return float(np.sqrt(d.dot(d)))


def _predict(lat: _Lattice, cell: tuple[int, int], back: tuple[int, int]) -> tuple[np.ndarray, float] | None:
    """Predict the point at ``cell`` from the line of known points behind it (direction ``back``)."""
    i, j = cell
    di, dj = back
    p1 = lat.p((i + di, j + dj))
    p2 = lat.p((i + 2 * di, j + 2 * dj))
    if p1 is None or p2 is None:
        return None
    p3 = lat.p((i + 3 * di, j + 3 * dj))
    step = _norm(p1 - p2)
    if p3 is None:
        return 2 * p1 - p2, step
    if lat.bend:
        return _turned(p1[None], p2[None], p3[None])[0], step
    # quadratic extrapolation follows the curvature of distorted lines
    return 3 * p1 - 3 * p2 + p3, step


def _turned(p1: np.ndarray, p2: np.ndarray, p3: np.ndarray) -> np.ndarray:
    """The next points (M, 2) of lines ending p3, p2, p1 (each (M, 2) px), each step the last one
    turned and scaled as the last one was from the one before (a constant complex ratio of steps).

    Towards a fisheye's rim a line's steps shrink by a similar fraction each step while its direction
    turns steadily; a quadratic (constant second difference) overshoots there, the more the faster
    they shrink. On the true corners of data_gen's ``fisheye_closeup`` boards the ratio misses the
    next corner by more than ``TOLERANCE`` of a step 125 times in 12600, the quadratic 144 times.
    """
    a, b = p1 - p2, p2 - p3
    den = (b * b).sum(axis=1)
    # (a / b) · a in complex numbers: a's length and turn relative to b, applied once more to a
    re = (a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]) / den
    im = (a[:, 1] * b[:, 0] - a[:, 0] * b[:, 1]) / den
    return p1 + np.stack([re * a[:, 0] - im * a[:, 1], re * a[:, 1] + im * a[:, 0]], axis=1)


def _side(lat: _Lattice, axis: int, sign: int):
    """The next line beyond one side: (cells, predictions (M, 2), tolerances (M,)), or None.

    Each line ending on that side predicts its next point as :func:`_predict` does (all lines at
    once). None when the grid has reached ``limit`` along ``axis`` or no line predicts a point.
    Worked out once per lattice version (``_Lattice.sides``), so callers must not change the arrays.
    """
    cached = lat.sides.get((axis, sign))
    if cached is None or cached[0] != lat.version:
        cached = (lat.version, _work_out_side(lat, axis, sign))
        lat.sides[(axis, sign)] = cached
    return cached[1]


def _work_out_side(lat: _Lattice, axis: int, sign: int):
    """:func:`_side`, computed."""
    if lat.limit is not None and lat.extent(axis) >= lat.limit:
        return None
    new = max(lat.coords[axis]) + 1 if sign > 0 else min(lat.coords[axis]) - 1
    get = lat.at.get
    b1, b2, b3 = new - sign, new - 2 * sign, new - 3 * sign
    cells, l1, l2, l3, quad = [], [], [], [], []
    for o in sorted(lat.coords[1 - axis]):
        if axis == 0:
            q1, q2, q3 = get((b1, o)), get((b2, o)), get((b3, o))
        else:
            q1, q2, q3 = get((o, b1)), get((o, b2)), get((o, b3))
        if q1 is not None and q2 is not None:
            cells.append((new, o) if axis == 0 else (o, new))
            l1.append(q1)
            l2.append(q2)
            l3.append(q1 if q3 is None else q3)
            quad.append(q3 is not None)
    if not cells:
        return None
    p1, p2, p3 = np.array(l1), np.array(l2), np.array(l3)
    quad = np.array(quad)[:, None]
    # quadratic where three points are known (with bend, the steps' ratio: _turned)
    ahead = _turned(p1, p2, p3) if lat.bend else 3 * p1 - 3 * p2 + p3
    preds = np.where(quad, ahead, 2 * p1 - p2)
    d = p1 - p2
    return cells, preds, TOLERANCE * np.sqrt((d * d).sum(axis=1))


def _grow_side(lat: _Lattice, axis: int, sign: int, whole: bool = False, answer=None) -> bool:
    """Try to add one row/column beyond the current extent on one side (:func:`_side`). True if added.

    The line is added when at least half its predictions (and 2) find a point; with ``whole``, only
    when all of them find a candidate point (``propose`` is not asked). answer : None, or
    (version, found) from :func:`_answer_sides`, used while the lattice is still at that version.
    """
    side = _side(lat, axis, sign)
    if side is None:
        return False
    cells, preds, tols = side
    if answer is not None and answer[0] == lat.version:
        found = answer[1]
    else:
        found = lat.find(preds, tols, allow_propose=lat.limit is not None and not whole)
    if lat.bend:
        found = _single_steps(lat, axis, sign, cells, preds, tols, found)
    hits = [(c, k) for c, k in zip(cells, found) if k >= 0]
    if whole and len(hits) < len(cells):
        return False
    if len(hits) < max(2, 0.5 * len(cells)) or len({k for _, k in hits}) < len(hits):
        return False
    for c, k in hits:
        lat.take(c, k)
    return True


def _answer_sides(lat: _Lattice) -> dict:
    """Every side's next line found in one batch: {(axis, sign): (version, found (M,))}, for
    :func:`_grow_side` (each prediction's answer is its own: the same as asked side by side)."""
    sides = {(axis, sign): side for axis in (0, 1) for sign in (1, -1) if (side := _side(lat, axis, sign)) is not None}
    if len(sides) < 2:
        return {}
    found = lat.find(np.concatenate([p for _, p, _ in sides.values()]), np.concatenate([t for _, _, t in sides.values()]))
    ends = np.cumsum([len(c) for c, _, _ in sides.values()])
    return {key: (lat.version, part) for key, part in zip(sides, np.split(found, ends[:-1]))}


def _single_steps(lat: _Lattice, axis: int, sign: int, cells: list, preds: np.ndarray, tols: np.ndarray,
                  found: np.ndarray) -> np.ndarray:
    """``found`` (M,) with double steps undone: a grid line's next corner is its neighbour, with no
    corner between them.

    Where a line's steps first grow and then shrink (a close-up board across a fisheye's centre,
    its far side squeezed towards the rim), the extrapolated step overshoots and the corner two
    steps on can lie nearer the prediction than the next one. A point found with a free candidate
    part-way along the step to it (20–80% of the way, within ``TOLERANCE`` of that part-step of
    the line) takes that candidate instead when it lies within ``DOUBLE_STEP_REACH`` tolerances of
    the prediction, and is dropped otherwise.
    """
    out = found.copy()
    n0 = lat.n0
    for m, (cell, k) in enumerate(zip(cells, found)):
        if k < 0:
            continue
        back = (cell[0] - sign, cell[1]) if axis == 0 else (cell[0], cell[1] - sign)
        p1 = lat.at[back]
        d = lat.point(int(k)) - p1
        l2 = float(d.dot(d))
        if l2 < 1e-12:
            continue
        rel = lat.pts - p1
        t = (rel @ d) / l2
        off = np.abs(rel[:, 0] * d[1] - rel[:, 1] * d[0]) / np.sqrt(l2)
        between = (t > 0.2) & (t < 0.8) & (off < TOLERANCE * np.sqrt((rel * rel).sum(axis=1)))
        if k < n0:
            between[k] = False
        idx = np.flatnonzero(between)
        if len(idx) == 0:
            continue
        near = idx[np.argmin(((lat.pts[idx] - preds[m]) ** 2).sum(axis=1))]
        ok = lat.free[near] and _norm(lat.pts[near] - preds[m]) <= DOUBLE_STEP_REACH * tols[m]
        out[m] = near if ok else -1
    return out


def _grow(lat: _Lattice) -> None:
    """Grow all four sides in turn until none grows. Where ``propose`` is asked (with ``limit``),
    first by lines whose every point is a candidate, then by any line (``propose`` asked about the
    points no candidate gives): a board's lines come from candidates, ``propose`` only looks where
    they end or have gaps.

    Each round of the second kind first looks for all four sides' next lines in one batch
    (:func:`_answer_sides`): a side is decided by that answer while no other side has grown before
    its turn, and asked again otherwise (``propose`` answers from its memory,
    :func:`aicalib_tf.detect.junctions.proposer`).
    """
    asks = lat.propose is not None and lat.limit is not None
    for whole in ((True, False) if asks else (False,)):
        if not lat.bend and not (asks and not whole):  # candidates alone: the same growth, compiled
            _grow_compiled(lat, whole)
            continue
        grown = True
        while grown:
            grown = False
            answers = _answer_sides(lat) if asks and not whole else {}
            for axis in (0, 1):
                for sign in (1, -1):
                    while _grow_side(lat, axis, sign, whole, answers.get((axis, sign))):
                        grown = True


def _grow_compiled(lat: _Lattice, whole: bool) -> None:
    """One phase of :func:`_grow` in which ``propose`` is not asked and lines do not bend: the cells
    :func:`~aicalib_tf.detect.grid_kernels.grow_lines` takes, taken in its order."""
    seed = np.array([(i, j, k) for (i, j), k in lat.cells.items()], np.int64)
    limit = -1 if lat.limit is None else int(lat.limit)
    for i, j, k in grow_lines(lat.pts, lat.free, seed, limit, whole, TOLERANCE).tolist():
        lat.take((i, j), k)


def _parallelogram(lat: _Lattice, cell: tuple[int, int]) -> list[tuple[np.ndarray, float]]:
    """Predictions of ``cell`` from three known neighbours forming a parallelogram with it."""
    i, j = cell
    out = []
    for di in (-1, 1):
        for dj in (-1, 1):
            a, b, c = lat.p((i + di, j)), lat.p((i, j + dj)), lat.p((i + di, j + dj))
            if a is not None and b is not None and c is not None:
                out.append((a + b - c, min(_norm(a - c), _norm(b - c))))
    return out


# Interpolation of a cell from known cells on its grid line, exact for a polynomial in the position
# (cubic, quadratic, linear): (offsets along the line, weights); the first whose cells are all known is used
_LINE_STENCILS = (
    ((-2, -1, 1, 2), (-1 / 6, 4 / 6, 4 / 6, -1 / 6)),
    ((-1, 1, 2, 3), (0.25, 1.5, -1.0, 0.25)),
    ((1, -1, -2, -3), (0.25, 1.5, -1.0, 0.25)),
    ((-1, 1, 2), (1 / 3, 1.0, -1 / 3)),
    ((1, -1, -2), (1 / 3, 1.0, -1 / 3)),
    ((-1, 1), (0.5, 0.5)),
)


def _interpolate(lat: _Lattice, cell: tuple[int, int]) -> tuple[np.ndarray, float] | None:
    """A missing cell between known cells on its grid lines: (point, tolerance) or None.

    Along each line with a known cell on both sides, the cell is interpolated (:data:`_LINE_STENCILS`)
    and the lines' points are averaged; the tolerance is ``TOLERANCE`` of the shortest half-span
    between the cell's two neighbours. Where a line's steps grow and then shrink across a fisheye's
    centre, interpolation follows the bend that extrapolation from one side overshoots.
    """
    i, j = cell
    preds, steps = [], []
    for di, dj in ((1, 0), (0, 1)):
        for offs, wts in _LINE_STENCILS:
            got = [lat.p((i + o * di, j + o * dj)) for o in offs]
            if all(q is not None for q in got):
                preds.append(sum(w * q for w, q in zip(wts, got)))
                steps.append(0.5 * _norm(got[offs.index(1)] - got[offs.index(-1)]))
                break
    if not preds:
        return None
    return np.mean(preds, axis=0), TOLERANCE * min(steps)


def _hole(lat: _Lattice, cell: tuple[int, int]) -> tuple[np.ndarray, float] | None:
    """A missing cell's predicted point and tolerance: the mean of its neighbours' predictions
    (with ``bend``, interpolated along its grid lines where it can be, :func:`_interpolate`)."""
    if lat.bend and (got := _interpolate(lat, cell)) is not None:
        return got
    preds = [got for back in ((-1, 0), (1, 0), (0, -1), (0, 1)) if (got := _predict(lat, cell, back)) is not None]
    preds += _parallelogram(lat, cell)
    if not preds:
        return None
    return np.mean([p for p, _ in preds], axis=0), TOLERANCE * min(s for _, s in preds)


def _fill_holes(lat: _Lattice, passes: int = 10) -> None:
    """Take points for missing cells inside the grid's extent, predicted from known neighbours.

    Cells are filled one by one, each prediction using the cells filled before it. Each pass first
    asks ``propose`` about all its holes in one batch (:meth:`_Lattice.ask_ahead`), so a hole whose
    prediction did not change before its turn is answered from ``propose``'s memory.
    """
    keys = np.array(list(lat.cells.keys()))
    (i0, j0), (i1, j1) = keys.min(0), keys.max(0)
    for _ in range(passes):
        holes = [(i, j) for i in range(i0, i1 + 1) for j in range(j0, j1 + 1) if (i, j) not in lat.cells]
        ahead = [h for cell in holes if (h := _hole(lat, cell)) is not None] if lat.propose is not None else []
        if len(ahead) > 1:
            lat.ask_ahead(np.array([p for p, _ in ahead]), np.array([t for _, t in ahead]))
        added = False
        for cell in holes:
            got = _hole(lat, cell)
            if got is None:
                continue
            k = lat.find(got[0][None], np.array([got[1]]))[0]
            if k < 0 and lat.bend and (alt := _cell_shape(lat, cell)) is not None:
                k = lat.find(alt[0][None], np.array([alt[1]]))[0]
            if k >= 0:
                lat.take(cell, k)
                added = True
        if not added:
            break


def _cell_shape(lat: _Lattice, cell: tuple[int, int]) -> tuple[np.ndarray, float] | None:
    """With ``bend``, a second prediction of a hole that no line interpolates: its cell's
    parallelograms alone, or None.

    Where the lines through a cell at the board's edge cross a fisheye's centre, their steps grow
    and then shrink, and extrapolating along them misses the turn; the neighbouring cell's shape
    changes little. On the true corners along the sides of data_gen's ``fisheye_closeup`` boards
    (100 images, each missing alone) the parallelograms miss by 0.03 tolerances (median) and the
    mean of all predictions by 0.07; but at the board's own four corners by 0.25 against 0.12, and
    beyond the tolerance 9 times in 2600 against 2: they are asked second.
    """
    if _interpolate(lat, cell) is not None:
        return None
    par = _parallelogram(lat, cell)
    if not par:
        return None
    return np.mean([p for p, _ in par], axis=0), TOLERANCE * min(s for _, s in par)


def edge_contrast(gray: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """How strongly the segments p→q look like an edge between two squares.

    Between neighbouring corners along a grid line the board has a black square on one side and a
    white one on the other; along a diagonal both sides are the same square. Samples at 35%, 50%
    and 65% of the way, a quarter of the length to each side (a compiled loop,
    :func:`aicalib_tf.detect.grid_kernels.edge_contrasts`).
    gray : (H, W) float32. p, q : (M, 2) px. Returns (M,) float32, |mean left − mean right|.
    """
    p = np.asarray(p, np.float64).reshape(-1, 2)
    q = np.asarray(q, np.float64).reshape(-1, 2)
    return edge_contrasts(np.asarray(gray, np.float32), p, q)


class _SeedContrast:
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


def _seed(lat: _Lattice, k: int, neighbours: np.ndarray, contrast: np.ndarray | None = None,
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
    """
    blocks, orders = (_OFFS[None], 1) if not strips else (_STRIP_BLOCKS, 2)
    b, _, _, found = seed_block(lat.pts, int(k), neighbours, _NO_CONTRAST if contrast is None else contrast, lat.free,
                                blocks, orders, TOLERANCE, MAX_STEP_RATIO, MAX_CELL_AREA, MAX_SPAN_RATIO)
    if b < 0:
        return False
    lat.take((0, 0), k)
    for (di, dj), q in zip(blocks[b].astype(int).tolist(), found.tolist()):
        lat.take((di, dj), q)
    return True


def _bent_pairs(steps: np.ndarray, ln: np.ndarray, contrast: np.ndarray | None) -> list[tuple]:
    """Pairs of seed steps as :func:`_seed` picks them, for :func:`_bent_seed`, in the order tried.

    steps : (K, 2) px from the seed point to its near points; ln : (K,) their lengths; contrast : (K,)
    :func:`edge_contrast` or None. Returns [(span, cos, area, a, b)]: single steps along square
    edges, not nearly collinear, cells up to ``BENT_CELL_AREA`` times the smallest, spans up to
    ``MAX_SPAN_RATIO`` times the shortest; shortest span first.
    """
    keep = []
    for a in range(len(steps)):  # single steps along square edges, as _seed's
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


def _bent_seed(lat: _Lattice, k: int, neighbours: np.ndarray, contrast: np.ndarray | None) -> bool:
    """A 3×3 seed about point ``k`` for a block that is no parallelogram; True (and cells taken) on success.

    Close to a fisheye the squares on one side of a corner can be a third smaller than on the
    other, and a 3×3 block's corners bow out: :func:`_seed`'s parallelogram misses them. Here the
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
        if len(set(got.values()) | {k}) < 9:
            continue
        lat.take((0, 0), k)
        for cell, q in got.items():
            lat.take(cell, q)
        return True
    return False


def _build(lat: _Lattice) -> None:
    """Grow a seeded lattice and fill its holes; with ``bend``, grow again while filled holes add
    lines to extend (a hole interpolated beside the lens' centre lets the line through it go on)."""
    _grow(lat)
    grown = lat.version
    _fill_holes(lat)
    while lat.bend and lat.version != grown:
        filled = lat.version
        _grow(lat)
        if lat.version == filled:
            break
        grown = lat.version
        _fill_holes(lat)


def assemble_grids(points: np.ndarray, scores: np.ndarray | None = None, *, gray: np.ndarray | None = None,
                   min_size: int = MIN_CORNERS, neighbours: int = 12, propose=None, limit: int | None = None,
                   strips: bool = False, stop=None, bend: bool = False) -> list[Grid]:
    """Find lattices among candidate corner points.

    points : (N, 2) float (x, y) px. scores : (N,) or None; seeds are tried strongest first.
    gray : (H, W) float32 image, smoothed; lets seeds tell grid lines from diagonals. Without it,
        a strongly skewed board can come out as a sheared lattice.
    min_size : the fewest points a grid may have. neighbours : near points tried as seed steps.
    propose : optional callable that looks for a corner where the lattice predicts one and no
        candidate is (see ``_Lattice``); it fills holes, and with ``limit`` also extends edges.
    limit : the largest number of positions along either grid axis (e.g. max(cols, rows)).
    strips : seed with 3×2 blocks, not 3×3 (see :func:`_seed`). Such seeds also fit sheared
        lattices of a board whose 3×3 blocks are in view; :mod:`aicalib_tf.detect.pipeline` uses them
        only where no 3×3 seed started a grid.
    stop : None, or ``stop(grid) -> bool``, asked about each grid as it is assembled; when it
        says True, no further seed is tried (the grids so far are returned). The detector stops at
        the first grid that is the full board: later seeds could only give other grids, and of
        the grids that are the full board the first assembled was returned anyway. On a photo
        with clutter (a keyboard, a screen), seeds there cost more than the board itself.
    bend : lines bending strongly, squares shrinking towards a fisheye's rim: :func:`_bent_seed`
        where :func:`_seed` fails, double steps undone (:func:`_single_steps`), lines and holes
        predicted by :func:`_turned`, :func:`_interpolate` and :func:`_cell_shape`, regrown (:func:`_build`).
    Returns grids, largest first; they share no point.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    n = len(pts)
    if n < MIN_CORNERS:
        return []
    order = np.argsort(-np.asarray(scores), kind="stable") if scores is not None else np.arange(n)
    near = nearest_k(pts, neighbours)  # in row blocks: memory O(N) per row, not an (N, N) matrix
    free = np.ones(n, bool)
    contrast = None if gray is None else _SeedContrast(gray, pts, near, order, free)
    grids = []
    for k in order:
        if not free[k]:
            continue
        lat = _Lattice(pts, free, propose, limit, bend)
        edges = None if contrast is None else contrast.row(int(k))
        if not (_seed(lat, int(k), near[k], edges, strips) or (bend and _bent_seed(lat, int(k), near[k], edges))):
            continue
        _build(lat)
        if len(lat.cells) < min_size:
            for kk in lat.cells.values():  # give the points back for other seeds
                if kk < n:
                    free[kk] = True
            continue
        ij = np.array(list(lat.cells.keys()))
        ks = list(lat.cells.values())
        grids.append(Grid(index=np.array([k if k < n else -1 for k in ks]), ij=ij - ij.min(0),
                          points=np.array([lat.point(k) for k in ks])))
        if stop is not None and stop(grids[-1]):
            break
    grids.sort(key=len, reverse=True)
    return grids
