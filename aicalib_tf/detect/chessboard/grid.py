"""Grid assembly: unordered corner points -> a lattice of (i, j) grid positions (pure numpy).

A chessboard's inner corners form a lattice that perspective and lens distortion bend but keep
locally regular: each corner's neighbours along a grid line sit about one step away, and the
step changes slowly. :func:`assemble_grids` finds such lattices among the candidate points:

1. Seed: a point, two of its near neighbours at an angle (steps u and v), and all 8 points of
   the 3×3 lattice they predict, each found within a tolerance (with ``strips``: the 5 other
   points of a 3×2 block, for boards of which only strips 2 corners wide are in view).
2. Grow: extrapolate every grid line one step outwards (quadratically when three points are
   known, so barrel distortion's curvature is followed; on a fisheye's bent lines by the steps'
   ratio, and by its trend where four are known, so squares shrinking 3× or more towards the rim
   are followed), accept a new row or column when most of its predictions find a point, and
   repeat in all four directions.
3. Fill holes: predict missing inside cells from their neighbours.

Seeds are placed by :mod:`aicalib_tf.detect.chessboard.grid_seeds`, growth and holes by
:mod:`aicalib_tf.detect.chessboard.grid_growth`.

Grids are returned largest first, each point used by at most one grid. Which grid is the board,
and the ids of its corners, is decided later (see :mod:`aicalib_tf.detect.pipeline`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aicalib_tf.detect.chessboard.grid_growth import GrowingGrid, build
from aicalib_tf.detect.chessboard.grid_seeds import SeedContrast, place_bent_seed, place_seed
from aicalib_tf.geometry.points import nearest_k

MIN_CORNERS = 9  # fewest corners of a grid, and so of any board returned: a grid grows from a 3x3 seed

__all__ = ["Grid", "assemble_grids", "full_subgrid"]


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


def assemble_grids(points: np.ndarray, scores: np.ndarray | None = None, *, gray: np.ndarray | None = None,
                   min_size: int = MIN_CORNERS, neighbours: int = 12, propose=None, limit: int | None = None,
                   strips: bool = False, stop=None, bend: bool = False) -> list[Grid]:
    """Find lattices among candidate corner points.

    points : (N, 2) float (x, y) px. scores : (N,) or None; seeds are tried strongest first.
    gray : (H, W) float32 image, smoothed; lets seeds tell grid lines from diagonals. Without it,
        a strongly skewed board can come out as a sheared lattice.
    min_size : the fewest points a grid may have. neighbours : near points tried as seed steps.
    propose : optional callable that looks for a corner where the lattice predicts one and no
        candidate is (see :class:`~aicalib_tf.detect.chessboard.grid_growth.GrowingGrid`); it fills
        holes, and with ``limit`` also extends edges.
    limit : the largest number of positions along either grid axis (e.g. max(cols, rows)).
    strips : seed with 3×2 blocks, not 3×3 (see :func:`~aicalib_tf.detect.chessboard.grid_seeds.place_seed`).
        Such seeds also fit sheared lattices of a board whose 3×3 blocks are in view;
        :mod:`aicalib_tf.detect.pipeline` uses them only where no 3×3 seed started a grid.
    stop : None, or ``stop(grid) -> bool``, asked about each grid as it is assembled; when it
        says True, no further seed is tried (the grids so far are returned). The detector stops at
        the first grid that is the full board: later seeds could only give other grids, and of
        the grids that are the full board the first assembled was returned anyway. On a photo
        with clutter (a keyboard, a screen), seeds there cost more than the board itself.
    bend : lines bending strongly, squares shrinking towards a fisheye's rim: a bent seed
        (:func:`~aicalib_tf.detect.chessboard.grid_seeds.place_bent_seed`) where the parallelogram
        seed fails, double steps undone, lines and holes predicted from the lines' turn and the
        cells' shape, regrown (:mod:`aicalib_tf.detect.chessboard.grid_growth`).
    Returns grids, largest first; they share no point.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    n = len(pts)
    if n < MIN_CORNERS:
        return []
    order = np.argsort(-np.asarray(scores), kind="stable") if scores is not None else np.arange(n)
    near = nearest_k(pts, neighbours)  # in row blocks: memory O(N) per row, not an (N, N) matrix
    free = np.ones(n, bool)
    contrast = None if gray is None else SeedContrast(gray, pts, near, order, free)
    grids = []
    for k in order:
        if not free[k]:
            continue
        lat = GrowingGrid(pts, free, propose, limit, bend)
        edges = None if contrast is None else contrast.row(int(k))
        seeded = place_seed(lat, int(k), near[k], edges, strips)
        if not (seeded or (bend and place_bent_seed(lat, int(k), near[k], edges))):
            continue
        build(lat)
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
