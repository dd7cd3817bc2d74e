"""The grid seed search, compiled (numba): the maths is :func:`aicalib_tf.detect.chessboard.grid_seeds.place_seed`'s.

Grid assembly tries a seed at every candidate, dozens per image, each a few dozen small array
operations; compiled, the per-call overhead goes.
"""

from __future__ import annotations

import math

import numpy as np

from aicalib_tf.kernels import helper, kernel

from aicalib_tf.detect.corners.sampling import _bilinear

__all__ = ["edge_contrasts", "seed_block", "grow_lines"]

EDGE_STEPS = (0.35, 0.5, 0.65)  # where along a segment its two sides are sampled
EDGE_SIDE = 0.25  # how far to each side, in segment lengths


@kernel("f4[:, ::1], f8[:, ::1], f8[:, ::1]")
def edge_contrasts(img, p, q):
    """(M,) float32: |mean left − mean right| of img (H, W) along each segment p → q ((M, 2) px),
    sampled (bilinear, the nearest edge pixel outside) at ``EDGE_STEPS`` of the way, ``EDGE_SIDE``
    of its length to each side. The maths of :func:`aicalib_tf.detect.chessboard.grid_seeds.edge_contrast`."""
    m = p.shape[0]
    out = np.empty(m, np.float32)
    for k in range(m):
        dx, dy = q[k, 0] - p[k, 0], q[k, 1] - p[k, 1]
        nx, ny = -dy * EDGE_SIDE, dx * EDGE_SIDE
        left = right = 0.0
        for t in EDGE_STEPS:
            mx, my = p[k, 0] + t * dx, p[k, 1] + t * dy
            left += _bilinear(img, mx + nx, my + ny)
            right += _bilinear(img, mx - nx, my - ny)
        out[k] = abs(left - right) / len(EDGE_STEPS)
    return out


@kernel("f8[:, ::1], i8, i8[::1], f8[::1], b1[::1], f8[:, :, ::1], i8, f8, f8, f8, f8")
def seed_block(pts, k, near, contrast, free, blocks, orders, tolerance, max_step_ratio, max_cell_area, max_span_ratio):
    """The first block of lattice points about point ``k`` that the seed pairs place on free points.

    pts (N, 2) float64; near (K,) int64, k's near points; contrast (K,) float64 (empty: no edge
    test); free (N,) bool; blocks (B, M, 2) float64 block offsets (i, j) of u and v; orders: 1, or 2
    to try each pair both ways round. The rules are those of :func:`aicalib_tf.detect.chessboard.grid_seeds.place_seed`.
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



@helper
def _cell(g, oi, oj, i, j):
    """The point index at lattice cell (i, j) of ``g`` (origin at row oi, column oj), or -1."""
    r, c = i + oi, j + oj
    if r < 0 or c < 0 or r >= g.shape[0] or c >= g.shape[1]:
        return -1
    return g[r, c]


@helper
def _next_line(g, oi, oj, pts, axis, sign, new, olo, ohi, tolerance):
    """The predictions for line ``new`` beyond one side (:func:`grow_lines`): the other-axis position
    of each line that predicts, the predicted x and y, and the tolerance, each (C,)."""
    b1, b2, b3 = new - sign, new - 2 * sign, new - 3 * sign
    m = ohi - olo + 1
    cell_o = np.empty(m, np.int64)
    px, py, tol = np.empty(m), np.empty(m), np.empty(m)
    c = 0
    for o in range(olo, ohi + 1):
        if axis == 0:
            q1, q2, q3 = _cell(g, oi, oj, b1, o), _cell(g, oi, oj, b2, o), _cell(g, oi, oj, b3, o)
        else:
            q1, q2, q3 = _cell(g, oi, oj, o, b1), _cell(g, oi, oj, o, b2), _cell(g, oi, oj, o, b3)
        if q1 < 0 or q2 < 0:
            continue
        if q3 >= 0:  # quadratic where three points are known, as grid_growth._work_out_side
            px[c] = 3 * pts[q1, 0] - 3 * pts[q2, 0] + pts[q3, 0]
            py[c] = 3 * pts[q1, 1] - 3 * pts[q2, 1] + pts[q3, 1]
        else:
            px[c] = 2 * pts[q1, 0] - pts[q2, 0]
            py[c] = 2 * pts[q1, 1] - pts[q2, 1]
        dx, dy = pts[q1, 0] - pts[q2, 0], pts[q1, 1] - pts[q2, 1]
        tol[c] = tolerance * math.sqrt(dx * dx + dy * dy)
        cell_o[c] = o
        c += 1
    return cell_o[:c], px[:c], py[:c], tol[:c]


@helper
def _nearest_free(pts, fr, px, py, tol):
    """For each prediction (px, py) the nearest free point (the lowest index of equals) when within
    its tol, else −1; and how many were found."""
    found = np.full(px.shape[0], -1, np.int64)
    hits = 0
    for e in range(px.shape[0]):
        best, bd = -1, np.inf
        for k in range(pts.shape[0]):
            if fr[k]:
                dx, dy = px[e] - pts[k, 0], py[e] - pts[k, 1]
                d = dx * dx + dy * dy
                if d < bd:
                    best, bd = k, d
        if best >= 0 and bd <= tol[e] * tol[e]:
            found[e] = best
            hits += 1
    return found, hits


@helper
def _room(g, oi, oj, at):
    """``g`` (square) with room for index ``at`` along either axis: twice the size, the content in
    the middle, where ``at`` lies outside; and the origin moved with it."""
    if 0 <= at < g.shape[0]:
        return g, oi, oj
    q = g.shape[0] // 2
    g2 = np.full((2 * g.shape[0], 2 * g.shape[0]), -1, np.int64)
    g2[q: q + g.shape[0], q: q + g.shape[1]] = g
    return g2, oi + q, oj + q


@helper
def _distinct(found):
    """True when no point index (≥ 0) appears twice in ``found``."""
    for e in range(found.shape[0]):
        for f in range(e):
            if found[e] >= 0 and found[e] == found[f]:
                return False
    return True


@kernel("f8[:, ::1], b1[::1], i8[:, ::1], i8, b1, f8")
def grow_lines(pts, free, seed, limit, whole, tolerance):
    """Grow a seeded lattice from candidate points alone, one grid line at a time, until no side grows.

    The maths and order of :func:`aicalib_tf.detect.chessboard.grid_growth.grow` in a phase where ``propose`` is not
    asked and lines do not bend strongly: the sides in turn (axis 0 then 1, + then −), each grown
    while it can, until a round adds nothing. A line is added when all (``whole``) or at least half
    (and 2) of its predictions (:func:`_next_line`) find distinct free points (:func:`_nearest_free`),
    and not beyond ``limit`` positions along an axis (−1: no limit).

    pts (N, 2) float64 (x, y) px; free (N,) bool (not changed); seed (M, 3) int64 rows (i, j,
    point index), the cells taken so far. Returns (T, 3) int64: the cells taken, in order.
    """
    fr = free.copy()
    imin, imax, jmin, jmax = seed[:, 0].min(), seed[:, 0].max(), seed[:, 1].min(), seed[:, 1].max()
    side = max(imax - imin, jmax - jmin) + 9
    g = np.full((2 * side, 2 * side), -1, np.int64)
    oi, oj = side - imin, side - jmin
    for s in range(seed.shape[0]):
        g[seed[s, 0] + oi, seed[s, 1] + oj] = seed[s, 2]
    out = np.empty((pts.shape[0], 3), np.int64)
    t = 0
    grown = True
    while grown:
        grown = False
        for axis in range(2):
            for sign in (1, -1):
                while True:
                    extent = imax - imin + 1 if axis == 0 else jmax - jmin + 1
                    if limit >= 0 and extent >= limit:
                        break
                    if axis == 0:
                        new = imax + 1 if sign > 0 else imin - 1
                        olo, ohi = jmin, jmax
                    else:
                        new = jmax + 1 if sign > 0 else jmin - 1
                        olo, ohi = imin, imax
                    g, oi, oj = _room(g, oi, oj, new + (oi if axis == 0 else oj))
                    cell_o, px, py, tol = _next_line(g, oi, oj, pts, axis, sign, new, olo, ohi, tolerance)
                    c = cell_o.shape[0]
                    if c == 0:
                        break
                    found, hits = _nearest_free(pts, fr, px, py, tol)
                    if whole and hits < c:
                        break
                    if hits < max(2.0, 0.5 * c) or not _distinct(found):
                        break
                    for e in range(c):
                        if found[e] < 0:
                            continue
                        i, j = (new, cell_o[e]) if axis == 0 else (cell_o[e], new)
                        g[i + oi, j + oj] = found[e]
                        fr[found[e]] = False
                        out[t, 0], out[t, 1], out[t, 2] = i, j, found[e]
                        t += 1
                    if axis == 0:
                        imin, imax = min(imin, new), max(imax, new)
                    else:
                        jmin, jmax = min(jmin, new), max(jmax, new)
                    grown = True
    return out[:t]
