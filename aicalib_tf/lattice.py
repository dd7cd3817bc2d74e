"""A board's lattice from its placed corners: local homographies over (col, row) ids (pure numpy).

Corners of a board with known ids lie on a lattice that perspective and lens distortion bend
smoothly, so a few nearby corners predict any other through a homography of their ids
(:func:`homographies`, many solved at once). :func:`predict_ids` predicts where ids lie,
:func:`lattice_residuals` measures how far each corner is from where its neighbours put it and
:func:`drop_outliers` removes the worst ones.

ids are (N, 2) int (col, row) (or a grid's (i, j)); points are (N, 2) (x, y) px.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MAX_RESIDUAL", "MIN_PARTIAL", "drop_outliers", "homographies", "in_view", "lattice_residuals",
           "local_step", "predict_ids"]


MIN_PARTIAL = 9  # fewest corners of a partial board (a grid's seed is 3x3)


MAX_RESIDUAL = 0.08  # of a step: how far a corner of a partial board may be from its neighbours' lattice


def in_view(pts: np.ndarray, size) -> np.ndarray:
    w, h = size
    return np.all(np.isfinite(pts), axis=1) & (pts[:, 0] >= 1) & (pts[:, 0] <= w - 2) & (pts[:, 1] >= 1) & (pts[:, 1] <= h - 2)


def homographies(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
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


def predict_ids(ids: np.ndarray, pts: np.ndarray, want: np.ndarray, k: int = 12) -> np.ndarray:
    """Image positions (M, 2) of board ids ``want`` (M, 2), each from a homography of its k nearest known ids.

    NaN rows where fewer than 4 ids are known or the fit is degenerate.
    """
    want = np.asarray(want, np.float64).reshape(-1, 2)
    if len(ids) < 4 or len(want) == 0:
        return np.full((len(want), 2), np.nan)
    d2 = ((want[:, None, :] - ids[None, :, :]) ** 2).sum(-1)
    near = np.argsort(d2, axis=1, kind="stable")[:, : min(k, len(ids))]
    hom = homographies(ids[near].astype(np.float64), pts[near].astype(np.float64))
    q = hom @ np.concatenate([want, np.ones((len(want), 1))], axis=1)[..., None]
    return q[:, :2, 0] / q[:, 2:, 0]


def local_step(ids: np.ndarray, pts: np.ndarray, want_xy: np.ndarray) -> np.ndarray:
    """(M,) px corner spacing near each position: the nearest known corner's distance to its nearest one."""
    d2 = ((pts[:, None, :] - pts[None, :, :]) ** 2).sum(-1)
    np.fill_diagonal(d2, np.inf)
    spacing = np.sqrt(d2.min(axis=1))
    near = np.argmin(((want_xy[:, None, :] - pts[None, :, :]) ** 2).sum(-1), axis=1)
    return spacing[near]


def lattice_residuals(ids: np.ndarray, pts: np.ndarray, k: int = 8) -> np.ndarray:
    """(N,) distance of each corner from where its k nearest other corners predict it, in local steps.

    The local step is the distance to the nearest other corner; for a corner none of whose four
    neighbours is found (hidden by an object in front), the shorter of that and the lattice's own
    step there (the predicted neighbours' distance).
    """
    n = len(ids)
    d2 = ((pts[:, None, :] - pts[None, :, :]) ** 2).sum(-1)
    np.fill_diagonal(d2, np.inf)
    step = np.sqrt(d2.min(axis=1))
    if n < 5:
        return np.zeros(n)
    di = ((ids[:, None, :] - ids[None, :, :]) ** 2).sum(-1).astype(np.float64)
    np.fill_diagonal(di, np.inf)  # leave each corner out of its own fit
    near = np.argsort(di, axis=1, kind="stable")[:, : min(k, n - 1)]
    hom = homographies(ids[near].astype(np.float64), pts[near].astype(np.float64))
    q = hom @ np.concatenate([ids.astype(np.float64), np.ones((n, 1))], axis=1)[..., None]
    pred = q[:, :2, 0] / q[:, 2:, 0]
    # a corner whose four neighbours are all hidden (an object in front) is further from the nearest
    # found one than a step: the step is then the lattice's own, the shortest of its four unit steps
    unit = np.array([[1, 0], [-1, 0], [0, 1], [0, -1]])
    have = set(map(tuple, ids.tolist()))
    alone = np.array([not any((int(i + a), int(j + b)) in have for a, b in unit) for i, j in ids])
    if alone.any():
        qs = hom[alone, None] @ np.concatenate([ids[alone, None, :] + unit[None], np.ones((int(alone.sum()), 4, 1))],
                                               axis=2)[..., None]
        lat = np.linalg.norm(qs[..., :2, 0] / qs[..., 2:, 0] - pred[alone, None, :], axis=2).min(axis=1)
        step[alone] = np.where(np.isfinite(lat), np.minimum(step[alone], lat), step[alone])
    res = np.linalg.norm(pred - pts, axis=1) / step
    return np.where(np.isfinite(res), res, 0.0)


def drop_outliers(ids, pts, sc, free=None, max_residual: float = MAX_RESIDUAL):
    """Drop corners off the lattice of their neighbours (e.g. pulled by the edge of an object in front).

    The worst corner goes first, until every residual (:func:`lattice_residuals`) is at most
    ``max_residual`` local steps. A board that would lose more than a tenth of its other corners
    (at least 2) this way is not a clean lattice: None. free : (N,) bool, corners whose loss does
    not count (found by the tight test beside an object). Returns the kept (ids, pts, sc) or None.
    """
    free = np.zeros(len(ids), bool) if free is None else np.asarray(free, bool)
    budget = max(2, int((~free).sum()) // 10)
    while len(ids) >= MIN_PARTIAL:
        res = lattice_residuals(ids, pts)
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
