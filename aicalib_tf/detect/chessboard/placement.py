"""Where a partial grid lies on the pattern: the ids its image evidence leaves (:func:`place_cells`).

A grid is placed on the pattern by a 90° turn that keeps handedness and a shift; the image must
decide which. Three kinds of evidence rule placements out (see :mod:`aicalib_tf.detect.pipeline` for the
contract):

* extent: the grid fits inside the pattern;
* borders (:func:`_border_sides`): a grid side whose next line has alternating squares before it
  and white paper just beyond it is the pattern's outermost line;
* colours (:func:`_square_colours`): the grid's black squares must be the board's black squares.

When placements of more than one kind are left, each is drawn around the grid
(:func:`_contradicted`): where it puts squares, white paper or the background, up to
``RENDER_BAND`` squares beyond the grid, against the image there. A corner of the board whose
one border lies mostly beyond the frame still shows, in its last few pixels, paper where another
placement puts squares. The placement the image does not contradict is kept when it contradicts
each other in at least ``RENDER_MIN`` squares; when an object in front contradicts every placement,
the least contradicted is kept when each other has ``RENDER_MARGIN`` squares more. Measured with
``benchmarks/partial_boards.py`` (data_gen ``occluded``, ``hard`` and ``partial``, seeds 5 and 7–12,
100 images each), against the rule before (a placement not contradicted, each other in 2 squares
or more): the same wrong ids on every seed, recall up 0.5–4 points. Ids come back only when the
placements left agree up to the board's symmetry.
"""

from __future__ import annotations

import cv2
import numpy as np

from aicalib_tf.detect.chessboard.board_order import choose_reading, symmetric_ids
from aicalib_tf.detect.chessboard.lattice import predict_ids
from aicalib_tf.detect.corners.sampling import sample_bilinear

__all__ = ["place_cells"]


# handedness-preserving maps of grid (i, j) onto board (col, row): 0°, 90°, 180°, 270°
_ROTATIONS = tuple(np.array(m) for m in ([[1, 0], [0, 1]], [[0, -1], [1, 0]], [[-1, 0], [0, -1]], [[0, 1], [-1, 0]]))


BORDER_BEYOND = 0.12  # where the margin is looked for: this fraction of a step beyond the last line


BORDER_T = 0.8  # white-normalised grey the margin must reach there (0 black square, 1 white square); 0.7 let a
# light grey object along a side pass for the margin (data_gen occluded seed 7 #44: 0.71, 36 wrong ids)


FAILED_RATIO = 2  # a border side: untested (corner missing in view) squares at most 1/FAILED_RATIO of the tested


RENDER_BAND = 2  # squares beyond the grid where placements are drawn and compared with the image


RENDER_MIN = 1  # squares each other placement must contradict when one is not contradicted (2: the same
# wrong ids on partial_boards.py seeds 5, 7-12, and up to 4.4 points less partial recall)


RENDER_MARGIN = 3  # when every placement is contradicted (an object in front): squares more than the least


_INNER = 0.2  # of a step: samples inside a square stay this far from its edges (blur)


_PAPER = (0.04, 0.1)  # of a step beyond the outer squares' edge: still white paper (the margin is >= 0.15 square)


_ACROSS = np.linspace(_INNER + 0.1, 0.9 - _INNER, 5)  # where across a square (0..1 between its two corners of the
# last line) the border test samples at each depth; their mean decides


def _square_centres(cells: dict) -> tuple[np.ndarray, np.ndarray]:
    """The grid squares with all four corners found: parity (K,) int of i + j, and centres (K, 2) px.

    cells : {(i, j): (2,) px}. Grid square (i, j) lies between corners (i, j) and (i+1, j+1); its
    centre is the mean of its four corners.
    """
    keys, centres = [], []
    for (i, j), p in cells.items():
        q = [cells.get(c) for c in ((i + 1, j), (i, j + 1), (i + 1, j + 1))]
        if all(v is not None for v in q):
            keys.append(i + j)
            centres.append(0.25 * (p + q[0] + q[1] + q[2]))
    return np.array(keys, int).reshape(-1) % 2, np.array(centres, np.float64).reshape(-1, 2)


def _square_colours(cells: dict, gray: np.ndarray):
    """Which grid squares are black, from the grey at their centres.

    cells : {(i, j): (2,) px}. Grid square (i, j) lies between corners (i, j) and (i+1, j+1).
    Returns (black, contrast): black is the parity of i + j of the black squares (0 or 1), or None
    when the squares do not split into two clearly different colours; contrast is white − black grey.
    """
    par, centres = _square_centres(cells)
    if len(par) < 2:
        return None, 0.0
    vals = sample_bilinear(gray, centres)
    if par.min() == par.max():
        return None, 0.0
    m0, m1 = vals[par == 0].mean(), vals[par == 1].mean()
    black = 0 if m0 < m1 else 1
    agree = np.mean((vals < 0.5 * (m0 + m1)) == (par == black))
    contrast = abs(m1 - m0)
    if agree < 0.9 or contrast < 0.08:
        return None, contrast
    return black, contrast


def _grid_samples(ext: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Sample points around a grid, in continuous grid coordinates, and the square each lies in.

    Every grid square (a, b) (between corners (a, b) and (a+1, b+1)) up to ``RENDER_BAND`` beyond
    the grid's extent gets five points at least ``_INNER`` of a step inside it (its colour, were it
    a board square) and four just inside its edges (white paper, were the board to end there).
    Returns (points (M, 2) float, squares (M, 2) int).
    """
    k = RENDER_BAND
    a, b = np.meshgrid(np.arange(-k, ext[0] - 1 + k), np.arange(-k, ext[1] - 1 + k), indexing="ij")
    sq = np.stack([a.ravel(), b.ravel()], 1)
    lo, hi = _INNER, 1.0 - _INNER
    e = 0.5 * (_PAPER[0] + _PAPER[1])
    offs = np.array([[0.5, 0.5], [lo, 0.5], [hi, 0.5], [0.5, lo], [0.5, hi],
                     [e, 0.5], [1 - e, 0.5], [0.5, e], [0.5, 1 - e]])
    pts = (sq[:, None, :] + offs[None]).reshape(-1, 2)
    return pts, np.repeat(sq, len(offs), axis=0)


def _expected(uv: np.ndarray, pattern_size) -> np.ndarray:
    """What a board shows at board-plane points uv (M, 2) (corner units, (col, row)): 0 black, 1 white, −1 unknown.

    The squares cover [−1, cols] × [−1, rows]; a point nearer than ``_INNER`` to a square's edge
    is unknown (blur), so is one off the board except ``_PAPER`` beyond a side (not a corner),
    which is white paper.
    """
    cols, rows = pattern_size
    u, v = uv[:, 0], uv[:, 1]
    out = np.full(len(uv), -1, np.int8)
    fu, fv = u - np.floor(u), v - np.floor(v)
    inner = (np.minimum(fu, 1 - fu) >= _INNER - 1e-9) & (np.minimum(fv, 1 - fv) >= _INNER - 1e-9)
    on = (u > -1) & (u < cols) & (v > -1) & (v < rows)
    par = (np.floor(u).astype(int) + np.floor(v).astype(int)) % 2  # board square (floor(u)+1, floor(v)+1)
    out[on & inner] = np.where(par[on & inner] == 0, 0, 1)
    du = np.maximum(-1 - u, u - cols)  # > 0 beyond a side of the board
    dv = np.maximum(-1 - v, v - rows)
    paper_u = (du >= _PAPER[0] - 1e-9) & (du <= _PAPER[1] + 1e-9) & (v >= -1 + _INNER) & (v <= rows - _INNER)
    paper_v = (dv >= _PAPER[0] - 1e-9) & (dv <= _PAPER[1] + 1e-9) & (u >= -1 + _INNER) & (u <= cols - _INNER)
    out[paper_u | paper_v] = 1
    return out


def _grid_to_board(ij: np.ndarray, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rotation m (2, 2) and shift t (2,) with ids = ij @ m.T + t."""
    for m in _ROTATIONS:
        t = ids[0] - m @ ij[0]
        if np.array_equal(ij @ m.T + t, ids):
            return m, t
    raise ValueError("ids are not a rotation and shift of the grid")


def _contradicted(ij: np.ndarray, pts: np.ndarray, found: list[np.ndarray], pattern_size, gray: np.ndarray,
                  black: int) -> list[int]:
    """For each placement, how many squares around the grid the image contradicts.

    ij : (K, 2) grid positions (min 0), pts : (K, 2) px, found : placements (K, 2) ids. The
    sample points of :func:`_grid_samples` are put in the image by homographies of their nearest
    grid corners (:func:`aicalib_tf.detect.chessboard.lattice.predict_ids`); grey is normalised by the grid's own
    black and white squares (0 black, 1 white). A square is contradicted when a point the
    placement expects black reads above 0.6, or one it expects white below 0.4.
    """
    h, w = gray.shape
    par, centres = _square_centres({(int(i), int(j)): p for (i, j), p in zip(ij, pts)})
    vals = sample_bilinear(gray, centres)
    is_black = par == black
    blk, wht = np.median(vals[is_black]), np.median(vals[~is_black])
    if not wht > blk:  # no contrast to normalise by: the image contradicts nothing
        return [0] * len(found)
    ext = (int(ij[:, 0].max()) + 1, int(ij[:, 1].max()) + 1)
    grid_pts, squares = _grid_samples(ext)
    xy = predict_ids(ij, pts.astype(np.float64), grid_pts)
    view = np.all(np.isfinite(xy), axis=1)
    view[view] = (xy[view, 0] >= 2) & (xy[view, 0] <= w - 3) & (xy[view, 1] >= 2) & (xy[view, 1] <= h - 3)
    grid_pts, squares, xy = grid_pts[view], squares[view], xy[view]
    if len(xy) == 0:
        return [0] * len(found)
    t = (sample_bilinear(gray, xy) - blk) / (wht - blk)
    out = []
    for ids in found:
        m, sh = _grid_to_board(ij, ids)
        want = _expected(grid_pts @ m.T + sh, pattern_size)
        bad = ((want == 0) & (t > 0.6)) | ((want == 1) & (t < 0.4))
        out.append(len({tuple(s) for s in squares[bad].tolist()}))
    return out


def _border_sides(cells: dict, ext: tuple[int, int], gray: np.ndarray, black: int, contrast: float) -> dict:
    """Which sides of a grid are the board's outermost corner lines.

    cells : {(i, j): (2,) px} with i in [0, ext[0]), j in [0, ext[1]). black, contrast : from
    :func:`_square_colours`. Beyond the outermost line of inner corners a board has one more row of
    squares, then plain white paper. For each side, the line one step further out (L1) is
    extrapolated from the last grid lines, and each square between the last line and L1 is tested:
    the squares alternate black and white as the grid's colours predict, a black square stays black
    up to 0.2 step before L1, and ``BORDER_BEYOND`` of a step beyond L1 the paper is white
    (normalised grey > ``BORDER_T``). Each of these three greys is the mean of samples across the
    square (``_ACROSS``): one sample each let noise pass the next line of squares for paper. Were
    the board to go on, a black square would lie beyond each white one; an object in front would
    have to line up with L1 along the whole side to pass.
    A side is a border when at least two of its squares are tested, all pass, and at most a third
    of the squares that lie in the image could not be tested because a corner of the last line is
    missing there (hidden, say). Squares outside the image are not counted.
    Returns {(axis, sign): bool} for axis 0 (i) / 1 (j) and sign −1 (min side) / +1 (max side).
    """


    # size: the four sides of one test share the sampled profiles; a loop over them reads as one unit.
    h, w = gray.shape
    lo_xy, hi_xy = np.array([2.0, 2.0]), np.array([w - 3.0, h - 3.0])
    ij = np.array(list(cells.keys()), np.float64)
    xy = np.array(list(cells.values()), np.float64)
    hom, _ = cv2.findHomography(ij, xy, 0) if len(ij) >= 4 else (None, None)
    out = {}
    for axis in (0, 1):
        for sign in (-1, 1):
            e = 0 if sign < 0 else ext[axis] - 1

            def at(a, o):
                return cells.get((a, o) if axis == 0 else (o, a))

            ends, missing_in_view = {}, set()
            for o in range(ext[1 - axis]):
                p0, p1, p2 = at(e, o), at(e - sign, o), at(e - 2 * sign, o)
                if p0 is not None and p1 is not None:
                    ends[o] = (p0, 2 * p0 - p1 if p2 is None else 3 * p0 - 3 * p1 + p2)
                elif p0 is None and hom is not None:
                    cell = np.array([[e, o] if axis == 0 else [o, e]], np.float64).reshape(-1, 1, 2)
                    q = cv2.perspectiveTransform(cell, hom).reshape(2)
                    if np.all((q >= lo_xy) & (q <= hi_xy)):
                        missing_in_view.add(o)
            rows, failed = [], 0
            lo = min(e, e + sign)
            for o in range(ext[1 - axis] - 1):
                if o in ends and o + 1 in ends:
                    a = _ACROSS[:, None] * ends[o][0] + (1 - _ACROSS[:, None]) * ends[o + 1][0]  # (S, 2)
                    b = _ACROSS[:, None] * ends[o][1] + (1 - _ACROSS[:, None]) * ends[o + 1][1]
                    pts = np.concatenate([a + 0.5 * (b - a), a + 0.8 * (b - a), b + BORDER_BEYOND * (b - a)])
                    if np.all((pts >= lo_xy) & (pts <= hi_xy)):
                        rows.append((pts, (lo + o) % 2 == black))
                elif o in missing_in_view or o + 1 in missing_in_view:
                    failed += 1
            out[(axis, sign)] = False
            if len(rows) < 2 or FAILED_RATIO * failed > len(rows):
                continue
            # each depth's grey is the mean of the samples across the square (noise; data_gen hard seed 8 #75)
            vals = sample_bilinear(gray, np.concatenate([r[0] for r in rows])).reshape(-1, 3, len(_ACROSS)).mean(axis=2)
            is_black = np.array([r[1] for r in rows])
            if is_black.all() or not is_black.any():
                continue
            blk, wht = np.median(vals[is_black, 0]), np.median(vals[~is_black, 0])
            if wht - blk < 0.5 * contrast:
                continue
            t = (vals - blk) / (wht - blk)
            alternate = np.all(np.where(is_black, t[:, 0] < 0.5, t[:, 0] > 0.5))
            black_to_edge = np.all(t[is_black, 1] < 0.5)
            margin = np.all(t[:, 2] > BORDER_T)
            out[(axis, sign)] = bool(alternate and black_to_edge and margin)
    return out


def _board_keys(ids: np.ndarray, pattern_size) -> bytes:
    """One key per class of id sets that the board's symmetries map onto each other."""
    return min(f.astype(np.int32).tobytes() for f in symmetric_ids(ids, pattern_size))


def _placements(ij: np.ndarray, pattern_size, borders: dict, black: int | None) -> list[np.ndarray]:
    """Every (col, row) id assignment of a grid that fits the pattern and the evidence.

    ij : (K, 2) handed grid positions. An assignment rotates the grid by a multiple of 90° (keeping
    handedness) and shifts it inside the pattern; a side in ``borders`` marked True must land on
    the pattern's outermost line, and with ``black`` the grid's black squares must be the board's
    black squares (board square (c, r) is black when c + r is even, squares indexed from the
    corner-0 outer square). Returns a list of (K, 2) int id arrays.
    """
    cols, rows = pattern_size
    unit = np.array([[0, 0], [1, 0], [0, 1], [1, 1]])
    out = []
    for m in _ROTATIONS:
        cr = ij @ m.T
        base = cr.min(0)
        cr = cr - base
        a, b = cr.max(0) + 1
        if a > cols or b > rows:
            continue
        c0, r0 = (unit @ m.T - base).min(0)
        sides = []
        for (axis, sign), border in borders.items():
            if border:
                d = m @ (sign * np.eye(2, dtype=int)[axis])
                sides.append((0 if d[0] else 1, int(d[0] + d[1])))
        for oc in range(cols - a + 1):
            for orow in range(rows - b + 1):
                ok = all((oc == 0 if s < 0 else oc + a == cols) if ax == 0 else (orow == 0 if s < 0 else orow + b == rows)
                         for ax, s in sides)
                if ok and black is not None and (c0 + oc + r0 + orow) % 2 != black:
                    ok = False
                if ok:
                    out.append(cr + np.array([oc, orow]))
    return out


def place_cells(cells: dict, pattern_size, gray: np.ndarray) -> np.ndarray | None:
    """(K, 2) int board ids of the cells (in ``cells`` order), or None when the evidence leaves them open."""
    cols, rows = pattern_size
    ij = np.array(list(cells.keys()))
    ij = ij - ij.min(0)
    pts = np.array([v[0] for v in cells.values()])
    cells_xy = {(int(i), int(j)): p for (i, j), p in zip(ij, pts)}
    ext = (int(ij[:, 0].max()) + 1, int(ij[:, 1].max()) + 1)
    black, contrast = _square_colours(cells_xy, gray)
    if black is None and (cols + rows) % 2 == 1:
        return None  # the colours must tell 180° apart, as for a full board
    borders = _border_sides(cells_xy, ext, gray, black, contrast) if black is not None else {}
    found = _placements(ij, pattern_size, borders, black)
    if not found:
        return None
    keys = [_board_keys(f, pattern_size) for f in found]
    if len(set(keys)) > 1 and black is not None:  # draw each placement around the grid: the image may tell
        bad = _contradicted(ij, pts, found, pattern_size, gray, black)
        least = min(bad)
        margin = RENDER_MIN if least == 0 else RENDER_MARGIN
        clean = {k for k, b in zip(keys, bad) if b == least}
        if len(clean) == 1 and all(b >= least + margin for k, b in zip(keys, bad) if k not in clean):
            found = [f for k, f in zip(keys, found) if k in clean]
            keys = [k for k in keys if k in clean]
    if len(set(keys)) != 1:
        return None
    ids = found[0]
    if black is None or (cols + rows) % 2 == 0:
        ids = choose_reading(ids, pts, pattern_size)
    return ids
