"""The shadow-edge symmetric fit and its asymmetry energies, compiled (numba): the maths is that of
:func:`aicalib_tf.detect.corners.shadow.refine_symmetric` and :func:`aicalib_tf.detect.corners.shadow.asymmetry`.
"""

from __future__ import annotations

import math

import numpy as np

from aicalib_tf.kernels import helper, kernel

from .sampling import _sample_grid

__all__ = ['symmetric_loop', 'symmetry_energies']


@helper
def _n_bins(kbin):
    """How many 1 px bins of |n·o| the (M, D) bin table uses."""
    nk = 0
    for k in range(kbin.shape[0]):
        for t in range(kbin.shape[1]):
            nk = max(nk, kbin[k, t] + 1)
    return nk


@helper
def _symmetric_step(big, side, inner, weights, mirror, kbin, sign, nk, acc, cand):
    """One Gauss–Newton step of the shadow-robust fit from the (2r+3)² samples ``big``: (ux, uy)."""
    m = inner.shape[0]
    ndir = kbin.shape[1]
    acc[:] = 0.0  # (ndir, nk, 4): Σ w e² , Σ± w e d, Σ± w e jx, Σ± w e jy per direction and bin
    a11 = a12 = a22 = b1 = b2 = c0 = 0.0
    for k in range(m):
        q, qm = inner[k], inner[mirror[k]]
        i0, i1 = big[q], big[qm]
        d = i0 - i1
        e = 0.5 * (i0 + i1)
        jx = 0.5 * (big[q + 1] - big[q - 1]) - 0.5 * (big[qm + 1] - big[qm - 1])
        jy = 0.5 * (big[q + side] - big[q - side]) - 0.5 * (big[qm + side] - big[qm - side])
        w = weights[k]
        a11 += w * jx * jx
        a12 += w * jx * jy
        a22 += w * jy * jy
        b1 += w * jx * d
        b2 += w * jy * d
        c0 += w * d * d
        we = w * e
        for t in range(ndir):
            b = kbin[k, t]
            s = sign[k, t]
            acc[t, b, 0] += we * e
            acc[t, b, 1] += s * we * d
            acc[t, b, 2] += s * we * jx
            acc[t, b, 3] += s * we * jy
    cand[0, 0], cand[0, 1], cand[0, 2], cand[0, 3], cand[0, 4], cand[0, 5] = a11, a12, a22, b1, b2, c0
    for t in range(ndir):
        g0 = g1 = g2 = g3 = g4 = g5 = 0.0
        for b in range(nk):
            see = acc[t, b, 0] + 1e-12
            sed, sex, sey = acc[t, b, 1], acc[t, b, 2], acc[t, b, 3]
            g0 += sex * sex / see
            g1 += sex * sey / see
            g2 += sey * sey / see
            g3 += sex * sed / see
            g4 += sey * sed / see
            g5 += sed * sed / see
        cand[t + 1, 0], cand[t + 1, 1], cand[t + 1, 2] = a11 - g0, a12 - g1, a22 - g2
        cand[t + 1, 3], cand[t + 1, 4], cand[t + 1, 5] = b1 - g3, b2 - g4, c0 - g5
    best, best_ux, best_uy = np.inf, 0.0, 0.0
    for t in range(ndir + 1):  # the model (none, or a shadow direction) that leaves the least
        A11, A12, A22, B1, B2, C0 = cand[t, 0], cand[t, 1], cand[t, 2], cand[t, 3], cand[t, 4], cand[t, 5]
        det = A11 * A22 - A12 * A12
        if not det > 1e-18 * max(A11 * A22, 1e-30):
            continue
        ux = -(A22 * B1 - A12 * B2) / det
        uy = -(A11 * B2 - A12 * B1) / det
        resid = C0 + B1 * ux + B2 * uy
        if resid < best:
            best, best_ux, best_uy = resid, ux, uy
    return best_ux, best_uy


@kernel("f4[:, ::1], f8[:, ::1], i8, f8[::1], i8[::1], i8[:, ::1], f8[:, ::1], i8")
def symmetric_loop(img, pts, radius, weights, mirror, kbin, sign, iterations):
    """The shadow-robust fit's iterations for each point.

    img (H, W) float32, pts (P, 2) float64; for the (2r+1)² window in row-major order: weights (M,),
    mirror (M,) int (index of −o), kbin (M, D) int (bin of |n·o| per direction) and sign (M, D)
    (±1 sign of n·o). Returns (P, 2) positions and (P,) the last step's length (px).
    """
    n = pts.shape[0]
    side = 2 * radius + 3
    m = (2 * radius + 1) ** 2
    inner = np.empty(m, np.int64)
    for k in range(m):
        inner[k] = (k // (2 * radius + 1) + 1) * side + (k % (2 * radius + 1)) + 1
    nk = _n_bins(kbin)
    acc = np.empty((kbin.shape[1], nk, 4))
    cand = np.empty((kbin.shape[1] + 1, 6))
    big = np.empty(side * side)
    out = pts.copy()
    last = np.full(n, np.inf)
    for p in range(n):
        x, y = pts[p, 0], pts[p, 1]
        px = py = 0.0
        damp = 1.0
        for _ in range(iterations):
            _sample_grid(img, x, y, -radius - 1, side, big)
            ux, uy = _symmetric_step(big, side, inner, weights, mirror, kbin, sign, nk, acc, cand)
            # the model can switch between two points a step apart, each sending the fit back to the
            # other: a step against the last one halves the steps from then on
            if ux * px + uy * py < 0:
                damp *= 0.5
            ux, uy = ux * damp, uy * damp
            norm = math.sqrt(ux * ux + uy * uy)
            scale = min(1.0, 1.0 / max(norm, 1e-12))  # at most 1 px per iteration
            x += ux * scale
            y += uy * scale
            px, py = ux, uy
            last[p] = norm
            if norm < 1e-3:
                break
        out[p, 0], out[p, 1] = x, y
    return out, last


@kernel("f4[:, ::1], f8[:, ::1], i8, f8[::1], i8[::1], i8[:, ::1], f8[:, ::1], b1")
def symmetry_energies(img, pts, radius, weights, mirror, kbin, sign, shadow):
    """How far the window about each point is from point symmetry, as three energies per point.

    img (H, W) float32, pts (P, 2) float64; weights, mirror, kbin, sign as in :func:`symmetric_loop`.
    Returns (P, 3): odd Σ w d², even 4 Σ w (e − ē)² (ē the weighted mean of e), and, with
    ``shadow``, the most of the odd energy that one shadow direction's model d = e·h(n·o) explains,
    max over directions of Σ_bins (Σ ± w e d)² / (Σ w e² + 1e-12) (0 without ``shadow``);
    d = I(p + o) − I(p − o), e = (I(p + o) + I(p − o)) / 2.
    """
    side = 2 * radius + 1
    m = side * side
    ndir = kbin.shape[1]
    nk = _n_bins(kbin)
    acc = np.empty((ndir, nk, 2))
    vals = np.empty(m)
    even = np.empty(m)
    wsum = 0.0
    for k in range(m):
        wsum += weights[k]
    out = np.zeros((pts.shape[0], 3))
    for p in range(pts.shape[0]):
        _sample_grid(img, pts[p, 0], pts[p, 1], -radius, side, vals)
        odd = mean = 0.0
        acc[:] = 0.0
        for k in range(m):
            i0, i1 = vals[k], vals[mirror[k]]
            d, e = i0 - i1, 0.5 * (i0 + i1)
            w = weights[k]
            odd += w * d * d
            mean += w * e
            even[k] = e
            if shadow:
                for t in range(ndir):
                    acc[t, kbin[k, t], 0] += w * e * e
                    acc[t, kbin[k, t], 1] += sign[k, t] * w * e * d
        mean /= wsum
        ev = 0.0
        for k in range(m):
            ev += weights[k] * (even[k] - mean) ** 2
        best = -np.inf
        if shadow:
            for t in range(ndir):
                s = 0.0
                for b in range(nk):
                    s += acc[t, b, 1] ** 2 / (acc[t, b, 0] + 1e-12)
                best = max(best, s)
        out[p, 0], out[p, 1], out[p, 2] = odd, 4 * ev, best if shadow else 0.0
    return out

