"""The per-corner σ model's window measurements, compiled (numba): the maths is :mod:`aicalib_tf.detect.corners.sigma`'s.

One pass over each corner's window: its bilinear samples, their point-symmetric and
antisymmetric parts (also after a [1 2 1]² smoothing), the saddle fit's quadratic and what it
leaves; the bend of the board's lattice at the corner from its neighbours by id; the noise and the
black/white contrast in the flat middles of the board's squares; and the JPEG blockiness over the board's box. As array code these took about a third of a
640×480 detection's time; here a few microseconds per board.
"""

from __future__ import annotations

import math

import numpy as np

from aicalib_tf.kernels import helper, kernel


__all__ = ["window_measures", "lattice_bend", "axis_spacing", "flat_noise", "square_contrast", "edge_width", "blockiness",
           "corner_features", "design_columns", "board_columns", "BOARD_COLUMNS", "CORNER_COLUMNS", "ASYMMETRY_COLUMN"]

BEND_KNOT = -3.0  # log(bend / spacing) above which lines bend enough to bias the saddle (hinge squared)
IMPULSE_KNOT = 0.8  # log(RMS / median antisymmetric part) above which the board's noise is impulsive (counted as much
# as the noise stands above NOISE_KNOT: an almost noise-free image's few grey-level steps look impulsive too)
NOISE_KNOT = -3.5  # log(noise / contrast) below which the detector's own error floor takes over
SPREAD_KNOT = 0.08  # (edge width / the nearer neighbour's distance along a lattice axis)² above which the blur
# reaches that side's next edges (σ beyond about 0.28 of the local square): the saddle is pulled by what lies beyond the
# junction (a foreshortened board's far side, the board's rim); summed over the corner's two axes
WHITE_EVEN = 1.45  # the window's symmetric part (weighted σ) over its median |antisymmetric part| for white noise
# (1.42 at radius 2, 1.48 at 3): the noise's share of the contrast, taken out before the edge width
SHARP_RETENTION = 0.63  # the window's contrast over half the squares' of a sharp render (edge width about 0.9 px):
# taken where no square has all four corners
ASYM_KNOT = 0.5  # log(own / board's median antisymmetric part) above which a corner's window holds more than noise
# (an object's edge, a shadow): its saddle is pulled in proportion to that asymmetry (hinge)
WHITE_ODD = -0.95  # log(median |antisymmetric part| / noise σ) of white noise in the bilinear window: the flat
# noise taken where a board has no square with all four corners
BLOCK = 8  # px, the JPEG block: blockiness compares the steps across its borders with the others
BLOCK_SAMPLES = 20000  # about this many steps each way at most (every k-th row of a larger box)
BOARD_COLUMNS = 20  # design columns 0..19: the board's (19, the blur's reach, each corner's own); the next CORNER_COLUMNS:
# each corner's excess over them; then ASYMMETRY_COLUMN
CORNER_COLUMNS = 10
ASYMMETRY_COLUMN = BOARD_COLUMNS + CORNER_COLUMNS  # log(odd energy / even energy) of the corner's window (not in log σ's sum:
# :mod:`aicalib_tf.detect.corners.sigma` turns it into the foreign edge's amplitude)


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
    """Per point (P, 6) float64: odd, odd_median, even, residual, curvature, smoothed odd
    (:mod:`~aicalib_tf.detect.corners.sigma`).

    img (H, W) float32 or uint8 (the measures used are ratios: the grey scale does not matter), pts
    (P, 2) float64 px, radius (P,) int64 window radii in 1 .. R, fits
    (R + 1, 6, (2R+1)²) each radius' quadratic fit operator (its first (2r+1)² columns used),
    weights (R + 1, (2R+1)²) each radius' window weights, summing to 1. The smoothed odd is the odd
    measure of the window smoothed by [1 2 1]/4 along x and y (from samples one px further out): the
    part of the asymmetry at the low frequencies the saddle fit of the smoothed image sees.
    """
    n = pts.shape[0]
    out = np.zeros((n, 6))
    big = fits.shape[2]
    rmax = (int(math.sqrt(big)) - 1) // 2
    wide = np.empty((2 * rmax + 3) ** 2)
    vals, smooth, anti = np.empty(big), np.empty(big), np.empty(big)
    for p in range(n):
        r = radius[p]
        side = 2 * r + 1
        m = side * side
        _sample_window(img, pts[p, 0], pts[p, 1], r + 1, wide)
        _inner_and_smoothed(wide, side, vals, smooth)
        a = b = c = d = e = f = 0.0
        for k in range(m):
            v = vals[k]
            a, b, c = a + fits[r, 0, k] * v, b + fits[r, 1, k] * v, c + fits[r, 2, k] * v
            d, e, f = d + fits[r, 3, k] * v, e + fits[r, 4, k] * v, f + fits[r, 5, k] * v
        mean = 0.0
        for k in range(m):
            mean += weights[r, k] * 0.5 * (vals[k] + vals[m - 1 - k])
        odd2 = even2 = left2 = smooth2 = 0.0
        half = 0
        for k in range(m):
            w = weights[r, k]
            o = 0.5 * (vals[k] - vals[m - 1 - k])
            s = 0.5 * (vals[k] + vals[m - 1 - k]) - mean
            dx = float(k % side - r)
            dy = float(k // side - r)
            q = vals[k] - (a * dx * dx + b * dx * dy + c * dy * dy + d * dx + e * dy + f)
            os = 0.5 * (smooth[k] - smooth[m - 1 - k])
            odd2 += w * o * o
            even2 += w * s * s
            left2 += w * q * q
            smooth2 += w * os * os
            if k < m // 2:  # |o| is the same at d and −d: one half of the window holds every value
                anti[half] = abs(o)
                half += 1
        out[p, 0] = math.sqrt(odd2)
        out[p, 1] = np.median(anti[:half])
        out[p, 2] = math.sqrt(even2)
        out[p, 3] = math.sqrt(left2)
        out[p, 4] = 0.5 * math.sqrt(abs(4.0 * a * c - b * b))  # √|det| of the fitted quadratic's Hessian
        out[p, 5] = math.sqrt(smooth2)
    return out


@helper
def _inner_and_smoothed(wide, side, vals, smooth):
    """From a (side + 2)² row-major window: its inner side² samples into vals and, into smooth, the
    inner samples smoothed by [1 2 1]/4 along x then y."""
    ws = side + 2
    for j in range(side):
        for i in range(side):
            acc = 0.0
            for dj in range(3):
                kj = 2.0 if dj == 1 else 1.0
                row = (j + dj) * ws + i
                acc += kj * (wide[row] + 2.0 * wide[row + 1] + wide[row + 2])
            vals[j * side + i] = wide[(j + 1) * ws + i + 1]
            smooth[j * side + i] = acc / 16.0


@helper
def _id_grid(ids, pad):
    """(where, c0, r0): where[r − r0, c − c0] the index of the point with ids (c, r) (P, 2) int64, −1 elsewhere; ``pad``
    more rows and columns of −1 beyond the last. P ≥ 1."""
    c0, r0 = ids[0, 0], ids[0, 1]
    for p in range(ids.shape[0]):
        c0, r0 = min(c0, ids[p, 0]), min(r0, ids[p, 1])
    cols = rows = 0
    for p in range(ids.shape[0]):
        cols, rows = max(cols, ids[p, 0] - c0 + 1), max(rows, ids[p, 1] - r0 + 1)
    where = np.full((rows + pad, cols + pad), -1, np.int64)
    for p in range(ids.shape[0]):
        where[ids[p, 1] - r0, ids[p, 0] - c0] = p
    return where, c0, r0


@helper
def _square_middles(img, pts, ids):
    """(M, 3) int64 rows (x, y, parity) px: the middle (the mean of its four corners, rounded) of every square with
    its four corners found (ids (c, r), (c+1, r), (c, r+1), (c+1, r+1)) and 2 px inside the image; parity
    (c + r) % 2 tells the squares' two colours apart."""
    n = pts.shape[0]
    h, w = img.shape
    out = np.zeros((n, 3), np.int64)
    if n == 0:
        return out[:0]
    where, c0, r0 = _id_grid(ids, 1)
    k = 0
    for p in range(n):
        i, j = ids[p, 0] - c0, ids[p, 1] - r0
        q1, q2, q3 = where[j, i + 1], where[j + 1, i], where[j + 1, i + 1]
        if q1 < 0 or q2 < 0 or q3 < 0:
            continue
        x = int(math.floor(0.25 * (pts[p, 0] + pts[q1, 0] + pts[q2, 0] + pts[q3, 0]) + 0.5))
        y = int(math.floor(0.25 * (pts[p, 1] + pts[q1, 1] + pts[q2, 1] + pts[q3, 1]) + 0.5))
        if x < 2 or y < 2 or x > w - 3 or y > h - 3:
            continue
        out[k, 0], out[k, 1], out[k, 2] = x, y, (ids[p, 0] + ids[p, 1]) % 2
        k += 1
    return out[:k]


@helper
def flat_noise(img, pts, ids, step):
    """The board's noise σ (grey levels of img) in the flat middles of its squares; −1 where no square has all
    four corners.

    At every square's middle (:func:`_square_middles`), the 5×5 pixels about it (unresampled:
    interpolation would smooth the noise) through the 3×3 mask [1 −2 1]⊗[1 −2 1] (blind to a level or
    a linear shading; its output is 6 σ for white noise σ): the mean square of its 9 outputs / 36. σ² is
    the median of these over the squares plus step² / 12, the rounding noise of grey levels ``step``
    apart (1 for uint8).
    """
    mids = _square_middles(img, pts, ids)
    if mids.shape[0] == 0:
        return -1.0
    ms = np.empty(mids.shape[0])
    for k in range(mids.shape[0]):
        x, y = mids[k, 0], mids[k, 1]
        total = 0.0
        for yy in range(y - 1, y + 2):
            for xx in range(x - 1, x + 2):
                v = 0.0
                for dj in range(-1, 2):
                    kj = -2.0 if dj == 0 else 1.0
                    for di in range(-1, 2):
                        ki = -2.0 if di == 0 else 1.0
                        v += kj * ki * float(img[yy + dj, xx + di])
                total += v * v
        ms[k] = total / (9.0 * 36.0)
    return math.sqrt(np.median(ms) + step * step / 12.0)


@helper
def square_contrast(img, pts, ids):
    """The board's black/white contrast (grey levels of img): |median of one colour's squares − the other's|, each
    square's level the mean of the 3×3 pixels at its middle (:func:`_square_middles`); −1 where a colour has
    no square with all four corners."""
    mids = _square_middles(img, pts, ids)
    levels = np.empty((2, mids.shape[0] + 1))
    count = np.zeros(2, np.int64)
    for k in range(mids.shape[0]):
        t = 0.0
        for yy in range(mids[k, 1] - 1, mids[k, 1] + 2):
            for xx in range(mids[k, 0] - 1, mids[k, 0] + 2):
                t += float(img[yy, xx])
        c = mids[k, 2]
        levels[c, count[c]] = t / 9.0
        count[c] += 1
    if count[0] == 0 or count[1] == 0:
        return -1.0
    return abs(np.median(levels[0, :count[0]]) - np.median(levels[1, :count[1]]))


@helper
def edge_width(even, radius, contrast, noise):
    """(P,) px: each corner's edge width σ_b from how much of the squares' contrast its window keeps.

    A straight X-junction of contrast C blurred by a Gaussian σ_b, in a Gaussian window of σ s, has the weighted
    standard deviation (C/2)·(2/π)·asin(s² / (s² + σ_b²)) (the product of the two edges' erf profiles); with J
    the window's ``even``, less the board's ``noise`` (median |antisymmetric part|) times ``WHITE_EVEN`` in
    quadrature (at most halved), over C/2: σ_b² = s² (1 / sin(πJ/2) − 1). s = r/2 + 1/2 for window radius r (the
    weights of :mod:`aicalib_tf.detect.corners.sigma`); J is held to [0.001, 0.999], and taken as
    ``SHARP_RETENTION`` where the board has no contrast measured (``contrast`` ≤ 0). The window is cut at
    r, so a blur of a few px reads about a fifth high (3.6 px for a 3 px blur of a sharp board, r = 3).
    """
    n = even.shape[0]
    out = np.empty(n)
    for p in range(n):
        signal = math.sqrt(max(even[p] * even[p] - (WHITE_EVEN * noise) ** 2, 0.25 * even[p] * even[p]))
        j = signal / (0.5 * contrast) if contrast > 0 else SHARP_RETENTION
        j = min(max(j, 0.001), 0.999)
        s = 0.5 * radius[p] + 0.5
        out[p] = s * math.sqrt(1.0 / math.sin(0.5 * math.pi * j) - 1.0)
    return out


@helper
def blockiness(img, pts, ox, oy, tiny):
    """(mean |step| across JPEG block borders + tiny) / (mean |step| elsewhere + tiny) in the box of the points.

    Steps are differences of neighbouring pixels along x and along y; a border lies between pixels
    x and x + 1 where (ox + x) % BLOCK == BLOCK − 1 (ox, oy: img's origin in the whole image, where
    the blocks start), the same along y. On every k-th row of the box (k odd, so that the rows visit
    every phase of the blocks; about ``BLOCK_SAMPLES`` steps each way): its steps along x and those to
    the next row. 1 for an image never JPEG-compressed (or resampled since), growing with the blocks'
    visible steps.
    """
    h, w = img.shape
    x0, y0 = max(int(math.floor(np.min(pts[:, 0]))), 0), max(int(math.floor(np.min(pts[:, 1]))), 0)
    x1, y1 = min(int(math.ceil(np.max(pts[:, 0]))), w - 1), min(int(math.ceil(np.max(pts[:, 1]))), h - 1)
    if x1 - x0 < BLOCK or y1 - y0 < BLOCK:
        return 1.0
    stride = max(1, ((x1 - x0) * (y1 - y0)) // BLOCK_SAMPLES) | 1
    on = off = 0.0
    n_on = n_off = 0
    for y in range(y0, y1, stride):
        row_on = (oy + y) % BLOCK == BLOCK - 1
        for x in range(x0, x1):
            here = float(img[y, x])
            d = abs(float(img[y, x + 1]) - here)
            v = abs(float(img[y + 1, x]) - here)
            if (ox + x) % BLOCK == BLOCK - 1:
                on += d
                n_on += 1
            else:
                off += d
                n_off += 1
            if row_on:
                on += v
                n_on += 1
            else:
                off += v
                n_off += 1
    if n_on == 0 or n_off == 0:
        return 1.0
    return (on / n_on + tiny) / (off / n_off + tiny)


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
    where, c0, r0 = _id_grid(ids, 0)
    rows, cols = where.shape
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
def axis_spacing(pts, ids):
    """(P, 2) float64 px: each point's distance to its nearer neighbour along the board's columns' axis (ids (c ± 1, r))
    and along its rows' axis ((c, r ± 1)); −1 where it has neither. pts (P, 2) px, ids (P, 2) int64 (col, row), distinct."""
    n = pts.shape[0]
    out = np.full((n, 2), -1.0)
    if n == 0:
        return out
    where, c0, r0 = _id_grid(ids, 0)
    rows, cols = where.shape
    for p in range(n):
        i, j = ids[p, 0] - c0, ids[p, 1] - r0
        for a in range(2):
            for step in (-1, 1):
                ii, jj = (i + step, j) if a == 0 else (i, j + step)
                if 0 <= ii < cols and 0 <= jj < rows and where[jj, ii] >= 0:
                    q = where[jj, ii]
                    d = math.hypot(pts[q, 0] - pts[p, 0], pts[q, 1] - pts[p, 1])
                    out[p, a] = d if out[p, a] < 0 else min(out[p, a], d)
    return out


@helper
def _board_median_fill(bend, tiny):
    """bend (P,) px with −1 (none) replaced by the board's median bend (``tiny`` when no corner has one)."""
    present = bend[bend >= 0]
    usual = np.median(present) if present.shape[0] else tiny
    return np.where(bend >= 0, bend, usual)


@helper
def corner_features(measures, bend, spacing, scores, min_score, tiny):
    """(P, 10) per-corner features and the board's impulsiveness (:func:`aicalib_tf.detect.corners.sigma.design`):
    noise/contrast, own excess asymmetry, residual/contrast, own impulsiveness, bend/spacing, score,
    curvature/contrast, the bend's excess over ``BEND_KNOT`` squared, smoothed/raw asymmetry, the own
    excess asymmetry's excess over ``ASYM_KNOT``; all logarithms."""
    n = measures.shape[0]
    f = np.zeros((n, CORNER_COLUMNS))
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
        f[p, 8] = math.log(max(measures[p, 5], tiny)) - log_odd[p]
        f[p, 9] = max(f[p, 1] - ASYM_KNOT, 0.0)
    return f, impulsive


@helper
def _reach(width, spacing, axes, tiny):
    """(P,) each corner's blur reach: Σ over its two lattice axes of ((board's median edge width / the nearer neighbour's
    distance along the axis)² − ``SPREAD_KNOT``)⁺; width (P,) px, spacing (P,) px (an axis without neighbours
    takes it), axes (P, 2) :func:`axis_spacing`."""
    w = math.exp(np.median(np.log(np.maximum(width, tiny))))
    out = np.zeros(width.shape[0])
    for p in range(width.shape[0]):
        for a in range(2):
            d = axes[p, a] if axes[p, a] > 0 else spacing[p]
            out[p] += max((w / max(d, tiny)) ** 2 - SPREAD_KNOT, 0.0)
    return out


@helper
def design_columns(measures, bend, spacing, scores, min_score, tiny, flat, block, width, axes):
    """The σ model's columns (P, 31) of one board (:func:`aicalib_tf.detect.corners.sigma.design`).

    measures (P, 6) :func:`window_measures`, bend (P,) :func:`lattice_bend` px (−1: none), spacing (P,)
    px, scores (P,), flat :func:`flat_noise` (−1: none; the window's noise over ``WHITE_ODD`` then),
    block :func:`blockiness`, width (P,) :func:`edge_width` px, axes (P, 2) :func:`axis_spacing` px. Values are
    floored at ``tiny`` and scores at ``min_score`` before the logarithms. Columns 0–19 are the board's (the same
    for all its corners but 19, each corner's blur reach :func:`_reach`), 20–29 each corner's excess over the
    board's median of its feature, 30 (``ASYMMETRY_COLUMN``) log(odd² / even²) of its window.
    """
    n = measures.shape[0]
    out = np.zeros((n, BOARD_COLUMNS + CORNER_COLUMNS + 1))
    if n == 0:
        return out
    f, impulsive = corner_features(measures, bend, spacing, scores, min_score, tiny)
    med = np.empty(CORNER_COLUMNS)
    for k in range(CORNER_COLUMNS):
        med[k] = np.median(f[:, k])
    noise = np.median(np.log(np.maximum(measures[:, 1], tiny)))
    log_flat = math.log(max(flat, tiny)) if flat > 0 else noise - WHITE_ODD
    q9_noise = np.percentile(f[:, 0], 90.0) - med[0]
    q9_bend = np.percentile(f[:, 4], 90.0) - med[4]
    board = np.array([med[0], med[2], impulsive, med[4], med[5], med[0] * med[0], med[6], np.median(np.log(np.maximum(spacing, tiny))),
                      max(med[4] - BEND_KNOT, 0.0) ** 2, q9_noise, q9_bend, max(impulsive - IMPULSE_KNOT, 0.0) * max(med[0] - NOISE_KNOT, 0.0), med[3],
                      max(NOISE_KNOT - med[0], 0.0), np.median(np.log(np.maximum(width, tiny))),
                      log_flat - noise + med[0], noise - log_flat, math.log(max(block, tiny)), med[8], 0.0])
    reach = _reach(width, spacing, axes, tiny)
    for p in range(n):
        out[p, :BOARD_COLUMNS] = board
        out[p, BOARD_COLUMNS - 1] = reach[p]
        for k in range(CORNER_COLUMNS):
            out[p, BOARD_COLUMNS + k] = f[p, k] - med[k]
        out[p, ASYMMETRY_COLUMN] = 2.0 * (math.log(max(measures[p, 0], tiny)) - math.log(max(measures[p, 2], tiny)))
    return out


@kernel("f4[:, ::1], f8[:, ::1], i8[:, ::1], f8[::1], i8[::1], f8[::1], f8[:, :, ::1], f8[:, ::1], f8, f8, f8, i8, i8",
        "u1[:, ::1], f8[:, ::1], i8[:, ::1], f8[::1], i8[::1], f8[::1], f8[:, :, ::1], f8[:, ::1], f8, f8, f8, i8, i8")
def board_columns(img, pts, ids, spacing, radius, scores, fits, weights, min_score, tiny, step, ox, oy):
    """The σ model's columns (P, 31) of one board in one call: :func:`window_measures`, :func:`lattice_bend`,
    :func:`axis_spacing`, :func:`flat_noise`, :func:`blockiness`, :func:`edge_width` (of :func:`square_contrast`) and
    :func:`design_columns` of its points (ids shifted to start at 0). step: the grey levels' step in img's
    units (1 for uint8); ox, oy: img's origin in the whole image, px (the JPEG blocks start at the whole image's)."""
    measures = window_measures(img, pts, radius, fits, weights)
    noise = math.exp(np.median(np.log(np.maximum(measures[:, 1], tiny)))) if measures.shape[0] else 0.0
    width = edge_width(measures[:, 2], radius, square_contrast(img, pts, ids), noise)
    return design_columns(measures, lattice_bend(pts, ids), spacing, scores, min_score, tiny,
                          flat_noise(img, pts, ids, step), blockiness(img, pts, ox, oy, tiny), width, axis_spacing(pts, ids))
