"""The per-corner σ model's window measurements, compiled (numba): the maths is :mod:`aicalib_tf.detect.corners.sigma`'s.

One pass over each corner's window: its bilinear samples, their point-symmetric and
antisymmetric parts, the saddle fit's quadratic and what it leaves; and the bend of the board's
lattice at the corner from its neighbours by id. As array code these took about a third of a
640×480 detection's time; here a few microseconds per board.
"""

from __future__ import annotations

import math

import numpy as np

from aicalib_tf.kernels import helper, kernel


__all__ = ["window_measures", "lattice_bend", "corner_features", "design_columns", "board_columns", "BOARD_COLUMNS",
           "CORNER_COLUMNS"]

BEND_KNOT = -3.0  # log(bend / spacing) above which lines bend enough to bias the saddle (hinge squared)
IMPULSE_KNOT = 0.8  # log(RMS / median antisymmetric part) above which the board's noise is impulsive (counted as much
# as the noise stands above NOISE_KNOT: an almost noise-free image's few grey-level steps look impulsive too)
NOISE_KNOT = -3.5  # log(noise / contrast) below which the detector's own error floor takes over
RESIDUAL_KNOT = -1.5  # log(residual / contrast) below which the junction is blurred smooth
BOARD_COLUMNS = 15  # design columns 0..14: the board's; the next CORNER_COLUMNS: each corner's excess over them
CORNER_COLUMNS = 8


@helper
def _sample_window(img, x, y, r, out):
    """Bilinear samples at (x + i, y + j), i, j in −r .. r, row-major into out, the nearest edge pixel
    outside the image; each pixel read as float first (a uint8 image's differences would wrap)."""
    h, w = img.shape
    x0, y0 = math.floor(x), math.floor(y)
    fx, fy = x - x0, y - y0
    k = 0
    for j in range(-r, r + 1):
        r0 = min(max(y0 + j, 0), h - 1)
        r1 = min(max(y0 + j + 1, 0), h - 1)
        for i in range(-r, r + 1):
            c0 = min(max(x0 + i, 0), w - 1)
            c1 = min(max(x0 + i + 1, 0), w - 1)
            top = float(img[r0, c0]) + fx * (float(img[r0, c1]) - float(img[r0, c0]))
            bot = float(img[r1, c0]) + fx * (float(img[r1, c1]) - float(img[r1, c0]))
            out[k] = top + fy * (bot - top)
            k += 1


@helper
def window_measures(img, pts, radius, fits, weights):
    """Per point (P, 5) float64: odd, odd_median, even, residual, curvature (:mod:`~aicalib_tf.detect.corners.sigma`).

    img (H, W) float32 or uint8 (the measures used are ratios: the grey scale does not matter), pts
    (P, 2) float64 px, radius (P,) int64 window radii in 1 .. R, fits
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
        _sample_window(img, pts[p, 0], pts[p, 1], r, vals)
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
        half = 0
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
            if k < m // 2:  # |o| is the same at d and −d: one half of the window holds every value
                anti[half] = abs(o)
                half += 1
        out[p, 0] = math.sqrt(odd2)
        out[p, 1] = np.median(anti[:half])
        out[p, 2] = math.sqrt(even2)
        out[p, 3] = math.sqrt(left2)
        out[p, 4] = 0.5 * math.sqrt(abs(4.0 * a * c - b * b))  # √|det| of the fitted quadratic's Hessian
    return out


@helper
def lattice_bend(pts, ids):
    """(P,) float64 px: the mean |c(i−1) − 2 c(i) + c(i+1)| along the board's rows and columns at each
    point, over the directions with both neighbours present; −1 where neither has them.

    pts (P, 2) px, ids (P, 2) int64 (col, row), distinct.
    """
    n = pts.shape[0]
    out = np.full(n, -1.0)
    if n == 0:
        return out
    cols = rows = 0
    c0, r0 = ids[0, 0], ids[0, 1]
    for p in range(n):
        c0, r0 = min(c0, ids[p, 0]), min(r0, ids[p, 1])
    for p in range(n):
        cols = max(cols, ids[p, 0] - c0 + 1)
        rows = max(rows, ids[p, 1] - r0 + 1)
    where = np.full((rows, cols), -1, np.int64)
    for p in range(n):
        where[ids[p, 1] - r0, ids[p, 0] - c0] = p
    for p in range(n):
        i, j = ids[p, 0] - c0, ids[p, 1] - r0
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


@helper
def _board_median_fill(bend, tiny):
    """bend (P,) px with −1 (none) replaced by the board's median bend (``tiny`` when no corner has one)."""
    seen = 0
    for v in bend:
        seen += v >= 0
    present = np.empty(seen)
    k = 0
    for v in bend:
        if v >= 0:
            present[k] = v
            k += 1
    usual = np.median(present) if seen else tiny
    out = np.empty(bend.shape[0])
    for p in range(bend.shape[0]):
        out[p] = bend[p] if bend[p] >= 0 else usual
    return out


@helper
def corner_features(measures, bend, spacing, scores, min_score, tiny):
    """(P, 8) per-corner features and the board's impulsiveness (:func:`aicalib_tf.detect.corners.sigma.design`):
    noise/contrast, own excess asymmetry, residual/contrast, own impulsiveness, bend/spacing, score,
    curvature/contrast, the bend's excess over ``BEND_KNOT`` squared; all logarithms."""
    n = measures.shape[0]
    f = np.zeros((n, 8))
    log_odd, log_med = np.empty(n), np.empty(n)
    for p in range(n):
        log_odd[p] = math.log(max(measures[p, 0], tiny))
        log_med[p] = math.log(max(measures[p, 1], tiny))
    noise = np.median(log_med)
    impulsive = np.median(log_odd) - noise
    b = _board_median_fill(bend, tiny)
    for p in range(n):
        even = math.log(max(measures[p, 2], tiny))
        f[p, 0] = noise - even
        f[p, 1] = log_med[p] - noise
        f[p, 2] = math.log(max(measures[p, 3], tiny)) - even
        f[p, 3] = log_odd[p] - log_med[p] - impulsive
        f[p, 4] = math.log(max(b[p], tiny)) - math.log(max(spacing[p], tiny))
        f[p, 5] = math.log(max(scores[p], min_score))
        f[p, 6] = math.log(max(measures[p, 4], tiny)) - even
        f[p, 7] = max(f[p, 4] - BEND_KNOT, 0.0) ** 2
    return f, impulsive


@helper
def design_columns(measures, bend, spacing, scores, min_score, tiny):
    """The σ model's columns (P, 23) of one board (:func:`aicalib_tf.detect.corners.sigma.design`).

    measures (P, 5) :func:`window_measures`, bend (P,) :func:`lattice_bend` px (−1: none), spacing (P,)
    px, scores (P,). Values are floored at ``tiny`` and scores at ``min_score`` before the logarithms.
    Columns 0–14 are the board's (the same for all its corners), 15–22 each corner's excess over the
    board's median of its feature.
    """
    n = measures.shape[0]
    out = np.zeros((n, BOARD_COLUMNS + CORNER_COLUMNS))
    if n == 0:
        return out
    f, impulsive = corner_features(measures, bend, spacing, scores, min_score, tiny)
    med = np.empty(8)
    for k in range(8):
        med[k] = np.median(f[:, k])
    q9_noise = np.percentile(f[:, 0], 90.0) - med[0]
    q9_bend = np.percentile(f[:, 4], 90.0) - med[4]
    board = np.array([med[0], med[2], impulsive, med[4], med[5], med[0] * med[0], med[6], np.median(np.log(np.maximum(spacing, tiny))),
                      max(med[4] - BEND_KNOT, 0.0) ** 2, q9_noise, q9_bend, max(impulsive - IMPULSE_KNOT, 0.0) * max(med[0] - NOISE_KNOT, 0.0), med[3],
                      max(NOISE_KNOT - med[0], 0.0), max(RESIDUAL_KNOT - med[2], 0.0)])
    for p in range(n):
        out[p, :BOARD_COLUMNS] = board
        for k in range(CORNER_COLUMNS):
            out[p, BOARD_COLUMNS + k] = f[p, k] - med[k]
    return out


@kernel("f4[:, ::1], f8[:, ::1], i8[:, ::1], f8[::1], i8[::1], f8[::1], f8[:, :, ::1], f8[:, ::1], f8, f8",
        "u1[:, ::1], f8[:, ::1], i8[:, ::1], f8[::1], i8[::1], f8[::1], f8[:, :, ::1], f8[:, ::1], f8, f8")
def board_columns(img, pts, ids, spacing, radius, scores, fits, weights, min_score, tiny):
    """The σ model's columns (P, 23) of one board in one call: :func:`window_measures`, :func:`lattice_bend`
    and :func:`design_columns` of its points (ids shifted to start at 0)."""
    return design_columns(window_measures(img, pts, radius, fits, weights), lattice_bend(pts, ids), spacing, scores,
                          min_score, tiny)
