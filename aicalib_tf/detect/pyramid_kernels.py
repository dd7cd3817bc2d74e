"""Block means straight from 8-bit pixels, compiled (numba): :func:`aicalib_tf.detect.pyramid.downscale`'s
maths without converting the whole image to float first.

A 1920×1080 uint8 frame converted to float32 and then averaged in 8×8 blocks costs two passes
over 8 MB; here one pass reads the 2 MB of bytes. Grey levels are those of the image gate
(:func:`aicalib_tf.io.as_gray_float`): v / 255, colour weighted 0.114 B + 0.587 G + 0.299 R.
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.kernels import helper, kernel

__all__ = ["block_mean_grey", "block_mean_colour"]


@helper
def _band_sums(rows, r0, f, cols):
    """cols (n,) int32 = the sums of rows r0 … r0 + f − 1 of rows (H, ≥ n) uint8, column by column
    (a loop over the columns, which vectorises)."""
    n = cols.shape[0]
    for c in range(n):
        cols[c] = rows[r0, c]
    for r in range(r0 + 1, r0 + f):
        for c in range(n):
            cols[c] += rows[r, c]


@helper
def _pair_sum(a, b, j):
    """int32: the 2×2 block sum of pixels 2j, 2j + 1 of rows a and b (1-D uint8, or one channel of one)."""
    return np.int32(a[2 * j]) + np.int32(a[2 * j + 1]) + np.int32(b[2 * j]) + np.int32(b[2 * j + 1])


@kernel("u1[:, ::1], i8")
def block_mean_grey(img, f):
    """(H // f, W // f) float32: each f×f block's mean of img (H, W) uint8, over 255 (f ≤ 2048).

    f = 2, the quick pass of a 640×480 frame, has a loop of its own: 0.04 ms there, against 0.1
    for the general loop, with the same sums.
    """
    h, w = img.shape[0] // f, img.shape[1] // f
    out = np.empty((h, w), np.float32)
    scale = 1.0 / (255.0 * f * f)
    if f == 2:
        for i in range(h):
            a, b = img[2 * i], img[2 * i + 1]
            for j in range(w):
                out[i, j] = _pair_sum(a, b, j) * scale
        return out
    cols = np.empty(w * f, np.int32)  # a band of f rows summed down each column
    sums = np.empty(w, np.int32)  # then every f-th column added across (loops over w vectorise; over f, not)
    for i in range(h):
        _band_sums(img, i * f, f, cols)
        for j in range(w):
            sums[j] = cols[j * f]
        for k in range(1, f):
            for j in range(w):
                sums[j] += cols[j * f + k]
        for j in range(w):
            out[i, j] = sums[j] * scale
    return out


@kernel("u1[:, :, ::1], i8")
def block_mean_colour(img, f):
    """(H // f, W // f) float32: each f×f block's mean grey level of img (H, W, 3|4) uint8 BGR(A),
    each channel's block sum weighted as OpenCV's BGR-to-grey weights, over 255 (alpha ignored; f ≤ 2048)."""
    h, w = img.shape[0] // f, img.shape[1] // f
    nc = img.shape[2]
    out = np.empty((h, w), np.float32)
    scale = 1.0 / (255.0 * f * f)
    if f == 2:  # as block_mean_grey, a loop of its own
        for i in range(h):
            a, b = img[2 * i], img[2 * i + 1]
            for j in range(w):
                s = 0.114 * _pair_sum(a[:, 0], b[:, 0], j) + 0.587 * _pair_sum(a[:, 1], b[:, 1], j)
                out[i, j] = min((s + 0.299 * _pair_sum(a[:, 2], b[:, 2], j)) * scale, 1.0)
        return out
    flat = img.reshape(img.shape[0], img.shape[1] * nc)  # a row's channels side by side
    cols = np.empty(w * f * nc, np.int32)  # as block_mean_grey, every channel of a band at once
    sums = np.empty((3, w), np.int32)
    for i in range(h):
        _band_sums(flat, i * f, f, cols)
        for ch in range(3):
            for j in range(w):
                sums[ch, j] = cols[j * f * nc + ch]
            for k in range(1, f):
                for j in range(w):
                    sums[ch, j] += cols[(j * f + k) * nc + ch]
        for j in range(w):
            out[i, j] = min((0.114 * sums[0, j] + 0.587 * sums[1, j] + 0.299 * sums[2, j]) * scale, 1.0)
    return out
