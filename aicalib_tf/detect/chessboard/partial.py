"""Partial boards: a grid grown across the frame and objects in front, placed and completed.

:func:`partial_board` takes assembled grids (largest first) and returns the first whose place on
the pattern the image decides: the grid is grown by partly visible lines (:func:`_grow_cut_lines`)
and across gaps (:func:`_reach`), placed (:func:`aicalib_tf.detect.chessboard.placement.place_cells`), the
pattern's missing corners are looked for where the placed ones predict them (:func:`_complete`),
off-lattice corners are dropped (:func:`aicalib_tf.detect.chessboard.lattice.drop_outliers`), so are corners whose
refinement window leaves the frame by more than 0.3 of its radius (``EDGE_WINDOW``: the saddle
fit slides towards the frame there, up to 2.4 px), and a board with X-junctions one step outside
the pattern is refused (:func:`_corners_beyond`).

cells : {(i, j): (point (2,) px, score)} while a grid grows.
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.detect.chessboard import placement
from aicalib_tf.detect.chessboard.board_order import handed, reading
from aicalib_tf.detect.chessboard.grid import MIN_CORNERS, Grid
from aicalib_tf.detect.chessboard.grid_growth import lines_ahead
from aicalib_tf.detect.corners.junctions import nearest_spacing
from aicalib_tf.detect.chessboard.lattice import (
    curved_residuals,
    drop_outliers,
    in_view,
    line_residuals,
    local_step,
    predict_ids,
)
from aicalib_tf.detect.corners.refine import window_radius
from aicalib_tf.geometry.points import sq_distances

__all__ = ["partial_board", "relative_board"]
MATCH_STEP = 0.3  # of a step: how far a corner found may lie from where the lattice predicts it


# of a step, with line_residuals: their own miss on true fisheye close-up corners reaches 0.15 (a wrong
# corner, a neighbour's, is half a step or more off)
BENT_RESIDUAL = 0.2
CURVED_SHARE = 0.9  # of the pattern's corners: a board this complete may be bent by its lens (curved_residuals)
EDGE_WINDOW = 0.7  # of its refinement window's radius: how far a partial board's corner must be from the frame
LONE_SHIFT = 0.1  # of a step: how near its prediction a line's lone corner must be when its ring test leaves the frame


def _room(pts: np.ndarray, size) -> np.ndarray:
    """(N,) px from each point to the image frame (the outer pixel centres); NaN for a NaN point."""
    w, h = size
    return np.minimum(np.minimum(pts[:, 0], pts[:, 1]), np.minimum(w - 1 - pts[:, 0], h - 1 - pts[:, 1]))


def _take(cells: dict, new: list, pred: np.ndarray, step: np.ndarray, got: np.ndarray, limit: int | None = None) -> int:
    """Add proposals ``got`` (M, 2, NaN where none) for cells ``new`` (M (i, j) keys) unless they repeat a point.

    With ``limit``, a cell that would stretch the cells past ``limit`` positions on an axis is left out.
    Returns how many were added.
    """
    pts = np.array([v[0] for v in cells.values()])
    ij = np.array(list(cells.keys()))
    (i0, j0), (i1, j1) = ij.min(0).tolist(), ij.max(0).tolist()
    added = 0
    for (i, j), p, s, q in zip(new, pred, step, got):
        if limit is not None and (max(i1, i) - min(i0, i) + 1 > limit or max(j1, j) - min(j0, j) + 1 > limit):
            continue
        if not np.all(np.isfinite(q)) or np.linalg.norm(q - p) > MATCH_STEP * s:
            continue
        if np.min(np.linalg.norm(pts - q, axis=1)) < 0.5 * s:
            continue
        cells[(i, j)] = (q.astype(np.float64), 0.0)
        pts = np.vstack([pts, q])
        i0, j0, i1, j1 = min(i0, i), min(j0, j), max(i1, i), max(j1, j)
        added += 1
    return added


def _grow_cut_lines(cells: dict, propose, limit: int, size) -> None:
    """Grow a grid by lines that are partly out of the image or hidden.

    Grid assembly adds a line when half of its predicted corners are found; at the image frame or
    beside an object most of them may not be visible. Here a line one step beyond each side is
    added when at least two of its predicted corners are found (saddle fit and ring test, see
    :func:`aicalib_tf.detect.corners.junctions.proposer`), or one where at most two lie in the image. Such a lone
    corner whose ring reaches beyond the frame must lie within ``LONE_SHIFT`` of a step of its
    prediction: the ring test reads samples beyond the frame as copies of the edge pixels, and
    there the junction of two border squares and the background, cut by the frame, passes it
    (the saddle sliding 0.18 step towards the frame; true corners there: at most 0.07 step on
    data_gen renders). The grid never grows past ``limit`` positions on an axis.
    cells : {(i, j): (point (2,), score)}, changed in place.
    """
    for _ in range(2 * limit):
        grown = False
        first = {(axis, sign): _cut_side(cells, axis, sign, limit) for axis in (0, 1) for sign in (-1, 1)}
        sides = [side for side in first.values() if side is not None]
        if len(sides) > 1:  # one batch; propose remembers, so the sides' own asks below cost nothing more
            propose(np.concatenate([p for _, p, _ in sides]), np.concatenate([st for _, _, st in sides]))
        for axis in (0, 1):
            for sign in (-1, 1):
                side = _cut_side(cells, axis, sign, limit) if grown else first[(axis, sign)]
                if side is None:
                    continue
                new, pred, step = side
                view = in_view(pred, size)
                got = propose(pred, step)
                ok = np.all(np.isfinite(got), axis=1) & (np.linalg.norm(got - pred, axis=1) <= MATCH_STEP * step)
                need = 1 if view.sum() <= 2 else 2
                if need == 1:  # a line on one corner's word, its ring cut by the frame: the lattice must vouch for it
                    with np.errstate(invalid="ignore"):
                        cut = _room(got, size) < MATCH_STEP * step
                    ok &= ~cut | (np.linalg.norm(got - pred, axis=1) <= LONE_SHIFT * step)
                if ok.sum() >= need:
                    trial = dict(cells)
                    if _take(trial, new, pred, step, np.where(ok[:, None], got, np.nan)) >= need:
                        cells.clear()
                        cells.update(trial)
                        grown = True
        _fill_cells(cells, propose)
        if not grown:
            return


def _cut_side(cells: dict, axis: int, sign: int, limit: int):
    """The line one step beyond a side of the grid: (new cells, predictions (M, 2) px, steps (M,) px).

    Each line ending there is extrapolated (quadratically where three points are known). None when
    the grid spans ``limit`` positions along ``axis`` or no line ends there.
    """
    keys = np.array(list(cells.keys()))
    if keys[:, axis].max() - keys[:, axis].min() + 1 >= limit:
        return None
    e = int(keys[:, axis].max() if sign > 0 else keys[:, axis].min())

    def point(key):
        v = cells.get(key)
        return None if v is None else v[0]

    ahead = lines_ahead(point, axis, sign, e, np.unique(keys[:, 1 - axis]).tolist())
    if ahead is None:
        return None
    new, pred, last = ahead
    return new, pred, np.linalg.norm(last, axis=1)


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
        pred = predict_ids(ij, pts, cand)
        view = in_view(pred, size)
        cand, pred = cand[view], pred[view]
        if len(cand) == 0:
            return
        step = local_step(ij, pts, pred)
        got = propose(pred, step)
        hit = np.all(np.isfinite(got), axis=1) & (np.linalg.norm(got - pred, axis=1) <= MATCH_STEP * step)
        # a corner outside the grid's extent needs a found neighbour that is outside too: one lone
        # junction (an object's corner against a square, say) must not stretch the grid
        outside = hit & np.any((cand < lo) | (cand > hi), axis=1)
        pair = np.abs(cand[:, None, :] - cand[None, outside, :]).max(-1) == 1  # (M, #outside)
        hit &= ~outside | pair.any(axis=1)
        if not _take(cells, [tuple(c) for c in cand[hit].tolist()], pred[hit], step[hit], got[hit], limit):
            return


def _complete(ids: np.ndarray, pts: np.ndarray, sc: np.ndarray, pattern_size, propose, size, passes: int = 3):
    """Look for the pattern's missing corners where the placed ones predict them (around objects in front).

    Each missing corner is predicted from its 12 nearest placed corners; where nothing is found
    there (and more than 12 are placed), from the homography of all of them: across a wide object
    the near ones, bunched on one side, extrapolate badly (evaluate occluded #77: 6-17 px off, 4-9 px
    with all), then with ``propose.tight`` beside an object.
    Returns (ids, pts, sc, tight): tight (N,) bool marks corners found by ``propose.tight`` only.
    """
    cols, rows = pattern_size
    tight = np.zeros(len(ids), bool)
    for _ in range(passes):
        have = set(map(tuple, ids.tolist()))
        want = np.array([(c, r) for r in range(rows) for c in range(cols) if (c, r) not in have])
        if len(want) == 0:
            break
        pred = predict_ids(ids, pts, want)
        view = in_view(pred, size)
        if not view.any():
            break
        want, pred = want[view], pred[view]
        step = local_step(ids, pts, pred)
        # far across an object in front: the whole board's homography; asked in the same batch
        # (each point's answer is its own), used where the near prediction finds nothing
        wide = predict_ids(ids, pts, want, k=len(ids)) if len(ids) > 12 else np.zeros((0, 2))
        got_all = propose(np.concatenate([pred, wide]), np.concatenate([step, step[: len(wide)]]))
        got = got_all[: len(pred)]
        ok = np.all(np.isfinite(got), axis=1) & (np.linalg.norm(got - pred, axis=1) <= MATCH_STEP * step)
        if (~ok).any() and len(wide):
            miss = np.flatnonzero(~ok)
            wide, got_w = wide[miss], got_all[len(pred):][miss]
            hit = np.all(np.isfinite(got_w), axis=1) & (np.linalg.norm(got_w - wide, axis=1) <= MATCH_STEP * step[miss])
            got[miss[hit]], pred[miss[hit]], ok[miss[hit]] = got_w[hit], wide[hit], True
        by_tight = np.zeros(len(ok), bool)
        if (~ok).any() and hasattr(propose, "tight"):  # beside an object in front
            miss = np.flatnonzero(~ok)
            got[miss] = propose.tight(pred[miss], step[miss])
            ok[miss] = by_tight[miss] = np.all(np.isfinite(got[miss]), axis=1)
        d_old = np.sqrt(sq_distances(got, pts)).min(axis=1) if ok.any() else None
        if ok.any():
            ok &= d_old >= 0.5 * step
        if not ok.any():
            break
        ids = np.concatenate([ids, want[ok]])
        pts = np.concatenate([pts, got[ok]])
        sc = np.concatenate([sc, np.zeros(int(ok.sum()), np.float32)])
        tight = np.concatenate([tight, by_tight[ok]])
    return ids, pts, sc, tight


def _corners_beyond(ids: np.ndarray, pts: np.ndarray, pattern_size, propose, size) -> int:
    """How many X-junctions lie one step outside the pattern, where a placed board has none."""
    cols, rows = pattern_size
    ring = [(c, -1) for c in range(-1, cols + 1)] + [(c, rows) for c in range(-1, cols + 1)]
    ring += [(-1, r) for r in range(rows)] + [(cols, r) for r in range(rows)]
    want = np.array(ring)
    pred = predict_ids(ids, pts, want)
    view = in_view(pred, size)
    if not view.any():
        return 0
    pred = pred[view]
    step = local_step(ids, pts, pred)
    got = propose(pred, step)
    return int((np.all(np.isfinite(got), axis=1) & (np.linalg.norm(got - pred, axis=1) <= MATCH_STEP * step)).sum())


def _cells(grid: Grid, scores: np.ndarray) -> dict:
    """{(i, j): (point (2,) px, weight)} of a grid, its (i, j) turned to the image's handedness; a
    corner the ``propose`` callback found (index -1) weighs 0."""
    ij = handed(grid.ij, grid.points)
    sc = np.where(grid.index >= 0, scores[np.maximum(grid.index, 0)], 0.0)
    return {(int(i), int(j)): (np.asarray(p, np.float64), float(s)) for (i, j), p, s in zip(ij, grid.points, sc)}


def partial_board(grids: list[Grid], scores: np.ndarray, pattern_size: tuple[int, int], gray: np.ndarray,
                  size: tuple[int, int], propose):
    """The largest grid whose place on the board the image decides, as an incomplete board.

    Each grid (largest first) is grown by partly visible lines, placed on the pattern
    (:func:`aicalib_tf.detect.chessboard.placement.place_cells`); the pattern's missing corners are then looked for
    where the placed ones predict them, and the board is dropped if X-junctions show up one step
    outside the pattern. grids : from :func:`aicalib_tf.detect.chessboard.grid.assemble_grids`, largest first.
    scores : (N,) candidate weights. gray : (H, W) float32 smoothed. size : (width, height) px.
    propose : from :func:`aicalib_tf.detect.corners.junctions.proposer`, or None (no board).
    Returns (board, undecided): board is (corners (K, 2) float32 px, ids (K, 2) int32 (col, row),
    scores (K,) float32, complete) with corners in row-major order of their ids (a completed board
    in the full-board order), or None; undecided is True when a grid was left out because the
    image leaves its place on the pattern open.
    """
    undecided = False
    if propose is None:
        return None, undecided
    cols, rows = pattern_size
    for grid in grids:
        if len(grid) < MIN_CORNERS:
            continue
        cells = _cells(grid, scores)
        _grow_cut_lines(cells, propose, max(pattern_size) + 1, size)
        _reach(cells, propose, max(pattern_size) + 1, size)
        ids = placement.place_cells(cells, pattern_size, gray)
        if ids is None:
            undecided = True
            continue
        pts = np.array([v[0] for v in cells.values()])
        sc = np.array([v[1] for v in cells.values()], np.float32)
        ids, pts, sc, tight = _complete(ids, pts, sc, pattern_size, propose, size)
        kept = drop_outliers(ids, pts, sc, tight)
        if kept is None and tight.any():  # the tight corners may have upset their neighbours' fits
            kept = drop_outliers(ids[~tight], pts[~tight], sc[~tight])
        if kept is None and len(ids) >= CURVED_SHARE * cols * rows:  # a (nearly) completed board bent by a strong lens
            kept = drop_outliers(ids, pts, sc, tight, residuals=curved_residuals)
        bent = kept is None and len(ids) == cols * rows  # bent too strongly for that (fisheye close-up): complete only
        if bent:
            kept = drop_outliers(ids, pts, sc, tight, max_residual=BENT_RESIDUAL, residuals=line_residuals)
        if kept is None:
            continue
        ids, pts, sc = kept
        # a corner nearer the frame than EDGE_WINDOW of its refinement window's radius is pulled
        # towards the frame (on data_gen renders: 0.5-2.4 px off below 0.7, at most 0.53 px above): left out
        edge = _room(pts, size) < EDGE_WINDOW * window_radius(nearest_spacing(pts))
        if edge.any():
            ids, pts, sc = ids[~edge], pts[~edge], sc[~edge]
            if len(ids) < MIN_CORNERS:
                continue
        if (bent and len(ids) < cols * rows) or _corners_beyond(ids, pts, pattern_size, propose, size) >= 2:
            continue
        order = np.argsort(ids[:, 1] * cols + ids[:, 0], kind="stable")
        ids, pts, sc = ids[order].astype(np.int32), pts[order].astype(np.float32), sc[order].astype(np.float32)
        if len(ids) == cols * rows:  # completed: read it like any full board
            perm = reading(pts, pattern_size, gray)
            return (pts[perm], ids, sc[perm], True), undecided
        return (pts, ids, sc, False), undecided
    return None, undecided


def _fit_pattern(ij: np.ndarray, pattern_size) -> np.ndarray | None:
    """Lattice positions (K, 2) shifted to start at 0 and, if they only fit the pattern turned,
    turned by 90° (handedness kept): ids within (cols, rows), or None when they fit neither way."""
    cols, rows = pattern_size
    ij = ij - ij.min(axis=0)
    span = ij.max(axis=0) + 1
    if span[0] <= cols and span[1] <= rows:
        return ij
    if span[1] <= cols and span[0] <= rows:  # (i, j) -> (span_j - 1 - j, i): a quarter turn
        return np.stack([span[1] - 1 - ij[:, 1], ij[:, 0]], axis=1)
    return None


def relative_board(grid: Grid, scores: np.ndarray, pattern_size: tuple[int, int], size: tuple[int, int], propose):
    """A grid whose place on the pattern the image leaves open, with ids relative to it.

    For calibration, where each view has its own pose: a board larger than the frame, no edge in
    view, still gives a consistent lattice. The grid is grown by partly visible lines, its corners
    off their neighbours' lattice and those too near the frame are dropped (as for a placed partial
    board), and its lattice positions become ids, shifted to start at 0 and turned a quarter when
    only that fits the pattern, handedness kept (x right, y down, as a board seen from the front).
    Returns (corners (K, 2) float32 px, ids (K, 2) int32, scores (K,) float32) in row-major order
    of the ids, or None (too few corners left, or a grid larger than the pattern).
    """
    if propose is None or len(grid) < MIN_CORNERS:
        return None
    cells = _cells(grid, scores)
    _grow_cut_lines(cells, propose, max(pattern_size) + 1, size)
    ids = _fit_pattern(np.array(list(cells.keys())), pattern_size)
    if ids is None:
        return None
    pts = np.array([v[0] for v in cells.values()])
    sc = np.array([v[1] for v in cells.values()], np.float32)
    kept = drop_outliers(ids, pts, sc)
    if kept is None:
        return None
    ids, pts, sc = kept
    keep = _room(pts, size) >= EDGE_WINDOW * window_radius(nearest_spacing(pts))
    if keep.sum() < MIN_CORNERS:
        return None
    ids = ids[keep] - ids[keep].min(axis=0)
    order = np.argsort(ids[:, 1] * pattern_size[0] + ids[:, 0], kind="stable")
    return pts[keep][order].astype(np.float32), ids[order].astype(np.int32), sc[keep][order].astype(np.float32)
