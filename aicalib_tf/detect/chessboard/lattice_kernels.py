"""Local-lattice fits of a board's corners, compiled (numba): the maths is that of
:func:`aicalib_tf.detect.chessboard.lattice.predict_ids`, :func:`~aicalib_tf.detect.chessboard.lattice.lattice_residuals` and
:func:`~aicalib_tf.detect.chessboard.lattice.local_step`. A board grown from a strip of corners asks them some forty
times, with N × N distance tables and sorts each time.
"""

from __future__ import annotations

import math

import numpy as np

from aicalib_tf.kernels import helper, kernel

__all__ = ['lattice_predict', 'nearest_predict', 'nearest_steps', 'lattice_residuals_loop']


@helper
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


@helper
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


@helper
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


@helper
def _apply_lattice(h, norm, wx, wy, out):
    """Put id (wx, wy) in the image with a fit of :func:`_fit_lattice`: out (2,) px."""
    sx, sy, ss, dx, dy, ds = norm[0], norm[1], norm[2], norm[3], norm[4], norm[5]
    x, y = (wx - sx) * ss, (wy - sy) * ss
    w = h[6] * x + h[7] * y + 1.0
    out[0] = (h[0] * x + h[1] * y + h[2]) / w / ds + dx
    out[1] = (h[3] * x + h[4] * y + h[5]) / w / ds + dy


@kernel("f8[:, ::1], f8[:, ::1], i8[:, ::1], f8[:, :, ::1]")
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


@kernel("f8[:, ::1], f8[:, ::1], f8[:, ::1], i8")
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


@helper
def _nearest_sq(pts, i):
    """Squared distance (in pts' own precision) from pts[i] to the nearest other point; inf when alone."""
    best = np.inf
    for j in range(pts.shape[0]):
        if j != i:
            dx, dy = pts[i, 0] - pts[j, 0], pts[i, 1] - pts[j, 1]
            best = min(best, dx * dx + dy * dy)
    return best


@kernel("f8[:, ::1], f8[:, ::1]")
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


@kernel("f8[:, ::1], f8[:, ::1], i8, b1", "f8[:, ::1], f4[:, ::1], i8, b1")
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
        if step > 0.0:  # no step (another corner at the same place): not finite, left 0 as numpy's x / 0 would be
            res = math.sqrt((pred[0] - pts[i, 0]) ** 2 + (pred[1] - pts[i, 1]) ** 2) / step
            if math.isfinite(res):
                out[i] = res
    return out

