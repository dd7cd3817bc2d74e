"""A printed board's out-of-plane shape: a low-order polynomial z(u, v) over the board, the sag its first two terms.

Board frame as in :mod:`aicalib_tf.geometry.board_flex`: a board point at (x, y) squares (a corner's id
(c, r)) moves along the board's z axis by z = Σ_k w_k·b_k(u, v), u = 2·x / (cols − 1) − 1 and
v = 2·y / (rows − 1) − 1 running over [−1, 1] across the inner-corner grid, w in squares. The terms,
in order (:data:`SHAPE_TERMS`), with P₃(t) = (5t³ − 3t) / 2 the third Legendre polynomial:

====  ==============  ==================  =================================================
k     name            b_k(u, v)           what it is
====  ==============  ==================  =================================================
0     ``sag_x``       1 − u²              the parabolic sag along x (:mod:`board_flex`'s w_x)
1     ``sag_y``       1 − v²              the parabolic sag along y (w_y)
2     ``twist``       u·v                 opposite corners up and down (a saddle)
3     ``cubic_x``     P₃(u)               an S along x
4     ``cubic_y``     P₃(v)               an S along y
5     ``sag_x_by_y``  (1 − u²)·v          the sag along x growing from one edge to the other
6     ``sag_y_by_x``  u·(1 − v²)          the sag along y growing along x
====  ==============  ==================  =================================================

The first two terms are the flex exactly, so a shape of two terms is the flex. A constant and the
terms u and v are left out: they move the board rigidly (to first order), which its pose already
does in a calibration. Every term is at most 1 in size over the grid, so w_k is about the largest
offset the term gives, in squares.
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.geometry.board_flex import flex_basis

__all__ = ["SHAPE_TERMS", "shape_basis", "shape_height", "shaped_points", "out_of_plane_rms"]

SHAPE_TERMS = ("sag_x", "sag_y", "twist", "cubic_x", "cubic_y", "sag_x_by_y", "sag_y_by_x")


def _p3(t: np.ndarray) -> np.ndarray:
    return 0.5 * (5.0 * t ** 3 - 3.0 * t)


def shape_basis(x, y, pattern_size, n_terms: int = len(SHAPE_TERMS)) -> np.ndarray:
    """(..., n_terms) float64: the first ``n_terms`` terms b_k of the module docstring at positions x, y
    (..., squares) of a (cols, rows) pattern; the derivative of :func:`shape_height` with respect to w.

    >>> shape_basis(np.array([0.0, 8.0]), np.array([0.0, 5.0]), (9, 6)).round(3).tolist()
    [[0.0, 0.0, 1.0, -1.0, -1.0, -0.0, -0.0], [0.0, 0.0, 1.0, 1.0, 1.0, 0.0, 0.0]]
    """
    n = int(n_terms)
    if not 1 <= n <= len(SHAPE_TERMS):
        raise ValueError(f"n_terms must be 1 to {len(SHAPE_TERMS)}, got {n_terms!r}")
    sag = flex_basis(x, y, pattern_size)  # checks the pattern size
    cols, rows = (int(k) for k in pattern_size)
    u = 2.0 * np.asarray(x, np.float64) / (cols - 1) - 1.0
    v = 2.0 * np.asarray(y, np.float64) / (rows - 1) - 1.0
    u, v = np.broadcast_arrays(u, v)
    more = (lambda: u * v, lambda: _p3(u), lambda: _p3(v), lambda: sag[..., 0] * v, lambda: u * sag[..., 1])
    terms = [sag[..., 0], sag[..., 1]] + [term() for term in more[:max(n - 2, 0)]]  # only the n asked for
    return np.stack(terms[:n], axis=-1)


def shape_height(x, y, pattern_size, shape) -> np.ndarray:
    """(...) z offset, squares, of board positions x, y (..., squares) under ``shape`` (K,) squares (the
    first K terms; K = 2 is the flex (w_x, w_y))."""
    w = np.asarray(shape, np.float64).ravel()
    return shape_basis(x, y, pattern_size, len(w)) @ w


def shaped_points(points, pattern_size, shape, square_size: float = 1.0) -> np.ndarray:
    """(N, 3) float64 board points with the shape applied: z += s·:func:`shape_height`(X / s, Y / s).

    points : (N, 3) flat board points in board units (z = 0); shape : (K,) squares (K = 2: the flex);
    square_size : s, board units. A zero shape returns the points unchanged (a copy).
    """
    p = np.array(points, dtype=np.float64).reshape(-1, 3)
    w = np.asarray(shape, np.float64).ravel()
    if np.any(w != 0.0):
        s = float(square_size)
        p[:, 2] += s * shape_height(p[:, 0] / s, p[:, 1] / s, pattern_size, w)
    return p


def out_of_plane_rms(shape, covariance, pattern_size) -> tuple[float, float]:
    """(RMS, its σ) squares of a shape's z over the inner-corner grid after the best-fitting plane is taken
    off (what a pose cannot absorb): shape (K,), covariance (K, K) squares² (σ to first order; 0 when
    the RMS is 0).

    >>> [round(v, 4) for v in out_of_plane_rms([0.0, 0.0, 0.01], np.eye(3) * 1e-6, (9, 6))]
    [0.0044, 0.0004]
    """
    w = np.asarray(shape, np.float64).ravel()
    cols, rows = (int(k) for k in pattern_size)
    c, r = np.meshgrid(np.arange(cols, dtype=np.float64), np.arange(rows, dtype=np.float64))
    B = shape_basis(c.ravel(), r.ravel(), pattern_size, len(w))
    A = np.stack([np.ones(c.size), c.ravel(), r.ravel()], axis=1)
    B = B - A @ np.linalg.lstsq(A, B, rcond=None)[0]  # each term less its best plane
    M = B.T @ B / len(B)
    rms = float(np.sqrt(max(w @ M @ w, 0.0)))
    if rms == 0.0:
        return 0.0, 0.0
    g = M @ w / rms
    return rms, float(np.sqrt(max(g @ np.asarray(covariance, np.float64) @ g, 0.0)))
