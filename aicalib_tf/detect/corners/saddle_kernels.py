"""The saddle fit's Gauss–Newton loop, compiled (numba): the maths is :func:`aicalib_tf.detect.corners.saddle.refine_saddle`'s.

Each refinement call fits only a handful of points, hundreds of times per image; as array code
the time went on per-call overhead. Here each point runs its whole loop in compiled code.
"""

from __future__ import annotations

import math

import numpy as np

from aicalib_tf.kernels import helper, kernel

from .sampling import _sample_grid

__all__ = ['ramp_symmetric', 'saddle_refine']

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


@helper
def _cholesky_solve4(a, b):
    """Solve a·u = b in place (u into b) for the symmetric 4×4 a given by its lower triangle; False if not
    positive definite."""
    for c in range(4):
        s = a[c, c]
        for k in range(c):
            s -= a[c, k] * a[c, k]
        if not (s > 0.0 and s > 1e-10 * a[c, c]):
            return False
        a[c, c] = math.sqrt(s)
        for r in range(c + 1, 4):
            t = a[r, c]
            for k in range(c):
                t -= a[r, k] * a[c, k]
            a[r, c] = t / a[c, c]
    for r in range(4):  # forward: L z = b
        t = b[r]
        for k in range(r):
            t -= a[r, k] * b[k]
        b[r] = t / a[r, r]
    for r in range(3, -1, -1):  # back: Lᵀ u = z
        t = b[r]
        for k in range(r + 1, 4):
            t -= a[k, r] * b[k]
        b[r] = t / a[r, r]
    return True


@kernel("f4[:, ::1], f8[:, ::1], i8, f8[::1], i8")
def ramp_symmetric(img, pts, radius, weights, iterations):
    """The point-symmetric fit under a linear light ramp: each point's Gauss–Newton loop and its last step.

    img (H, W) float32, pts (P, 2) float64 px, weights ((2r+1)²,) the Gaussian weights of the window's
    offsets o (row-major, dy outer). Each step solves, over the pairs (o, −o) of the window, the weighted
    least squares of D(o) + J(o)·u = E(o)·(g·o) for the step u and the ramp g (1/px), with
    D(o) = I(c + o) − I(c − o), E(o) = I(c + o) + I(c − o) and J(o) = ∇I(c + o) − ∇I(c − o) (central
    differences of the bilinear samples); each step is at most 1 px. Returns (P, 2) float64, where
    each loop ended, and (P,) float64, the length of its last step (px; inf where the normal
    equations were singular).
    """
    n = pts.shape[0]
    side = 2 * radius + 3
    big = np.empty(side * side)
    out = pts.copy()
    last = np.full(n, np.inf)
    a = np.empty((4, 4))
    b = np.empty(4)
    v = np.empty(4)
    for p in range(n):
        x, y = pts[p, 0], pts[p, 1]
        for _ in range(iterations):
            _sample_grid(img, x, y, -radius - 1, side, big)
            a[:] = 0.0
            b[:] = 0.0
            k = -1
            for j in range(-radius, radius + 1):
                for i in range(-radius, radius + 1):
                    k += 1
                    if j < 0 or (j == 0 and i <= 0):
                        continue  # each pair (o, −o) once
                    q = (j + radius + 1) * side + i + radius + 1
                    qm = (radius + 1 - j) * side + radius + 1 - i
                    d = big[q] - big[qm]
                    e = big[q] + big[qm]
                    v[0] = 0.5 * (big[q + 1] - big[q - 1] - big[qm + 1] + big[qm - 1])
                    v[1] = 0.5 * (big[q + side] - big[q - side] - big[qm + side] + big[qm - side])
                    v[2] = -e * i
                    v[3] = -e * j
                    w = weights[k]
                    for r in range(4):
                        b[r] -= w * v[r] * d
                        for c in range(r + 1):
                            a[r, c] += w * v[r] * v[c]
            if not _cholesky_solve4(a, b):
                last[p] = np.inf
                break
            ux, uy = b[0], b[1]
            norm = math.sqrt(ux * ux + uy * uy)
            if norm > 1.0:  # at most 1 px per iteration
                ux, uy = ux / norm, uy / norm
            x += ux
            y += uy
            last[p] = math.sqrt(ux * ux + uy * uy)
            if last[p] < 1e-3:
                break
        out[p, 0], out[p, 1] = x, y
    return out, last

