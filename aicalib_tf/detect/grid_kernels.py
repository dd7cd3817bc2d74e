"""The grid seed search, compiled (numba): the maths is :func:`aicalib_tf.detect.grid._seed`'s.

Grid assembly tries a seed at every candidate, dozens per image, each a few dozen small array
operations; compiled, the per-call overhead goes.
"""

from __future__ import annotations

import math

import numpy as np

from aicalib_tf.kernels import kernel

__all__ = ['seed_block']


@kernel("f8[:, ::1], i8, i8[::1], f8[::1], b1[::1], f8[:, :, ::1], i8, f8, f8, f8, f8")
def seed_block(pts, k, near, contrast, free, blocks, orders, tolerance, max_step_ratio, max_cell_area, max_span_ratio):
    """The first block of lattice points about point ``k`` that the seed pairs place on free points.

    pts (N, 2) float64; near (K,) int64, k's near points; contrast (K,) float64 (empty: no edge
    test); free (N,) bool; blocks (B, M, 2) float64 block offsets (i, j) of u and v; orders: 1, or 2
    to try each pair both ways round. The rules are those of :func:`aicalib_tf.grid._seed`.
    Returns (b, u index, v index, found (M,) int64) of the first block found, or b = −1.
    """
    # size: one compiled loop: split into calls, numba would pass its arrays back and forth per seed.
    p0, p1 = pts[k, 0], pts[k, 1]
    n = near.shape[0]
    sx, sy, ln = np.empty(n), np.empty(n), np.empty(n)
    for a in range(n):
        sx[a], sy[a] = pts[near[a], 0] - p0, pts[near[a], 1] - p1
        ln[a] = math.sqrt(sx[a] * sx[a] + sy[a] * sy[a])
    cmax = -np.inf
    for a in range(contrast.shape[0]):
        cmax = max(cmax, contrast[a])
    keep = np.empty(n, np.int64)
    m = 0
    for a in range(n):  # single steps (no near point part-way along them), along square edges
        l2, l1 = max(ln[a] * ln[a], 1e-12), max(ln[a], 1e-12)
        single = True
        for b in range(n):
            t = (sx[a] * sx[b] + sy[a] * sy[b]) / l2
            off = abs(sx[a] * sy[b] - sy[a] * sx[b]) / l1
            if t > 0.2 and t < 0.8 and off < tolerance * ln[b]:
                single = False
                break
        if single and (contrast.shape[0] == 0 or contrast[a] >= 0.5 * cmax):
            keep[m] = a
            m += 1
    npair = m * (m - 1) // 2
    pa, pb = np.empty(npair, np.int64), np.empty(npair, np.int64)
    pcos, parea, pspan = np.empty(npair), np.empty(npair), np.empty(npair)
    q = 0
    for i in range(m):
        for j in range(i + 1, m):
            a, b = keep[i], keep[j]
            nu, nv = ln[a], ln[b]
            if nu < 1.0 or nv < 1.0 or not (1 / max_step_ratio <= nu / nv <= max_step_ratio):
                continue
            cos = abs(sx[a] * sx[b] + sy[a] * sy[b]) / (nu * nv)
            if cos < 0.95:
                pa[q], pb[q], pcos[q] = a, b, cos
                parea[q] = abs(sx[a] * sy[b] - sy[a] * sx[b])
                pspan[q] = nu + nv
                q += 1
    if q == 0:
        return -1, 0, 0, np.full(blocks.shape[1], -1, np.int64)
    amin = np.inf
    for i in range(q):
        amin = min(amin, parea[i])
    smin = np.inf
    for i in range(q):
        if not parea[i] > max_cell_area * amin:
            smin = min(smin, pspan[i])
    sel = np.empty(q, np.int64)
    r = 0
    for i in range(q):
        if not parea[i] > max_cell_area * amin and pspan[i] <= max_span_ratio * smin:
            sel[r] = i
            r += 1
    for i in range(1, r):  # insertion sort by (span, cos, a, b): the order pairs are tried in
        x = sel[i]
        j = i - 1
        while j >= 0:
            y = sel[j]
            if (pspan[y], pcos[y], pa[y], pb[y]) > (pspan[x], pcos[x], pa[x], pb[x]):
                sel[j + 1] = y
                j -= 1
            else:
                break
        sel[j + 1] = x
    reach = 0.0
    for i in range(r):
        s = sel[i]
        reach = max(reach, pspan[s] + tolerance * min(ln[pa[s]], ln[pb[s]]))
    reach += 1.0
    cand = np.empty(pts.shape[0], np.int64)
    nc = 0
    for c in range(pts.shape[0]):
        dx, dy = pts[c, 0] - p0, pts[c, 1] - p1
        if dx * dx + dy * dy <= reach * reach and free[c]:
            cand[nc] = c
            nc += 1
    nm = blocks.shape[1]
    found = np.empty(nm, np.int64)
    for i in range(r):
        s = sel[i]
        tol = tolerance * min(ln[pa[s]], ln[pb[s]])
        for o in range(orders):
            ua, va = (pa[s], pb[s]) if o == 0 else (pb[s], pa[s])
            for bi in range(blocks.shape[0]):
                ok = True
                for e in range(nm):
                    px = p0 + blocks[bi, e, 0] * sx[ua] + blocks[bi, e, 1] * sx[va]
                    py = p1 + blocks[bi, e, 0] * sy[ua] + blocks[bi, e, 1] * sy[va]
                    best, bd = -1, np.inf
                    for cc in range(nc):
                        c = cand[cc]
                        dx, dy = px - pts[c, 0], py - pts[c, 1]
                        d = dx * dx + dy * dy
                        if d < bd:
                            best, bd = c, d
                    if best < 0 or bd > tol * tol or best == k:
                        ok = False
                        break
                    for f in range(e):
                        if found[f] == best:
                            ok = False
                    if not ok:
                        break
                    found[e] = best
                if ok:
                    return bi, ua, va, found
    return -1, 0, 0, np.full(nm, -1, np.int64)

