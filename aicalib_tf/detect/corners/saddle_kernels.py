"""The saddle fit's Gauss–Newton loop, compiled (numba): the maths is :func:`aicalib_tf.detect.corners.saddle.refine_saddle`'s.

Each refinement call fits only a handful of points, hundreds of times per image; as array code
the time went on per-call overhead. Here each point runs its whole loop in compiled code.
"""

from __future__ import annotations

import math

import numpy as np

from aicalib_tf.kernels import kernel

from .sampling import _sample_grid

__all__ = ['saddle_refine']

CONVERGED = 0.05  # px: a fit whose last step is at least this long did not settle


@kernel("f4[:, ::1], f8[:, ::1], f8[:, ::1], i8, i8, f8")
def saddle_refine(img, pts, fit, radius, iterations, max_shift):
    """The saddle fit's iterations for each point, and whether each result holds.

    img (H, W) float32, pts (P, 2) float64 px, fit (6, (2r+1)²) the quadratic fit operator,
    max_shift px. A point holds (ok) when its last fit was a saddle, its last step was under
    ``CONVERGED``, it ended within ``max_shift`` of its start and inside the image's outer edge
    (x in [−0.5, W − 0.5], y in [−0.5, H − 0.5]). Returns (P, 2) float64, the point's saddle where it
    holds and its start otherwise, and (P,) bool ok.
    """
    n = pts.shape[0]
    h, w = img.shape
    side = 2 * radius + 1
    m = side * side
    out = pts.copy()
    ok = np.zeros(n, np.bool_)
    vals = np.empty(m)
    for p in range(n):
        x, y = pts[p, 0], pts[p, 1]
        ux = uy = 0.0
        sad = False
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
            if abs(ux) < 1e-3 and abs(uy) < 1e-3:
                break
        dx, dy = x - pts[p, 0], y - pts[p, 1]
        if (sad and math.sqrt(ux * ux + uy * uy) < CONVERGED and math.sqrt(dx * dx + dy * dy) <= max_shift
                and x >= -0.5 and x <= w - 0.5 and y >= -0.5 and y <= h - 0.5):
            ok[p] = True
            out[p, 0], out[p, 1] = x, y
    return out, ok
