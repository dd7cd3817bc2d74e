"""Distances between sets of image points (numpy; scipy's k-d tree for large sets).

Points are (N, 2) (x, y) px. numpy reduces over an axis of length 2 slowly (``(d ** 2).sum(-1)``
of a (60, 60, 2) array takes about seven times as long as adding its two planes), and the
detector asks for these distances many times per image.

Memory. :func:`sq_distances` makes the whole (M, N) matrix, so it is for sets whose sizes are
bounded (a board's corners, a few thousand candidates at most). Sets of any size go through
:func:`close_pairs` and :func:`any_within` (the pairs within a radius: a k-d tree where M·N is
large, memory O(M + N + pairs)) or :func:`nearest_k` (row blocks of at most ``BLOCK`` distances).
Every answer is worked out from the same arithmetic as :func:`sq_distances`, so it is the same,
bit for bit, whichever way the pairs were found.
"""

from __future__ import annotations

import numpy as np

__all__ = ["sq_distances", "close_pairs", "any_within", "nearest_k", "nearest_index", "BLOCK"]

BLOCK = 1 << 20  # distances held at once by the blockwise and the dense paths (8 MB of float64)


def sq_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(M, N) squared distances (px²) between points a (M, 2) and b (N, 2).

    The same values, bit for bit, as ``((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)``. Memory
    M·N values: for sets of bounded size only (see the module docstring).
    """
    a, b = np.asarray(a), np.asarray(b)
    dx = a[:, None, 0] - b[None, :, 0]
    dy = a[:, None, 1] - b[None, :, 1]
    return dx * dx + dy * dy


def _pair_sq(a: np.ndarray, b: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Squared distances of the pairs (a[i], b[j]), in :func:`sq_distances`' arithmetic and dtype."""
    dx = a[i, 0] - b[j, 0]
    dy = a[i, 1] - b[j, 1]
    return dx * dx + dy * dy


def close_pairs(a: np.ndarray, b: np.ndarray, radius: float, *, strict: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """All pairs (i, j) with a[i] (M, 2) and b[j] (N, 2) within ``radius`` px.

    Within means ``sq_distances(a, b)[i, j] <= radius**2`` (``<`` with ``strict``), that very
    value. Points with a NaN or infinite coordinate are never within. Returns i (K,) and j (K,)
    int64, sorted by i then j. Where M·N ≤ ``BLOCK`` the distances are taken densely; otherwise a
    k-d tree (:class:`scipy.spatial.cKDTree`) finds the pairs within a slightly larger radius
    and the exact test above keeps those within, in memory O(M + N + pairs).

    >>> close_pairs(np.array([[0.0, 0.0], [10.0, 0.0]]), np.array([[0.0, 1.0], [3.0, 4.0]]), 5.0)
    (array([0, 0]), array([0, 1]))
    """
    a, b = np.asarray(a), np.asarray(b)
    dtype = np.result_type(a, b)
    r2 = float(radius) ** 2  # compared as `d2 <= radius**2` compares it: a Python float cast to a float d2's dtype
    lim = dtype.type(r2) if np.issubdtype(dtype, np.floating) else r2
    empty = np.zeros(0, np.int64)
    if len(a) == 0 or len(b) == 0 or not np.isfinite(lim) or lim < 0:
        return empty, empty
    if len(a) * len(b) <= BLOCK:
        d2 = sq_distances(a, b)
        i, j = np.nonzero(d2 < lim if strict else d2 <= lim)
        return i.astype(np.int64), j.astype(np.int64)
    from scipy.spatial import cKDTree  # imported only for large sets: the detector's usual sets never need it

    ka = np.flatnonzero(np.isfinite(a).all(axis=1))
    kb = np.flatnonzero(np.isfinite(b).all(axis=1))
    if len(ka) == 0 or len(kb) == 0:
        return empty, empty
    reach = float(radius) * (1.0 + 1e-6) + 1e-6  # a bound on the float32 rounding of the exact test
    pairs = cKDTree(np.asarray(a[ka], np.float64)).sparse_distance_matrix(
        cKDTree(np.asarray(b[kb], np.float64)), reach, output_type="ndarray")
    i, j = ka[pairs["i"]], kb[pairs["j"]]
    d2 = _pair_sq(a, b, i, j)
    keep = d2 < lim if strict else d2 <= lim
    i, j = i[keep], j[keep]
    order = np.lexsort((j, i))
    return i[order], j[order]


def any_within(a: np.ndarray, b: np.ndarray, radius: float, *, strict: bool = False) -> np.ndarray:
    """(M,) bool: whether some point of b (N, 2) lies within ``radius`` px of each point of a (M, 2).

    The same answer as ``sq_distances(a, b).min(axis=1) <= radius**2`` (``<`` with ``strict``) for
    finite points, in memory O(M + N + pairs) (:func:`close_pairs`).
    """
    out = np.zeros(len(a), bool)
    i, _ = close_pairs(a, b, radius, strict=strict)
    out[i] = True
    return out


def nearest_k(pts: np.ndarray, k: int) -> np.ndarray:
    """(N, min(k, N − 1)) int64: each point's ``k`` nearest other points of pts (N, 2), nearest first.

    The same indices, ties included, as ``np.argsort(d2, axis=1)[:, :k]`` of the whole
    ``d2 = sq_distances(pts, pts)`` with its diagonal set to infinity: worked out on blocks of rows
    (each row's sort depends on that row alone), at most ``BLOCK`` distances at a time.
    """
    pts = np.asarray(pts)
    n = len(pts)
    k = min(int(k), n - 1)
    out = np.empty((n, max(k, 0)), np.int64)
    step = max(1, BLOCK // max(n, 1))
    for start in range(0, n, step):
        rows = np.arange(start, min(n, start + step))
        d2 = sq_distances(pts[rows], pts)
        d2[np.arange(len(rows)), rows] = np.inf
        out[rows] = np.argsort(d2, axis=1)[:, :k]
    return out


def nearest_index(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(M,) int64: for each point of a (M, 2), the index of its nearest point of b (N, 2), N ≥ 1.

    The same indices, ties included, as ``np.argmin(np.linalg.norm(a[:, None] - b[None], axis=2), axis=1)``,
    worked out on blocks of rows of at most ``BLOCK`` distances.
    """
    a, b = np.asarray(a), np.asarray(b)
    out = np.empty(len(a), np.int64)
    step = max(1, BLOCK // max(len(b), 1))
    for start in range(0, len(a), step):
        out[start:start + step] = np.argmin(np.linalg.norm(a[start:start + step, None] - b[None], axis=2), axis=1)
    return out

