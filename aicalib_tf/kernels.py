"""Compiled inner loops of the detector (numba; pure numpy/OpenCV callers, no TensorFlow).

Each refinement call fits only a handful of points, so as numpy array code its time went on
per-call overhead: a grid or a partial board asks the fits about a few points at a time, hundreds
of times per image. Here each point runs its whole Gauss–Newton loop in compiled code, on exact
bilinear samples of the image (``cv2.remap`` rounds the sample position to 1/32 px).

The grid seed search (:func:`seed_block`) is compiled for the same reason: grid assembly tries a
seed at every candidate, dozens per image, each a few dozen small array operations. So are the
lattice sums of a partial board's growth (:func:`nearest_predict`, :func:`lattice_residuals_loop`,
:func:`nearest_steps`): a board grown from a strip of corners asks them some forty times, with
N × N distance tables and sorts each time. So is the corner map's decoding (:func:`decode_cells`):
every image's map, some 20,000 cells of which about a hundred are looked at, took 0.28 ms as
array code and takes 0.03 ms here.

The maths is that of :func:`aicalib_tf.refine.refine_saddle`,
:func:`aicalib_tf.robust_refine.refine_symmetric` (and its asymmetry measures),
:func:`aicalib_tf.junctions.ring_symmetry`, :func:`aicalib_tf.corner_map.decode_map`, :func:`aicalib_tf.lattice.predict_ids`,
:func:`aicalib_tf.lattice.lattice_residuals`, :func:`aicalib_tf.lattice.local_step` and
:func:`aicalib_tf.grid._seed`, whose docstrings define it; these functions are their loops and take the fixed operators those modules build. Images are (H, W) float32; points
are (x, y) px with the centre of pixel (0, 0) at (0.0, 0.0); samples outside the image take the
nearest edge pixel (OpenCV's BORDER_REPLICATE). Compiled on first use and cached on disk.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["decode_cells", "lattice_predict", "nearest_steps", "lattice_residuals_loop", "nearest_predict", "ring_stats", "saddle_loop", "sample_windows", "seed_block", "symmetric_loop", "symmetry_energies"]


@njit(cache=True, nogil=True)
def _lerp(img, r0, r1, c0, c1, fx, fy):
    """Bilinear value between pixels (r0, c0), (r0, c1), (r1, c0), (r1, c1) at fractions fx, fy."""
    top = img[r0, c0] + fx * (img[r0, c1] - img[r0, c0])
    bot = img[r1, c0] + fx * (img[r1, c1] - img[r1, c0])
    return top + fy * (bot - top)


@njit(cache=True, nogil=True)
def _n_bins(kbin):
    """How many 1 px bins of |n·o| the (M, D) bin table uses."""
    nk = 0
    for k in range(kbin.shape[0]):
        for t in range(kbin.shape[1]):
            nk = max(nk, kbin[k, t] + 1)
    return nk


@njit(cache=True, nogil=True)
def _sample_grid(img, x, y, lo, side, out):
    """Bilinear samples at (x + i, y + j) for i, j in lo .. lo + side − 1, row-major into out (side²,)."""
    h, w = img.shape
    x0, y0 = math.floor(x), math.floor(y)
    fx, fy = x - x0, y - y0
    k = 0
    for j in range(side):
        r0 = min(max(y0 + lo + j, 0), h - 1)
        r1 = min(max(y0 + lo + j + 1, 0), h - 1)
        for i in range(side):
            c0 = min(max(x0 + lo + i, 0), w - 1)
            c1 = min(max(x0 + lo + i + 1, 0), w - 1)
            out[k] = _lerp(img, r0, r1, c0, c1, fx, fy)
            k += 1


@njit(cache=True, nogil=True)
def decode_cells(cmap, threshold, min_distance, pool_distance, pool_floor, stride):
    """The cell loop of :func:`aicalib_tf.corner_map.decode_map`, whose docstring defines it.

    cmap : (h, w, 3) float32. The other arguments are float32 scalars. Only cells of weight
    >= min(threshold, pool_floor) are looked at, in row-major order.
    Returns x, y, score (pooled weight, capped at 1), own weight, each (K,) float32, of the cells kept.
    """
    h, w = cmap.shape[0], cmap.shape[1]
    one, half = np.float32(1.0), np.float32(0.5)
    floor = min(threshold, pool_floor)
    near2, pool2 = min_distance * min_distance, pool_distance * pool_distance
    n = 0
    for i in range(h):
        for j in range(w):
            if cmap[i, j, 0] >= floor:
                n += 1
    xs, ys = np.empty(n, np.float32), np.empty(n, np.float32)
    sc, own = np.empty(n, np.float32), np.empty(n, np.float32)
    k = 0
    for i in range(h):
        for j in range(w):
            p = cmap[i, j, 0]
            if p < floor:
                continue
            x = stride * (np.float32(j) + cmap[i, j, 1]) - half
            y = stride * (np.float32(i) + cmap[i, j, 2]) - half
            pooled, sx, sy = p, p * x, p * y
            keep = True
            for di in range(-1, 2):
                for dj in range(-1, 2):
                    a, b = i + di, j + dj
                    if (di == 0 and dj == 0) or a < 0 or a >= h or b < 0 or b >= w:
                        continue
                    q = cmap[a, b, 0]
                    qx = stride * (np.float32(b) + cmap[a, b, 1]) - half
                    qy = stride * (np.float32(a) + cmap[a, b, 2]) - half
                    d2 = (qx - x) ** 2 + (qy - y) ** 2
                    if d2 < pool2 and q >= pool_floor:
                        pooled += q
                        sx += q * qx
                        sy += q * qy
                    # a close neighbour that is stronger (ties: the one earlier in row-major order) suppresses
                    if d2 < near2 and (q > p or (q == p and (di < 0 or (di == 0 and dj < 0)))):
                        keep = False
            if keep and pooled >= threshold:
                den = max(pooled, np.float32(1e-12))
                xs[k], ys[k] = sx / den, sy / den
                sc[k], own[k] = min(pooled, one), p
                k += 1
    return xs[:k], ys[:k], sc[:k], own[:k]


@njit(cache=True, nogil=True)
def sample_windows(img, pts, radius):
    """(P, (2r+1)²) float64: bilinear samples of img about each point, offsets row-major (dy outer)."""
    side = 2 * radius + 1
    out = np.empty((pts.shape[0], side * side))
    for p in range(pts.shape[0]):
        _sample_grid(img, pts[p, 0], pts[p, 1], -radius, side, out[p])
    return out


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
def _normaliser(p, idx):
    """Mean (2,) and scale of points p[idx]: centred, their mean distance from the mean becomes √2."""
    mx = my = 0.0
    for t in idx:
        mx += p[t, 0]
        my += p[t, 1]
    mx /= len(idx)
    my /= len(idx)
    dist = 0.0
    for t in idx:
        dist += math.sqrt((p[t, 0] - mx) ** 2 + (p[t, 1] - my) ** 2)
    return mx, my, math.sqrt(2.0) / max(dist / len(idx), 1e-12)


@njit(cache=True, nogil=True)
def _solve8(a, b):
    """Solve a (8, 8) x = b (8,) in place by Gaussian elimination with partial pivoting; returns det(a)."""
    n = 8
    det = 1.0
    for c in range(n):
        piv = c
        for r in range(c + 1, n):
            if abs(a[r, c]) > abs(a[piv, c]):
                piv = r
        if piv != c:
            for q in range(n):
                a[c, q], a[piv, q] = a[piv, q], a[c, q]
            b[c], b[piv] = b[piv], b[c]
            det = -det
        det *= a[c, c]
        if a[c, c] == 0.0:
            return 0.0
        for r in range(c + 1, n):
            f = a[r, c] / a[c, c]
            if f != 0.0:
                for q in range(c, n):
                    a[r, q] -= f * a[c, q]
                b[r] -= f * b[c]
    for c in range(n - 1, -1, -1):
        s = b[c]
        for q in range(c + 1, n):
            s -= a[c, q] * b[q]
        b[c] = s / a[c, c]
    return det


@njit(cache=True, nogil=True)
def _fit_lattice(ids, pts, idx, ata, atb, row, norm):
    """Fit the homography of ids[idx] -> pts[idx] (see :func:`lattice_predict`) into atb (8,).

    norm (6,) gets the id and point normalisers (sx, sy, ss, dx, dy, ds). Returns False where the
    normal equations are singular.
    """
    sx, sy, ss = _normaliser(ids, idx)
    dx, dy, ds = _normaliser(pts, idx)
    norm[0], norm[1], norm[2], norm[3], norm[4], norm[5] = sx, sy, ss, dx, dy, ds
    ata[:] = 0.0
    atb[:] = 0.0
    for t in idx:
        x, y = (ids[t, 0] - sx) * ss, (ids[t, 1] - sy) * ss
        u, v = (pts[t, 0] - dx) * ds, (pts[t, 1] - dy) * ds
        for rhs, other in ((u, 0), (v, 1)):
            row[:] = 0.0
            row[3 * other], row[3 * other + 1], row[3 * other + 2] = x, y, 1.0
            row[6], row[7] = -rhs * x, -rhs * y
            for i in range(8):
                if row[i] != 0.0:
                    atb[i] += row[i] * rhs
                    for j in range(8):
                        ata[i, j] += row[i] * row[j]
    return abs(_solve8(ata, atb)) > 1e-12


@njit(cache=True, nogil=True)
def _apply_lattice(h, norm, wx, wy, out):
    """Put id (wx, wy) in the image with a fit of :func:`_fit_lattice`: out (2,) px."""
    sx, sy, ss, dx, dy, ds = norm[0], norm[1], norm[2], norm[3], norm[4], norm[5]
    x, y = (wx - sx) * ss, (wy - sy) * ss
    w = h[6] * x + h[7] * y + 1.0
    out[0] = (h[0] * x + h[1] * y + h[2]) / w / ds + dx
    out[1] = (h[3] * x + h[4] * y + h[5]) / w / ds + dy


@njit(cache=True, nogil=True)
def lattice_predict(ids, pts, near, want):
    """Image positions of lattice ids, each set from a homography of its own known corners.

    ids (N, 2) float64 lattice ids, pts (N, 2) float64 px, near (M, K) int (K >= 4) the known
    corners of each set, want (M, Q, 2) float64 ids to place with set m. The homography is the
    linear (DLT, h33 = 1) least-squares fit on ids and points each centred and scaled to a mean
    distance of √2. Returns (M, Q, 2) px; NaN for a set whose normal equations are singular
    (|det| <= 1e-12).
    """
    m, q = want.shape[0], want.shape[1]
    out = np.full((m, q, 2), np.nan)
    ata, atb, row, norm = np.empty((8, 8)), np.empty(8), np.empty(8), np.empty(6)
    for s in range(m):
        if not _fit_lattice(ids, pts, near[s], ata, atb, row, norm):
            continue
        for k in range(q):
            _apply_lattice(atb, norm, want[s, k, 0], want[s, k, 1], out[s, k])
    return out


@njit(cache=True, nogil=True)
def nearest_predict(ids, pts, want, k):
    """Image positions of lattice ids ``want`` (M, 2) float64, each from a homography of its k nearest known ids.

    ids (N, 2) float64, pts (N, 2) float64 px, N > k. Each want's set is its k nearest ids by
    squared distance, ties to the lower index (a stable sort); the set is fitted in index order
    as in :func:`lattice_predict`, once for all wants that share it (around a grid, nine of a
    square's sample points often do). Returns (M, 2) px, NaN where the fit is singular.
    """
    n, m = ids.shape[0], want.shape[0]
    out = np.full((m, 2), np.nan)
    sets = np.empty((m, k), np.int64)
    keys = np.empty(m, np.int64)
    d2, bv, bi = np.empty(n), np.empty(k), np.empty(k, np.int64)
    for s in range(m):
        for t in range(n):
            dx, dy = want[s, 0] - ids[t, 0], want[s, 1] - ids[t, 1]
            d2[t] = dx * dx + dy * dy
        # the first k of a stable sort: an insertion into k sorted slots, later ids after equal ones
        got = 0
        for t in range(n):
            if got == k and not d2[t] < bv[k - 1]:
                continue
            j = min(got, k - 1)
            while j > 0 and bv[j - 1] > d2[t]:
                bv[j], bi[j] = bv[j - 1], bi[j - 1]
                j -= 1
            bv[j], bi[j] = d2[t], t
            got = min(got + 1, k)
        for a in range(k):  # in index order, as they are fitted
            j = a
            while j > 0 and sets[s, j - 1] > bi[a]:
                sets[s, j] = sets[s, j - 1]
                j -= 1
            sets[s, j] = bi[a]
        key = 0
        for a in range(k):
            key = key * 1000003 + sets[s, a]  # wraps: a hash only, equal sets are compared in full
        keys[s] = key
    ata, atb, row, norm = np.empty((8, 8)), np.empty(8), np.empty(8), np.empty(6)
    prev, ok = -1, False
    for s in np.argsort(keys):  # wants of one set are neighbours here: one fit each
        same = prev >= 0
        for a in range(k):
            same = same and sets[s, a] == sets[prev, a]
        if not same:
            ok = _fit_lattice(ids, pts, sets[s], ata, atb, row, norm)
        prev = s
        if ok:
            _apply_lattice(atb, norm, want[s, 0], want[s, 1], out[s])
    return out


@njit(cache=True, nogil=True)
def _nearest_sq(pts, i):
    """Squared distance (in pts' own precision) from pts[i] to the nearest other point; inf when alone."""
    best = np.inf
    for j in range(pts.shape[0]):
        if j != i:
            dx, dy = pts[i, 0] - pts[j, 0], pts[i, 1] - pts[j, 1]
            best = min(best, dx * dx + dy * dy)
    return best


@njit(cache=True, nogil=True)
def nearest_steps(pts, want):
    """For each want (M, 2) px: the nearest point of pts (N, 2) px (first on ties), and that point's
    distance to its own nearest other point. Returns (M,) px (inf where N < 2)."""
    n, m = pts.shape[0], want.shape[0]
    spacing = np.empty(n)
    for i in range(n):
        spacing[i] = math.sqrt(_nearest_sq(pts, i))
    out = np.empty(m)
    for s in range(m):
        best, arg = np.inf, 0
        for j in range(n):
            dx, dy = want[s, 0] - pts[j, 0], want[s, 1] - pts[j, 1]
            d = dx * dx + dy * dy
            if d < best:
                best, arg = d, j
        out[s] = spacing[arg]
    return out


@njit(cache=True, nogil=True)
def lattice_residuals_loop(ids, pts, k, single):
    """The loop of :func:`aicalib_tf.lattice.lattice_residuals`: ids (N, 2) float64, pts (N, 2) px, N >= 5.

    Each corner's set is its k nearest other ids (stable order, itself left out), fitted as in
    :func:`lattice_predict`. The nearest-corner step is computed in pts' own precision (``single``:
    pts are float32, and so is the step, as numpy would have it). Returns (N,) residuals in local
    steps, 0 where not finite.
    """
    n = ids.shape[0]
    kk = min(k, n - 1)
    out = np.zeros(n)
    di = np.empty(n)
    ata, atb, row, norm = np.empty((8, 8)), np.empty(8), np.empty(8), np.empty(6)
    pred, q = np.empty(2), np.empty(2)
    units = ((1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0))
    for i in range(n):
        for j in range(n):
            ex, ey = ids[i, 0] - ids[j, 0], ids[i, 1] - ids[j, 1]
            di[j] = ex * ex + ey * ey
        di[i] = np.inf
        step = math.sqrt(_nearest_sq(pts, i))
        if single:
            step = np.float32(step)  # sqrt rounded to float32: numpy's float32 sqrt (correctly rounded both)
        if not _fit_lattice(ids, pts, np.argsort(di, kind="mergesort")[:kk], ata, atb, row, norm):
            continue
        _apply_lattice(atb, norm, ids[i, 0], ids[i, 1], pred)
        alone = True  # none of its four neighbours found (an object in front): the lattice's own step counts too
        for a, b in units:
            for j in range(n):
                if ids[j, 0] == ids[i, 0] + a and ids[j, 1] == ids[i, 1] + b:
                    alone = False
        if alone:
            lat = np.inf
            for a, b in units:
                _apply_lattice(atb, norm, ids[i, 0] + a, ids[i, 1] + b, q)
                d = math.sqrt((q[0] - pred[0]) ** 2 + (q[1] - pred[1]) ** 2)
                lat = d if math.isnan(d) or math.isnan(lat) else min(lat, d)
            if math.isfinite(lat):
                step = min(step, lat)
                if single:
                    step = np.float32(step)
        res = math.sqrt((pred[0] - pts[i, 0]) ** 2 + (pred[1] - pts[i, 1]) ** 2) / step
        if math.isfinite(res):
            out[i] = res
    return out


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
def _bilinear(img, x, y):
    """The image at (x, y) px, bilinear, the nearest edge pixel outside."""
    h, w = img.shape
    x0, y0 = math.floor(x), math.floor(y)
    fx, fy = x - x0, y - y0
    c0, c1 = min(max(x0, 0), w - 1), min(max(x0 + 1, 0), w - 1)
    r0, r1 = min(max(y0, 0), h - 1), min(max(y0 + 1, 0), h - 1)
    return _lerp(img, r0, r1, c0, c1, fx, fy)


@njit(cache=True, nogil=True)
def ring_stats(img, pts, radius, ring):
    """Amplitude and point asymmetry of the image on a ring about each point.

    img (H, W) float32, pts (P, 2) float64 px, radius (P,) px, ring (R, 2) unit directions, R even,
    the second half opposite the first. Returns (P, 2): mean |I − mean I| over the ring and mean
    |I(θ) − I(θ + π)| over its R / 2 opposite pairs.
    """
    nr = ring.shape[0]
    half = nr // 2
    vals = np.empty(nr)
    out = np.empty((pts.shape[0], 2))
    for p in range(pts.shape[0]):
        mean = 0.0
        for k in range(nr):
            vals[k] = _bilinear(img, pts[p, 0] + radius[p] * ring[k, 0], pts[p, 1] + radius[p] * ring[k, 1])
            mean += vals[k]
        mean /= nr
        amp = asym = 0.0
        for k in range(nr):
            amp += abs(vals[k] - mean)
        for k in range(half):
            asym += abs(vals[k] - vals[k + half])
        out[p, 0], out[p, 1] = amp / nr, asym / half
    return out


@njit(cache=True, nogil=True)
def seed_block(pts, k, near, contrast, free, blocks, orders, tolerance, max_step_ratio, max_cell_area, max_span_ratio):
    """The first block of lattice points about point ``k`` that the seed pairs place on free points.

    pts (N, 2) float64; near (K,) int64, k's near points; contrast (K,) float64 (empty: no edge
    test); free (N,) bool; blocks (B, M, 2) float64 block offsets (i, j) of u and v; orders: 1, or 2
    to try each pair both ways round. The rules are those of :func:`aicalib_tf.grid._seed`.
    Returns (b, u index, v index, found (M,) int64) of the first block found, or b = −1.
    """
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
