"""The saddle fit's Gauss–Newton loop, compiled (numba): the maths is :func:`aicalib_tf.detect.saddle.refine_saddle`'s.

Each refinement call fits only a handful of points, hundreds of times per image; as array code
the time went on per-call overhead. Here each point runs its whole loop in compiled code.
"""

from __future__ import annotations

import math

import numpy as np

from aicalib_tf.kernels import kernel

from .sampling import _sample_grid

__all__ = ['saddle_loop']


@kernel("f4[:, ::1], f8[:, ::1], f8[:, ::1], i8, i8")
def saddle_loop(img, pts, fit, radius, iterations):
    """The saddle fit's iterations for each point.

    img (H, W) float32, pts (P, 2) float64, fit (6, (2r+1)²) the quadratic fit operator.
    Returns (P, 2) positions, (P, 2) the last step (px) and (P,) bool: the last fit was a saddle.
    """
    n = pts.shape[0]
    side = 2 * radius + 1
    m = side * side
    out = pts.copy()
    step = np.zeros((n, 2))
    saddle = np.zeros(n, np.bool_)
    vals = np.empty(m)
    for p in range(n):
        x, y = pts[p, 0], pts[p, 1]
        for _ in range(iterations):
            _sample_grid(img, x, y, -radius, side, vals)
            a = b = c = d = e = 0.0
            for k in range(m):
                v = vals[k]
                a += fit[0, k] * v
                b += fit[1, k] * v
                c += fit[2, k] * v
                d += fit[3, k] * v
                e += fit[4, k] * v
            det = 4 * a * c - b * b
            ux = uy = 0.0
            sad = det < 0
            if sad:
                ux = (-2 * c * d + b * e) / det
                uy = (b * d - 2 * a * e) / det
                norm = math.sqrt(ux * ux + uy * uy)
                if norm > 1.0:  # at most 1 px per iteration
                    ux, uy = ux / norm, uy / norm
            x += ux
            y += uy
            step[p, 0], step[p, 1], saddle[p] = ux, uy, sad
            if abs(ux) < 1e-3 and abs(uy) < 1e-3:
                break
        out[p, 0], out[p, 1] = x, y
    return out, step, saddle

