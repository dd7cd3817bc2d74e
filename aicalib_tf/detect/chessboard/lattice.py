"""A board's lattice from its placed corners: local homographies over (col, row) ids (numpy, numba).

Corners of a board with known ids lie on a lattice that perspective and lens distortion bend
smoothly, so a few nearby corners predict any other through a homography of their ids
(:func:`aicalib_tf.detect.chessboard.lattice_kernels.lattice_predict`, compiled). :func:`predict_ids` predicts where ids lie,
:func:`lattice_residuals` measures how far each corner is from where its neighbours put it and
:func:`drop_outliers` removes the worst ones.

ids are (N, 2) int (col, row) (or a grid's (i, j)); points are (N, 2) (x, y) px.
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.detect.chessboard.grid import MIN_CORNERS
from aicalib_tf.detect.chessboard.lattice_kernels import (
    lattice_predict,
    lattice_residuals_loop,
    nearest_predict,
    nearest_steps,
)

__all__ = ["MAX_RESIDUAL", "curved_residuals", "drop_outliers", "in_view", "lattice_residuals", "line_residuals",
           "local_step", "predict_ids"]




MAX_RESIDUAL = 0.08  # of a step: how far a corner of a partial board may be from its neighbours' lattice


def _f64(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, np.float64)


def in_view(pts: np.ndarray, size) -> np.ndarray:
    w, h = size
    return np.all(np.isfinite(pts), axis=1) & (pts[:, 0] >= 1) & (pts[:, 0] <= w - 2) & (pts[:, 1] >= 1) & (pts[:, 1] <= h - 2)


def predict_ids(ids: np.ndarray, pts: np.ndarray, want: np.ndarray, k: int = 12) -> np.ndarray:
    """Image positions (M, 2) of board ids ``want`` (M, 2), each from a homography of its k nearest known ids.

    NaN rows where fewer than 4 ids are known or the fit is degenerate.
    """
    want = np.asarray(want, np.float64).reshape(-1, 2)
    if len(ids) < 4 or len(want) == 0:
        return np.full((len(want), 2), np.nan)
    if k >= len(ids):  # every id's set is all of them: one homography serves all
        return lattice_predict(_f64(ids), _f64(pts), np.arange(len(ids))[None], want[None])[0]
    return nearest_predict(_f64(ids), _f64(pts), want, k)


def local_step(ids: np.ndarray, pts: np.ndarray, want_xy: np.ndarray) -> np.ndarray:
    """(M,) px corner spacing near each position: the nearest known corner's distance to its nearest one."""
    return nearest_steps(_f64(pts), _f64(np.asarray(want_xy).reshape(-1, 2)))


def lattice_residuals(ids: np.ndarray, pts: np.ndarray, k: int = 8) -> np.ndarray:
    """(N,) distance of each corner from where its k nearest other corners predict it, in local steps.

    The local step is the distance to the nearest other corner; for a corner none of whose four
    neighbours is found (hidden by an object in front), the shorter of that and the lattice's own
    step there (the predicted neighbours' distance).
    """
    if len(ids) < 5:
        return np.zeros(len(ids))
    single = np.asarray(pts).dtype == np.float32
    return lattice_residuals_loop(_f64(ids), np.ascontiguousarray(pts, np.float32 if single else np.float64), k, single)


def curved_residuals(ids: np.ndarray, pts: np.ndarray, k: int = 12) -> np.ndarray:
    """(N,) like :func:`lattice_residuals`, but each corner is predicted by a quadratic in the ids
    fitted to its k nearest other corners, so a lattice bent by a strong lens fits too.

    Under a 120° barrel lens the local homographies of a board's compressed edge miss its true
    corners by up to 0.25 steps; the quadratic, by under 0.04 (docs/benchmark.md, wide-angle).
    Steps as in :func:`lattice_residuals` without the lone-corner case. Needs N > k; else zeros.
    """
    ids = np.asarray(ids, np.float64).reshape(-1, 2)
    pts = np.asarray(pts, np.float64).reshape(-1, 2)
    n = len(ids)
    if n <= k:
        return np.zeros(n)
    d_ids = ((ids[:, None] - ids[None]) ** 2).sum(-1)
    np.fill_diagonal(d_ids, np.inf)
    step = local_step(ids, pts, pts)  # each corner's distance to its nearest other corner
    out = np.zeros(n)
    for i in range(n):
        sel = np.argsort(d_ids[i], kind="stable")[:k]
        u, v = (ids[sel] - ids[i]).T
        design = np.stack([np.ones(k), u, v, u * u, u * v, v * v], 1)
        coef, *_ = np.linalg.lstsq(design, pts[sel], rcond=None)
        with np.errstate(divide="ignore", invalid="ignore"):
            res = np.hypot(*(coef[0] - pts[i])) / step[i]
        out[i] = res if np.isfinite(res) else 0.0
    return out


# Interpolation along a grid line, exact for a cubic in the id: (offsets along the line, weights)
_LINE_STENCILS = (
    ((-2, -1, 1, 2), (-1 / 6, 4 / 6, 4 / 6, -1 / 6)),  # centred: 2 corners on each side
    ((-1, 1, 2, 3), (0.25, 1.5, -1.0, 0.25)),  # second corner of a line
    ((1, -1, -2, -3), (0.25, 1.5, -1.0, 0.25)),  # second-last
)


def line_residuals(ids: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """(N,) like :func:`lattice_residuals`, with each corner interpolated along its grid lines, for a
    lattice that bends too strongly for a fit over an area (a board close to a fisheye).

    Along each of its two grid lines a corner is interpolated from four others on that line (two
    on each side, or one on one side and three on the other: a cubic in the id); its residual is
    the smaller miss of the two lines, in local steps (distance to the nearest other corner).
    Interpolation follows the line's bend and its squeeze towards the rim: on the true corners of
    data_gen's ``fisheye_closeup`` the centred form misses by 0.003 steps (median), 0.07 (p99). A
    corner neither line can interpolate (a board corner, say) gets 0: it is judged as a node of
    its neighbours' interpolations.
    """
    ids = np.asarray(ids).reshape(-1, 2).astype(np.int64)
    pts = np.asarray(pts, np.float64).reshape(-1, 2)
    n = len(ids)
    if n < 5:
        return np.zeros(n)
    at = {(int(c), int(r)): k for k, (c, r) in enumerate(ids.tolist())}
    step = local_step(ids, pts, pts)
    out = np.zeros(n)
    for k, (c, r) in enumerate(ids.tolist()):
        best = np.inf
        for axis in (0, 1):
            for offs, wts in _LINE_STENCILS:
                cells = [(c + o, r) if axis == 0 else (c, r + o) for o in offs]
                if all(cell in at for cell in cells):
                    pred = sum(w * pts[at[cell]] for w, cell in zip(wts, cells))
                    best = min(best, float(np.hypot(*(pred - pts[k]))))
                    break
        if np.isfinite(best) and step[k] > 0:
            out[k] = best / step[k]
    return out


def drop_outliers(ids, pts, sc, free=None, max_residual: float = MAX_RESIDUAL, residuals=None):
    """Drop corners off the lattice of their neighbours (e.g. pulled by the edge of an object in front).

    The worst corner goes first, until every residual (:func:`lattice_residuals`) is at most
    ``max_residual`` local steps. A board that would lose more than a tenth of its other corners
    (at least 2) this way is not a clean lattice: None. free : (N,) bool, corners whose loss does
    not count (found by the tight test beside an object). residuals : the measure, by default
    :func:`lattice_residuals`. Returns the kept (ids, pts, sc) or None.
    """
    residuals = lattice_residuals if residuals is None else residuals
    free = np.zeros(len(ids), bool) if free is None else np.asarray(free, bool)
    budget = max(2, int((~free).sum()) // 10)
    while len(ids) >= MIN_CORNERS:
        res = residuals(ids, pts)
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
