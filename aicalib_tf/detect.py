"""Chessboard detection with the CNN: image -> ordered board (``python -m aicalib_tf.detect``).

Pipeline: CNN corner weights -> peaks (:mod:`aicalib_tf.inference`) -> saddle-point refinement
on the original image (:mod:`aicalib_tf.refine`) -> grid assembly (:mod:`aicalib_tf.grid`) ->
ordered board.

Order of a full board (OpenCV's, row-major: index = r·cols + c). A board read from the front
keeps its handedness, so only its rotations are ambiguous: 180°, and 90° too for a square
pattern. They are resolved like ``cv2.findChessboardCorners`` (measured on data_gen boards):

* cols + rows odd (e.g. 9x6): the board's colours tell 180° apart. Corner 0 is the one whose
  outer diagonal square is black (the square beyond it, away from corners 1 and ``cols``). It is
  decided by a vote of all inner squares, so it never samples outside the board.
* otherwise (both even or both odd): the reading whose last row starts lowest in the image
  relative to corner 0 (largest y[(rows−1)·cols] − y[0]). OpenCV reverses its order when that
  difference is negative; the two agree whenever one reading has it positive and the other negative.
* square patterns: of the four rotations, the one with the largest (x[cols−1] − x[0]) +
  (y[(rows−1)·cols] − y[0]): rows run most nearly left to right and top to bottom.

Partial boards (``pattern_size`` given, no full board found; ``complete=False``). A board cut by
the frame or hidden in part by an object in front comes back with the corners that are seen, in
row-major order of their ids, each id the corner's (col, row) on the full board, correct up to
the board's symmetry as above. Ids are only returned when the image decides them; otherwise no
board (a miss rather than a wrong id). The grid is first grown by partly visible lines and across
gaps (corners found where the lattice predicts them, by saddle fit and ring test), then every
placement of it on the pattern (a 90° turn keeping handedness, and a shift) is checked against
three kinds of evidence:

* extent: the grid fits inside the pattern; spanning all ``cols`` (or ``rows``) corners of an axis
  fixes that axis;
* borders: beyond the board's outermost corner line lies one more row of squares, then white
  paper. A grid side whose next line, extrapolated, has alternating squares before it and white
  paper just beyond it all along (and is not mostly hidden) is the pattern's outermost line on
  that side;
* colours: the grid's black squares must be the board's black squares (board square (c, r), the
  one between corners (c−1, r−1) and (c, r), is black when c + r is even, as on a full board).
  This settles 180° when cols + rows is odd, as for full boards; the colours must be readable then.

The ids are returned when the placements left agree up to the board's symmetry; where that
leaves a choice (cols + rows even), the reading whose rows run most nearly downwards (square
patterns: rows right and columns down) is taken, the full-board geometric rule applied to the
mean steps. The pattern's missing corners are then looked for where the placed ones predict them
(a second time with a 2 px window and a small ring, for corners beside an object in front),
corners off their neighbours' lattice by more than ``MAX_RESIDUAL`` of a step are dropped (at most
a tenth of them, else no board), and a board with X-junctions one step outside the pattern is
dropped. If every corner is found, the board is complete and ordered by the full-board rules.
A view of one corner of a non-square board alone (two sides cut by the frame) cannot be placed:
the visible sides could be the long or the short ones.

Without ``pattern_size``, the largest grid with every corner found is returned, complete, its
size taken as the pattern; ids are relative to that grid, in the full-board order. A grid with
positions missing (a line cut by the frame that kept a few corners, say) counts by its largest
filled rectangle (:func:`aicalib_tf.grid.full_subgrid`), so a few extra corners never hide it,
after corners off their neighbours' lattice are dropped as for partial boards.
:func:`find_chessboard_corners` reports full boards only, like OpenCV.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .grid import Grid, assemble_grids, full_subgrid
from .io import load_image
from .refine import refine_saddle

__all__ = ["Detection", "detect_corners", "find_chessboard_corners", "order_full_board"]


@dataclass(frozen=True)
class Detection:
    """A detected chessboard.

    corners : (N, 2) float32 (x, y) px, in OpenCV order when ``complete``; a partial board's are
        ordered by id (row-major), with the unseen corners left out.
    ids : (N, 2) int32, (col, row) of each corner on the board (see the module docstring for a
        partial board's).
    scores : (N,) float32 CNN corner weights in [0, 1]; 0 for a corner the CNN missed that was
        recovered where the grid predicts one (saddle fit and ring test on the image).
    pattern_size : (cols, rows) inner corners (the found grid's size when none was given).
    complete : every corner of ``pattern_size`` is present.
    image_size : (width, height) px.
    """

    corners: np.ndarray
    ids: np.ndarray
    scores: np.ndarray
    pattern_size: tuple[int, int] | None
    complete: bool
    image_size: tuple[int, int]

    @property
    def found(self) -> bool:
        return len(self.corners) > 0


_DEFAULT_MODEL = None
MAX_CANDIDATES = 3000  # a 20x15 board has 300 corners; more candidates are clutter


def _default_model():
    global _DEFAULT_MODEL
    if _DEFAULT_MODEL is None:
        from .model import load_model

        _DEFAULT_MODEL = load_model("default")
    return _DEFAULT_MODEL


class _Smoothed:
    """The image smoothed for each refinement radius r (σ = 0.4·r), made once per image on demand."""

    def __init__(self, gray: np.ndarray):
        self.gray, self.cache = gray, {}

    def __getitem__(self, r: int) -> np.ndarray:
        if r not in self.cache:
            self.cache[r] = cv2.GaussianBlur(self.gray, (0, 0), 0.4 * r)
        return self.cache[r]


def _radius(spacing: np.ndarray) -> np.ndarray:
    """Refinement window half-size (px) that fits inside squares of ``spacing`` px: 2..5."""
    return np.clip(np.round(0.45 * np.asarray(spacing, np.float64)), 2, 5).astype(int)


def _refine(smoothed: _Smoothed, pts: np.ndarray, spacing: np.ndarray, max_shift: np.ndarray | None = None):
    """Saddle refinement with a window that fits inside the local squares.

    pts : (N, 2). spacing : (N,) px, the local corner spacing. max_shift : (N,) px or None.
    Returns refined (N, 2) float32 and ok (N,) bool.
    """
    radius = _radius(spacing)
    out = np.asarray(pts, np.float32).copy()
    ok = np.zeros(len(pts), bool)
    for r in np.unique(radius):
        sel = radius == r
        out[sel], ok[sel] = refine_saddle(smoothed[int(r)], pts[sel], sigma=0.0, radius=int(r))
    if max_shift is not None:
        ok &= np.linalg.norm(out - pts, axis=1) <= max_shift
    return out, ok


def _nearest_spacing(pts: np.ndarray) -> np.ndarray:
    """(N,) distance from each point to its nearest other point (px); 8 when alone."""
    if len(pts) < 2:
        return np.full(len(pts), 8.0)
    d2 = ((pts[:, None, :] - pts[None, :, :]) ** 2).sum(-1)
    np.fill_diagonal(d2, np.inf)
    return np.sqrt(d2.min(axis=1))


def _dedupe(pts: np.ndarray, scores: np.ndarray, min_distance: float = 1.5) -> np.ndarray:
    """Indices of points to keep: of points closer than ``min_distance`` px, only the strongest."""
    order = np.argsort(-scores, kind="stable")
    d2 = ((pts[order, None, :] - pts[None, order, :]) ** 2).sum(-1)
    close = d2 < min_distance**2
    alive = np.ones(len(order), bool)
    for a in range(len(order)):
        if alive[a]:
            close_after = close[a].copy()
            close_after[: a + 1] = False
            alive &= ~close_after
    return order[alive]


_RING = np.stack([np.cos(np.linspace(0, 2 * np.pi, 16, endpoint=False)),
                  np.sin(np.linspace(0, 2 * np.pi, 16, endpoint=False))], 1)


def ring_symmetry(gray: np.ndarray, pts: np.ndarray, radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """X-junction evidence on a ring around each point.

    An X-junction is point-symmetric (I(p + d) = I(p − d)) and its ring alternates two dark and
    two bright arcs. gray : (H, W) float32. pts : (M, 2) px. radius : (M,) px.
    Returns amplitude (M,) (mean |I − mean| on the ring) and asymmetry (M,) (mean |I(θ) − I(θ + π)|).
    """
    xy = pts[:, None, :] + radius[:, None, None] * _RING[None]
    ring = cv2.remap(gray, xy[..., 0].astype(np.float32), xy[..., 1].astype(np.float32), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)
    amp = np.abs(ring - ring.mean(axis=1, keepdims=True)).mean(axis=1)
    asym = np.abs(ring[:, :8] - ring[:, 8:]).mean(axis=1)
    return amp, asym


def _proposer(smoothed: _Smoothed, ring_image: np.ndarray, ref_amp: float):
    """Look for a corner at each grid prediction: saddle refinement plus the ring test."""

    def propose(pred: np.ndarray, step: np.ndarray) -> np.ndarray:
        out = np.full(pred.shape, np.nan)
        h, w = ring_image.shape
        inside = (pred[:, 0] >= 1) & (pred[:, 0] <= w - 2) & (pred[:, 1] >= 1) & (pred[:, 1] <= h - 2)
        k = np.flatnonzero(inside)
        if len(k) == 0:
            return out
        q, ok = _refine(smoothed, pred[k], step[k], max_shift=0.3 * step[k])
        amp, asym = ring_symmetry(ring_image, q.astype(np.float64), 0.3 * step[k])
        ok &= (amp >= 0.3 * ref_amp) & (asym <= 0.5 * amp)  # a T-junction at a board edge has asym ≈ 1.3·amp
        out[k[ok]] = q[ok]
        return out

    def tight(pred: np.ndarray, step: np.ndarray) -> np.ndarray:
        """``propose`` for a corner beside an object in front: the smallest fit window (2 px) and a
        ring of 0.15 step (at least 2 px), and the corner within 0.1 step of the prediction."""
        out = np.full(pred.shape, np.nan)
        h, w = ring_image.shape
        inside = (pred[:, 0] >= 3) & (pred[:, 0] <= w - 4) & (pred[:, 1] >= 3) & (pred[:, 1] <= h - 4)
        k = np.flatnonzero(inside)
        if len(k) == 0:
            return out
        q, ok = _refine(smoothed, pred[k], np.full(len(k), 4.0), max_shift=0.1 * step[k])
        amp, asym = ring_symmetry(ring_image, q.astype(np.float64), np.maximum(2.0, 0.15 * step[k]))
        ok &= (amp >= 0.3 * ref_amp) & (asym <= 0.5 * amp)
        out[k[ok]] = q[ok]
        return out

    propose.tight = tight
    return propose


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
    rr, cc = np.meshgrid(np.arange(1, rows), np.arange(1, cols), indexing="ij")
    grey = cv2.remap(gray, centres[..., 0].astype(np.float32), centres[..., 1].astype(np.float32), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)
    even = (rr + cc) % 2 == 0
    return float(grey[~even].mean() - grey[even].mean())


def order_full_board(corners: np.ndarray, pattern_size: tuple[int, int], gray: np.ndarray) -> np.ndarray:
    """Reorder a full board's corners (any admissible reading) by the module's rule.

    corners : (cols·rows, 2) in some row-major reading of the board with the right handedness.
    Returns the (cols·rows, 2) corners in the rule's order.
    """
    return corners[_reading(corners, pattern_size, gray)]


def _reading(corners: np.ndarray, pattern_size: tuple[int, int], gray: np.ndarray) -> np.ndarray:
    """The board symmetry (a (cols·rows,) index permutation) that puts ``corners`` in the rule's order."""
    from .metrics import board_symmetries

    cols, rows = pattern_size
    best, best_key = None, None
    for perm in board_symmetries(pattern_size):
        c = corners[perm]
        dy = c[(rows - 1) * cols, 1] - c[0, 1]
        dx = c[cols - 1, 0] - c[0, 0]
        if (cols + rows) % 2 == 1 and cols != rows:
            key = (_parity_contrast(c, pattern_size, gray), 0.0)
        elif cols == rows:
            key = (float(dx + dy), 0.0)
        else:
            key = (float(dy), float(dx))
        if best_key is None or key > best_key:
            best, best_key = perm, key
    return best


def _handed(grid_ij: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Flip j if needed so that the i and j directions have the image's handedness (x right, y down).

    A board seen from the front keeps its handedness, so the board's (col, row) axes must too.
    """
    a = np.concatenate([grid_ij.astype(np.float64), np.ones((len(grid_ij), 1))], axis=1)
    (u, v, _), *_ = np.linalg.lstsq(a, pts.astype(np.float64), rcond=None)
    if u[0] * v[1] - u[1] * v[0] < 0:
        return np.stack([grid_ij[:, 0], grid_ij[:, 1].max() - grid_ij[:, 1]], 1)
    return grid_ij


def _board_from_grid(grid: Grid, scores, pattern_size, gray, size) -> Detection | None:
    ij = _handed(grid.ij, grid.points)
    a, b = grid.shape
    if pattern_size is None:
        cols, rows = a, b
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
    perm = _reading(corners, (cols, rows), gray)
    ids = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), -1).reshape(-1, 2).astype(np.int32)
    return Detection(corners[perm], ids, sc[perm], (cols, rows), True, size)


# ---- partial boards ---------------------------------------------------------------------------

# handedness-preserving maps of grid (i, j) onto board (col, row): 0°, 90°, 180°, 270°
_ROTATIONS = tuple(np.array(m) for m in ([[1, 0], [0, 1]], [[0, -1], [1, 0]], [[-1, 0], [0, -1]], [[0, 1], [-1, 0]]))
MIN_PARTIAL = 9  # fewest corners of a partial board (a grid's seed is 3x3)
BORDER_BEYOND = 0.12  # where the margin is looked for: this fraction of a step beyond the last line
BORDER_T = 0.7  # white-normalised grey the margin must reach there (0 black square, 1 white square)
FAILED_RATIO = 2  # a border side: untested (corner missing in view) squares at most 1/FAILED_RATIO of the tested
MAX_RESIDUAL = 0.08  # of a step: how far a corner of a partial board may be from its neighbours' lattice


def _sample(gray: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Bilinear grey values (M,) at points xy (M, 2) px."""
    xy = np.asarray(xy, np.float32).reshape(-1, 1, 2)
    return cv2.remap(gray, xy[..., 0], xy[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).ravel()


def _square_colours(cells: dict, gray: np.ndarray):
    """Which grid squares are black, from the grey at their centres.

    cells : {(i, j): (2,) px}. Grid square (i, j) lies between corners (i, j) and (i+1, j+1).
    Returns (black, contrast): black is the parity of i + j of the black squares (0 or 1), or None
    when the squares do not split into two clearly different colours; contrast is white − black grey.
    """
    keys, centres = [], []
    for (i, j), p in cells.items():
        q = [cells.get(c) for c in ((i + 1, j), (i, j + 1), (i + 1, j + 1))]
        if all(v is not None for v in q):
            keys.append(i + j)
            centres.append(0.25 * (p + q[0] + q[1] + q[2]))
    if len(keys) < 2:
        return None, 0.0
    par = np.array(keys) % 2
    vals = _sample(gray, np.array(centres))
    if par.min() == par.max():
        return None, 0.0
    m0, m1 = vals[par == 0].mean(), vals[par == 1].mean()
    black = 0 if m0 < m1 else 1
    agree = np.mean((vals < 0.5 * (m0 + m1)) == (par == black))
    contrast = abs(m1 - m0)
    if agree < 0.9 or contrast < 0.08:
        return None, contrast
    return black, contrast


def _border_sides(cells: dict, ext: tuple[int, int], gray: np.ndarray, black: int, contrast: float) -> dict:
    """Which sides of a grid are the board's outermost corner lines.

    cells : {(i, j): (2,) px} with i in [0, ext[0]), j in [0, ext[1]). black, contrast : from
    :func:`_square_colours`. Beyond the outermost line of inner corners a board has one more row of
    squares, then plain white paper. For each side, the line one step further out (L1) is
    extrapolated from the last grid lines, and each square between the last line and L1 is tested:
    the squares alternate black and white as the grid's colours predict, a black square stays black
    up to 0.2 step before L1, and ``BORDER_BEYOND`` of a step beyond L1 the paper is white
    (normalised grey > ``BORDER_T``). Were the board to go on, a black square would lie beyond each
    white one; an object in front would have to line up with L1 along the whole side to pass.
    A side is a border when at least two of its squares are tested, all pass, and at most a third
    of the squares that lie in the image could not be tested because a corner of the last line is
    missing there (hidden, say). Squares outside the image are not counted.
    Returns {(axis, sign): bool} for axis 0 (i) / 1 (j) and sign −1 (min side) / +1 (max side).
    """
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
                    a = 0.5 * (ends[o][0] + ends[o + 1][0])
                    b = 0.5 * (ends[o][1] + ends[o + 1][1])
                    pts = np.stack([a + 0.5 * (b - a), a + 0.8 * (b - a), b + BORDER_BEYOND * (b - a)])
                    if np.all((pts >= lo_xy) & (pts <= hi_xy)):
                        rows.append((pts, (lo + o) % 2 == black))
                elif o in missing_in_view or o + 1 in missing_in_view:
                    failed += 1
            out[(axis, sign)] = False
            if len(rows) < 2 or FAILED_RATIO * failed > len(rows):
                continue
            vals = _sample(gray, np.concatenate([r[0] for r in rows])).reshape(-1, 3)
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
    cols, rows = pattern_size
    c, r = ids[:, 0], ids[:, 1]
    forms = [np.stack([c, r], 1), np.stack([cols - 1 - c, rows - 1 - r], 1)]
    if cols == rows:
        forms += [np.stack([rows - 1 - r, c], 1), np.stack([r, cols - 1 - c], 1)]
    return min(f.astype(np.int32).tobytes() for f in forms)


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


def _steps(ids: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean image displacement (px) per +1 column and per +1 row, by an affine fit."""
    a = np.concatenate([ids.astype(np.float64), np.ones((len(ids), 1))], axis=1)
    (u, v, _), *_ = np.linalg.lstsq(a, pts.astype(np.float64), rcond=None)
    return u, v


def _choose_reading(ids: np.ndarray, pts: np.ndarray, pattern_size) -> np.ndarray:
    """Of the symmetric readings of a placement, the one the full-board geometric rule prefers.

    Only used when colours cannot tell them apart (cols + rows even): the reading whose rows run
    most nearly downwards (largest y step per row; then x step per column); for square patterns,
    the largest x step per column + y step per row.
    """
    cols, rows = pattern_size
    c, r = ids[:, 0], ids[:, 1]
    forms = [np.stack([c, r], 1), np.stack([cols - 1 - c, rows - 1 - r], 1)]
    if cols == rows:
        forms += [np.stack([rows - 1 - r, c], 1), np.stack([r, cols - 1 - c], 1)]

    def key(f):
        u, v = _steps(f, pts)
        return (float(u[0] + v[1]), 0.0) if cols == rows else (float(v[1]), float(u[0]))

    return max(forms, key=key)


def _in_view(pts: np.ndarray, size) -> np.ndarray:
    w, h = size
    return np.all(np.isfinite(pts), axis=1) & (pts[:, 0] >= 1) & (pts[:, 0] <= w - 2) & (pts[:, 1] >= 1) & (pts[:, 1] <= h - 2)


def _take(cells: dict, new: dict, pred: np.ndarray, step: np.ndarray, got: np.ndarray) -> int:
    """Add proposals ``got`` (M, 2, NaN where none) for cells ``new`` (M keys) unless they repeat a point."""
    pts = np.array([v[0] for v in cells.values()])
    added = 0
    for key, p, s, q in zip(new, pred, step, got):
        if not np.all(np.isfinite(q)) or np.linalg.norm(q - p) > 0.3 * s:
            continue
        if np.min(np.linalg.norm(pts - q, axis=1)) < 0.5 * s:
            continue
        cells[key] = (q.astype(np.float64), 0.0)
        pts = np.vstack([pts, q])
        added += 1
    return added


def _grow_cut_lines(cells: dict, propose, limit: int, size) -> None:
    """Grow a grid by lines that are partly out of the image or hidden.

    Grid assembly adds a line when half of its predicted corners are found; at the image frame or
    beside an object most of them may not be visible. Here a line one step beyond each side is
    added when at least two of its predicted corners are found (saddle fit and ring test, see
    :func:`_proposer`), or one where at most two lie in the image. The grid never grows past
    ``limit`` positions on an axis. cells : {(i, j): (point (2,), score)}, changed in place.
    """
    for _ in range(2 * limit):
        grown = False
        for axis in (0, 1):
            for sign in (-1, 1):
                keys = np.array(list(cells.keys()))
                if keys[:, axis].max() - keys[:, axis].min() + 1 >= limit:
                    continue
                e = keys[:, axis].max() if sign > 0 else keys[:, axis].min()
                new, pred, step = [], [], []
                for o in np.unique(keys[:, 1 - axis]):
                    def at(a, o=int(o)):
                        v = cells.get((int(a), o) if axis == 0 else (o, int(a)))
                        return None if v is None else v[0]
                    p0, p1, p2 = at(e), at(e - sign), at(e - 2 * sign)
                    if p0 is None or p1 is None:
                        continue
                    new.append((int(e + sign), int(o)) if axis == 0 else (int(o), int(e + sign)))
                    pred.append(2 * p0 - p1 if p2 is None else 3 * p0 - 3 * p1 + p2)
                    step.append(np.linalg.norm(p0 - p1))
                if not new:
                    continue
                pred, step = np.array(pred), np.array(step)
                view = _in_view(pred, size)
                got = propose(pred, step)
                ok = np.all(np.isfinite(got), axis=1) & (np.linalg.norm(got - pred, axis=1) <= 0.3 * step)
                need = 1 if view.sum() <= 2 else 2
                if ok.sum() >= need:
                    trial = dict(cells)
                    if _take(trial, new, pred, step, np.where(ok[:, None], got, np.nan)) >= need:
                        cells.clear()
                        cells.update(trial)
                        grown = True
        _fill_cells(cells, propose)
        if not grown:
            return


def _fill_cells(cells: dict, propose, passes: int = 3) -> None:
    """Look for the corners of missing cells inside a grid's extent, predicted by parallelograms."""
    for _ in range(passes):
        keys = np.array(list(cells.keys()))
        (i0, j0), (i1, j1) = keys.min(0), keys.max(0)
        new, pred, step = [], [], []
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                if (i, j) in cells:
                    continue
                preds = []
                for di in (-1, 1):
                    for dj in (-1, 1):
                        a, b, c = cells.get((i + di, j)), cells.get((i, j + dj)), cells.get((i + di, j + dj))
                        if a is not None and b is not None and c is not None:
                            preds.append((a[0] + b[0] - c[0], min(np.linalg.norm(a[0] - c[0]), np.linalg.norm(b[0] - c[0]))))
                if preds:
                    new.append((i, j))
                    pred.append(np.mean([p for p, _ in preds], axis=0))
                    step.append(min(s for _, s in preds))
        if not new:
            return
        pred, step = np.array(pred), np.array(step)
        if _take(cells, new, pred, step, propose(pred, step)) == 0:
            return


def _reach(cells: dict, propose, limit: int, size, passes: int = 3, radius: int = 3) -> None:
    """Look for corners of the lattice across gaps (an object in front, a missed line).

    Every missing cell within ``radius`` steps of the grid, inside a ``limit`` × ``limit`` window
    around it, is predicted by a homography of its 12 nearest known cells and looked for there.
    cells : {(i, j): (point (2,), score)}, changed in place.
    """
    for _ in range(passes):
        ij = np.array(list(cells.keys()))
        pts = np.array([v[0] for v in cells.values()])
        lo, hi = ij.min(0), ij.max(0)
        span = limit - (hi - lo + 1)  # room left on each axis
        a0, a1 = lo - np.minimum(span, radius), hi + np.minimum(span, radius)
        ii, jj = np.meshgrid(np.arange(a0[0], a1[0] + 1), np.arange(a0[1], a1[1] + 1), indexing="ij")
        cand = np.stack([ii.ravel(), jj.ravel()], 1)
        have = set(map(tuple, ij.tolist()))
        cand = np.array([c for c in cand.tolist() if tuple(c) not in have])
        if len(cand) == 0:
            return
        dist = np.abs(cand[:, None, :] - ij[None, :, :]).max(-1).min(1)
        cand = cand[dist <= radius]
        if len(cand) == 0:
            return
        pred = _predict_ids(ij, pts, cand)
        view = _in_view(pred, size)
        cand, pred = cand[view], pred[view]
        if len(cand) == 0:
            return
        step = _local_step(ij, pts, pred)
        got = propose(pred, step)
        hit = np.all(np.isfinite(got), axis=1) & (np.linalg.norm(got - pred, axis=1) <= 0.3 * step)
        # a corner outside the grid's extent needs a found neighbour that is outside too: one lone
        # junction (an object's corner against a square, say) must not stretch the grid
        outside = hit & np.any((cand < lo) | (cand > hi), axis=1)
        pair = np.abs(cand[:, None, :] - cand[None, outside, :]).max(-1) == 1  # (M, #outside)
        hit &= ~outside | pair.any(axis=1)
        cand, pred, step, got = cand[hit], pred[hit], step[hit], got[hit]
        added = 0
        for c, p, s, q in zip(cand, pred, step, got):
            ij_now = np.array(list(cells.keys()))
            lo_n, hi_n = np.minimum(ij_now.min(0), c), np.maximum(ij_now.max(0), c)
            if np.any(hi_n - lo_n + 1 > limit):
                continue
            added += _take(cells, [(int(c[0]), int(c[1]))], p[None], np.array([s]), q[None])
        if not added:
            return


def _place_cells(cells: dict, pattern_size, gray: np.ndarray) -> np.ndarray | None:
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
    if not found or len({_board_keys(f, pattern_size) for f in found}) != 1:
        return None
    ids = found[0]
    if black is None or (cols + rows) % 2 == 0:
        ids = _choose_reading(ids, pts, pattern_size)
    return ids


def _homographies(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Least-squares homographies, many at once: src, dst (M, K, 2) with K >= 4 -> (M, 3, 3).

    The linear (DLT, h33 = 1) fit on coordinates centred and scaled per set; a degenerate set
    gives NaNs.
    """
    def norm(p):
        mean = p.mean(axis=1, keepdims=True)
        scale = np.sqrt(2.0) / np.maximum(np.sqrt(((p - mean) ** 2).sum(-1)).mean(axis=1), 1e-12)[:, None, None]
        t = np.zeros((len(p), 3, 3))
        t[:, 0, 0] = t[:, 1, 1] = scale[:, 0, 0]
        t[:, :2, 2] = -mean[:, 0, :] * scale[:, 0, :]
        t[:, 2, 2] = 1.0
        return (p - mean) * scale, t

    (s, ts), (d, td) = norm(np.asarray(src, np.float64)), norm(np.asarray(dst, np.float64))
    m, k = s.shape[:2]
    x, y, u, v = s[..., 0], s[..., 1], d[..., 0], d[..., 1]
    one, zero = np.ones_like(x), np.zeros_like(x)
    rows_u = np.stack([x, y, one, zero, zero, zero, -u * x, -u * y], -1)
    rows_v = np.stack([zero, zero, zero, x, y, one, -v * x, -v * y], -1)
    a = np.concatenate([rows_u, rows_v], axis=1)  # (M, 2K, 8)
    rhs = np.concatenate([u, v], axis=1)  # (M, 2K)
    ata = a.transpose(0, 2, 1) @ a
    atb = (a.transpose(0, 2, 1) @ rhs[..., None])[..., 0]
    h = np.full((m, 9), np.nan)
    ok = np.abs(np.linalg.det(ata)) > 1e-12
    if ok.any():
        h[ok, :8] = np.linalg.solve(ata[ok], atb[ok][..., None])[..., 0]
        h[ok, 8] = 1.0
    hn = h.reshape(m, 3, 3)
    return np.linalg.inv(td) @ hn @ ts


def _predict_ids(ids: np.ndarray, pts: np.ndarray, want: np.ndarray, k: int = 12) -> np.ndarray:
    """Image positions (M, 2) of board ids ``want`` (M, 2), each from a homography of its k nearest known ids.

    NaN rows where fewer than 4 ids are known or the fit is degenerate.
    """
    want = np.asarray(want, np.float64).reshape(-1, 2)
    if len(ids) < 4 or len(want) == 0:
        return np.full((len(want), 2), np.nan)
    d2 = ((want[:, None, :] - ids[None, :, :]) ** 2).sum(-1)
    near = np.argsort(d2, axis=1, kind="stable")[:, : min(k, len(ids))]
    hom = _homographies(ids[near].astype(np.float64), pts[near].astype(np.float64))
    q = hom @ np.concatenate([want, np.ones((len(want), 1))], axis=1)[..., None]
    return q[:, :2, 0] / q[:, 2:, 0]


def _local_step(ids: np.ndarray, pts: np.ndarray, want_xy: np.ndarray) -> np.ndarray:
    """(M,) px corner spacing near each position: the nearest known corner's distance to its nearest one."""
    d2 = ((pts[:, None, :] - pts[None, :, :]) ** 2).sum(-1)
    np.fill_diagonal(d2, np.inf)
    spacing = np.sqrt(d2.min(axis=1))
    near = np.argmin(((want_xy[:, None, :] - pts[None, :, :]) ** 2).sum(-1), axis=1)
    return spacing[near]


def _complete(ids: np.ndarray, pts: np.ndarray, sc: np.ndarray, pattern_size, propose, size, passes: int = 3):
    """Look for the pattern's missing corners where the placed ones predict them (around objects in front).

    Returns (ids, pts, sc, tight): tight (N,) bool marks corners found by ``propose.tight`` only.
    """
    cols, rows = pattern_size
    tight = np.zeros(len(ids), bool)
    for _ in range(passes):
        have = set(map(tuple, ids.tolist()))
        want = np.array([(c, r) for r in range(rows) for c in range(cols) if (c, r) not in have])
        if len(want) == 0:
            break
        pred = _predict_ids(ids, pts, want)
        view = _in_view(pred, size)
        if not view.any():
            break
        want, pred = want[view], pred[view]
        step = _local_step(ids, pts, pred)
        got = propose(pred, step)
        ok = np.all(np.isfinite(got), axis=1) & (np.linalg.norm(got - pred, axis=1) <= 0.3 * step)
        by_tight = np.zeros(len(ok), bool)
        if (~ok).any() and hasattr(propose, "tight"):  # beside an object in front
            miss = np.flatnonzero(~ok)
            got[miss] = propose.tight(pred[miss], step[miss])
            ok[miss] = by_tight[miss] = np.all(np.isfinite(got[miss]), axis=1)
        d_old = np.sqrt(((got[:, None, :] - pts[None, :, :]) ** 2).sum(-1)).min(axis=1) if ok.any() else None
        if ok.any():
            ok &= d_old >= 0.5 * step
        if not ok.any():
            break
        ids = np.concatenate([ids, want[ok]])
        pts = np.concatenate([pts, got[ok]])
        sc = np.concatenate([sc, np.zeros(int(ok.sum()), np.float32)])
        tight = np.concatenate([tight, by_tight[ok]])
    return ids, pts, sc, tight


def _lattice_residuals(ids: np.ndarray, pts: np.ndarray, k: int = 8) -> np.ndarray:
    """(N,) distance of each corner from where its k nearest other corners predict it, in local steps."""
    n = len(ids)
    d2 = ((pts[:, None, :] - pts[None, :, :]) ** 2).sum(-1)
    np.fill_diagonal(d2, np.inf)
    step = np.sqrt(d2.min(axis=1))
    if n < 5:
        return np.zeros(n)
    di = ((ids[:, None, :] - ids[None, :, :]) ** 2).sum(-1).astype(np.float64)
    np.fill_diagonal(di, np.inf)  # leave each corner out of its own fit
    near = np.argsort(di, axis=1, kind="stable")[:, : min(k, n - 1)]
    hom = _homographies(ids[near].astype(np.float64), pts[near].astype(np.float64))
    q = hom @ np.concatenate([ids.astype(np.float64), np.ones((n, 1))], axis=1)[..., None]
    pred = q[:, :2, 0] / q[:, 2:, 0]
    res = np.linalg.norm(pred - pts, axis=1) / step
    return np.where(np.isfinite(res), res, 0.0)


def _drop_outliers(ids, pts, sc, free=None, max_residual: float = MAX_RESIDUAL):
    """Drop corners off the lattice of their neighbours (e.g. pulled by the edge of an object in front).

    The worst corner goes first, until every residual (:func:`_lattice_residuals`) is at most
    ``max_residual`` local steps. A board that would lose more than a tenth of its other corners
    (at least 2) this way is not a clean lattice: None. free : (N,) bool, corners whose loss does
    not count (found by the tight test beside an object). Returns the kept (ids, pts, sc) or None.
    """
    free = np.zeros(len(ids), bool) if free is None else np.asarray(free, bool)
    budget = max(2, int((~free).sum()) // 10)
    while len(ids) >= MIN_PARTIAL:
        res = _lattice_residuals(ids, pts)
        worst = int(np.argmax(res))
        if res[worst] <= max_residual:
            return ids, pts, sc
        if not free[worst]:
            budget -= 1
            if budget < 0:
                return None
        keep = np.arange(len(ids)) != worst
        ids, pts, sc, free = ids[keep], pts[keep], sc[keep], free[keep]
    return None


def _corners_beyond(ids: np.ndarray, pts: np.ndarray, pattern_size, propose, size) -> int:
    """How many X-junctions lie one step outside the pattern, where a placed board has none."""
    cols, rows = pattern_size
    ring = [(c, -1) for c in range(-1, cols + 1)] + [(c, rows) for c in range(-1, cols + 1)]
    ring += [(-1, r) for r in range(rows)] + [(cols, r) for r in range(rows)]
    want = np.array(ring)
    pred = _predict_ids(ids, pts, want)
    view = _in_view(pred, size)
    if not view.any():
        return 0
    pred = pred[view]
    step = _local_step(ids, pts, pred)
    got = propose(pred, step)
    return int((np.all(np.isfinite(got), axis=1) & (np.linalg.norm(got - pred, axis=1) <= 0.3 * step)).sum())


def _partial_board(grids: list[Grid], scores, pattern_size, gray, size, propose) -> Detection | None:
    """The largest grid whose place on the board the image decides, as an incomplete board.

    Each grid (largest first) is grown by partly visible lines, placed on the pattern
    (:func:`_place_cells`); the pattern's missing corners are then looked for where the placed ones
    predict them, and the board is dropped if X-junctions show up one step outside the pattern.
    """
    if propose is None:
        return None
    cols, rows = pattern_size
    for grid in grids:
        if len(grid) < MIN_PARTIAL:
            continue
        ij = _handed(grid.ij, grid.points)
        sc = np.where(grid.index >= 0, scores[np.maximum(grid.index, 0)], 0.0)
        cells = {(int(i), int(j)): (np.asarray(p, np.float64), float(s)) for (i, j), p, s in zip(ij, grid.points, sc)}
        _grow_cut_lines(cells, propose, max(pattern_size) + 1, size)
        _reach(cells, propose, max(pattern_size) + 1, size)
        ids = _place_cells(cells, pattern_size, gray)
        if ids is None:
            continue
        pts = np.array([v[0] for v in cells.values()])
        sc = np.array([v[1] for v in cells.values()], np.float32)
        ids, pts, sc, tight = _complete(ids, pts, sc, pattern_size, propose, size)
        kept = _drop_outliers(ids, pts, sc, tight)
        if kept is None and tight.any():  # the tight corners may have upset their neighbours' fits
            kept = _drop_outliers(ids[~tight], pts[~tight], sc[~tight])
        if kept is None:
            continue
        ids, pts, sc = kept
        if _corners_beyond(ids, pts, pattern_size, propose, size) >= 2:
            continue
        order = np.argsort(ids[:, 1] * cols + ids[:, 0], kind="stable")
        ids, pts, sc = ids[order].astype(np.int32), pts[order].astype(np.float32), sc[order].astype(np.float32)
        if len(ids) == cols * rows:  # completed: read it like any full board
            perm = _reading(pts, pattern_size, gray)
            return Detection(pts[perm], ids, sc[perm], (cols, rows), True, size)
        return Detection(pts, ids, sc, (cols, rows), False, size)
    return None


def _own_grids(grids: list[Grid]) -> list[Grid]:
    """Without a pattern: each grid's filled part, largest first.

    A grid with every position filled is kept as it is. In any other grid, corners off their
    neighbours' lattice (:func:`_drop_outliers`, as for partial boards; a grid that would lose more
    than a tenth of them is dropped) leave holes, then the largest filled rectangle is kept
    (:func:`aicalib_tf.grid.full_subgrid`): a line cut by the frame that kept a few corners never
    hides the rest of the grid, and a corner pulled by an object in front does not come back with it.
    """
    out = []
    for grid in grids:
        a, b = grid.shape
        if len(grid) == a * b:  # filled already
            out.append(grid)
            continue
        kept = _drop_outliers(grid.ij, grid.points, grid.index)
        if kept is not None:
            sub = full_subgrid(Grid(index=kept[2], ij=kept[0], points=kept[1]))
            if sub is not None:
                out.append(sub)
    return sorted(out, key=len, reverse=True)


def detect_corners(image, pattern_size: tuple[int, int] | None = None, *, model=None,
                   threshold: float = 0.5) -> Detection:
    """Find a chessboard's inner corners.

    image : path or array (see :func:`aicalib_tf.io.load_image`).
    pattern_size : (cols, rows) inner corners; None returns the largest complete grid found, with
        ids relative to it.
    model : a loaded corner model (default: the shipped ``models/default.keras``).
    threshold : CNN corner weight above which a peak is a candidate.
    Returns a :class:`Detection`; ``found`` is False when no board is there. With ``pattern_size``,
    a board partly out of frame or hidden is returned with ``complete=False`` when the image
    decides its ids (module docstring), and not at all otherwise.
    """
    from .inference import corner_points

    gray = load_image(image)
    h, w = gray.shape
    if pattern_size is not None:
        from data_gen.board import check_pattern

        check_pattern(pattern_size)
    empty = Detection(np.zeros((0, 2), np.float32), np.zeros((0, 2), np.int32), np.zeros(0, np.float32),
                      pattern_size, False, (w, h))
    if h < 8 or w < 8:
        return empty
    model = model if model is not None else _default_model()
    pts, scores = corner_points(model, gray, threshold)
    pts, scores = pts[:MAX_CANDIDATES], scores[:MAX_CANDIDATES]  # strongest first; bounds the N² steps
    if len(pts) < 9:
        return empty
    smoothed = _Smoothed(gray)
    refined, ok = _refine(smoothed, pts, _nearest_spacing(pts))
    refined, scores = refined[ok], scores[ok]
    keep = _dedupe(refined, scores)
    refined, scores = refined[keep], scores[keep]
    smooth = cv2.GaussianBlur(gray, (0, 0), 1.0)
    propose = None
    if len(refined) >= 9:
        spacing = _nearest_spacing(refined)
        amp, _ = ring_symmetry(smooth, refined.astype(np.float64), 0.3 * spacing)
        propose = _proposer(smoothed, smooth, float(np.median(amp[: max(9, len(amp) // 2)])))
    # grow one step past the pattern so that a bigger board shows itself and is rejected
    limit = max(pattern_size) + 1 if pattern_size is not None else None
    grids = assemble_grids(refined, scores, gray=smooth, propose=propose, limit=limit)
    if pattern_size is None:
        grids = _own_grids(grids)
    for grid in grids:
        det = _board_from_grid(grid, scores, pattern_size, smooth, (w, h))
        if det is not None:
            return det
    if pattern_size is not None:
        det = _partial_board(grids, scores, pattern_size, smooth, (w, h), propose)
        if det is not None:
            return det
    return empty


def find_chessboard_corners(image, pattern_size: tuple[int, int], *, model=None) -> tuple[bool, np.ndarray | None]:
    """Drop-in for ``cv2.findChessboardCorners``: (found, corners (cols·rows, 1, 2) float32 or None)."""
    det = detect_corners(image, pattern_size, model=model)
    if not det.complete:
        return False, None
    return True, det.corners.reshape(-1, 1, 2).copy()


def draw_detection(gray: np.ndarray, det: Detection) -> np.ndarray:
    """An overlay: (H, W, 3) uint8 BGR with the corners, row lines and corner (0, 0) marked (red)."""
    img = cv2.cvtColor(np.clip(gray * 255.0 + 0.5, 0, 255).astype(np.uint8), cv2.COLOR_GRAY2BGR)
    if not det.found:
        cv2.putText(img, "no board", (10, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (0, 0, 255), 2)
        return img
    for r in np.unique(det.ids[:, 1]):  # a partial board's rows too: its corners are ordered by id
        row = det.corners[det.ids[:, 1] == r]
        colour = tuple(int(c) for c in cv2.applyColorMap(np.uint8([[40 * int(r) % 255]]), cv2.COLORMAP_JET)[0, 0])
        cv2.polylines(img, [np.round(row * 16).astype(np.int32)], False, colour, 1, cv2.LINE_AA, shift=4)
    first = (det.ids == 0).all(axis=1)
    for (x, y), is_first in zip(det.corners, first):
        cv2.circle(img, (int(round(x * 16)), int(round(y * 16))), 4 * 16, (0, 0, 255) if is_first else (0, 255, 0), 1,
                   cv2.LINE_AA, shift=4)
    if not det.complete:
        cv2.putText(img, f"partial: {len(det.corners)} corners", (10, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (0, 200, 255), 2)
    return img


def _parse_args(argv):
    import argparse

    ap = argparse.ArgumentParser(prog="python -m aicalib_tf.detect", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("images", nargs="+", help="image files or glob patterns")
    ap.add_argument("--pattern", required=True, help="inner corners, COLSxROWS, e.g. 9x6")
    ap.add_argument("--out", required=True, help="folder for <image>.png overlays and <image>.json corners")
    ap.add_argument("--model", default="default", help="default, report, or a path to a .keras model (default: %(default)s)")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Detect boards in images and write overlays and corner files; exit 2 on bad arguments."""
    import os

    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    import glob
    import json
    import sys
    from pathlib import Path

    from tqdm import tqdm

    from data_gen.board import parse_pattern

    from .io import ImageError, atomic_write_bytes, atomic_write_text
    from .model import file_sha256, load_model

    args = _parse_args(argv)
    try:
        pattern = parse_pattern(args.pattern)
        files = []
        for item in args.images:
            matches = sorted(glob.glob(item)) if any(ch in item for ch in "*?[") else [item]
            files += matches
        if not files:
            raise ValueError(f"no images match {' '.join(args.images)}")
        model = load_model(args.model)
    except (ValueError, FileNotFoundError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sha = file_sha256(model.aicalib_path) if hasattr(model, "aicalib_path") else None
    counts = {"complete": 0, "partial": 0, "none": 0, "failed": 0}
    failures = []
    used: set[str] = set()
    for f in tqdm(files, desc="detect", unit="img", disable=args.quiet):
        try:
            gray = load_image(f)
            det = detect_corners(gray, pattern, model=model)
        except ImageError as exc:
            counts["failed"] += 1
            failures.append(str(exc))
            continue
        counts["complete" if det.complete else "partial" if det.found else "none"] += 1
        stem = Path(f).stem
        if stem in used:  # a/x.jpg and b/x.png must not overwrite each other
            stem = f"{stem}-{len(used)}"
        used.add(stem)
        ok, png = cv2.imencode(".png", draw_detection(gray, det))
        atomic_write_bytes(out / f"{stem}.png", png.tobytes())
        record = {
            "file": str(f), "image_size": list(det.image_size), "pattern_size": list(pattern),
            "found": det.found, "complete": det.complete, "corners": det.corners.tolist(),
            "ids": det.ids.tolist(), "scores": det.scores.tolist(), "model": str(args.model), "model_sha256": sha,
        }
        atomic_write_text(out / f"{stem}.json", json.dumps(record, indent=1) + "\n")
    print(f"{len(files)} images: {counts['complete']} full boards, {counts['partial']} partial (seen corners, ids fixed by the image), "
          f"{counts['none']} without a board, {counts['failed']} unreadable")
    for msg in failures:
        print(f"  skipped: {msg}")
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main())
