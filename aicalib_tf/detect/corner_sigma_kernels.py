"""The per-corner σ model's window measurements, compiled (numba): the maths is :mod:`aicalib_tf.detect.corner_sigma`'s.

One pass over each corner's window: its bilinear samples, their point-symmetric and
antisymmetric parts, the saddle fit's quadratic and what it leaves; and the bend of the board's
lattice at the corner from its neighbours by id. As array code these took about a third of a
640×480 detection's time; here a few microseconds per board.
"""

from __future__ import annotations

import math

import numpy as np

from aicalib_tf.kernels import kernel

from .sampling import _sample_grid

__all__ = ["window_measures", "lattice_bend"]


@kernel("f4[:, ::1], f8[:, ::1], i8[::1], f8[:, :, ::1], f8[:, ::1]")
def window_measures(img, pts, radius, fits, weights):
    """Per point (P, 5) float64: odd, odd_median, even, residual, curvature (:mod:`~aicalib_tf.detect.corner_sigma`).

    img (H, W) float32, pts (P, 2) float64 px, radius (P,) int64 window radii in 1 .. R, fits
    (R + 1, 6, (2R+1)²) each radius' quadratic fit operator (its first (2r+1)² columns used),
    weights (R + 1, (2R+1)²) each radius' window weights, summing to 1.
    """
    n = pts.shape[0]
    out = np.zeros((n, 5))
    big = fits.shape[2]
    vals = np.empty(big)
    anti = np.empty(big)
    for p in range(n):
        r = radius[p]
        side = 2 * r + 1
        m = side * side
        _sample_grid(img, pts[p, 0], pts[p, 1], -r, side, vals)
        a = b = c = d = e = f = 0.0
        for k in range(m):
            v = vals[k]
            a += fits[r, 0, k] * v
            b += fits[r, 1, k] * v
            c += fits[r, 2, k] * v
            d += fits[r, 3, k] * v
            e += fits[r, 4, k] * v
            f += fits[r, 5, k] * v
        mean = 0.0
        for k in range(m):
            mean += weights[r, k] * 0.5 * (vals[k] + vals[m - 1 - k])
        odd2 = even2 = left2 = 0.0
        for k in range(m):
            w = weights[r, k]
            o = 0.5 * (vals[k] - vals[m - 1 - k])
            s = 0.5 * (vals[k] + vals[m - 1 - k]) - mean
            dx = float(k % side - r)
            dy = float(k // side - r)
            q = vals[k] - (a * dx * dx + b * dx * dy + c * dy * dy + d * dx + e * dy + f)
            odd2 += w * o * o
            even2 += w * s * s
            left2 += w * q * q
            anti[k] = abs(o)
        out[p, 0] = math.sqrt(odd2)
        out[p, 1] = np.median(anti[:m])
        out[p, 2] = math.sqrt(even2)
        out[p, 3] = math.sqrt(left2)
        out[p, 4] = math.sqrt(abs(4 * a * c - b * b))
    return out


@kernel("f8[:, ::1], i8[:, ::1]")
def lattice_bend(pts, ids):
    """(P,) float64 px: the mean |c(i−1) − 2 c(i) + c(i+1)| along the board's rows and columns at each
    point, over the directions with both neighbours present; −1 where neither has them.

    pts (P, 2) px, ids (P, 2) int64 (col, row), distinct, non-negative.
    """
    n = pts.shape[0]
    out = np.full(n, -1.0)
    if n == 0:
        return out
    cols = rows = 0
    for p in range(n):
        cols = max(cols, ids[p, 0] + 1)
        rows = max(rows, ids[p, 1] + 1)
    where = np.full((rows, cols), -1, np.int64)
    for p in range(n):
        where[ids[p, 1], ids[p, 0]] = p
    for p in range(n):
        i, j = ids[p, 0], ids[p, 1]
        total, count = 0.0, 0
        if 0 < i < cols - 1 and where[j, i - 1] >= 0 and where[j, i + 1] >= 0:
            u, v = where[j, i - 1], where[j, i + 1]
            total += math.hypot(pts[u, 0] - 2 * pts[p, 0] + pts[v, 0], pts[u, 1] - 2 * pts[p, 1] + pts[v, 1])
            count += 1
        if 0 < j < rows - 1 and where[j - 1, i] >= 0 and where[j + 1, i] >= 0:
            u, v = where[j - 1, i], where[j + 1, i]
            total += math.hypot(pts[u, 0] - 2 * pts[p, 0] + pts[v, 0], pts[u, 1] - 2 * pts[p, 1] + pts[v, 1])
            count += 1
        if count:
            out[p] = total / count
    return out
