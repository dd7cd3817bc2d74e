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


@kernel("u1[:, ::1], i8")
def block_mean_grey(img, f):
    """(H // f, W // f) float32: each f×f block's mean of img (H, W) uint8, over 255 (f ≤ 2048)."""
    h, w = img.shape[0] // f, img.shape[1] // f
    out = np.empty((h, w), np.float32)
    cols = np.empty(w * f, np.int32)  # a band of f rows summed down each column
    sums = np.empty(w, np.int32)  # then every f-th column added across (loops over w vectorise; over f, not)
    scale = 1.0 / (255.0 * f * f)
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
    flat = img.reshape(img.shape[0], img.shape[1] * nc)  # a row's channels side by side
    out = np.empty((h, w), np.float32)
    cols = np.empty(w * f * nc, np.int32)  # as block_mean_grey, every channel of a band at once
    sums = np.empty((3, w), np.int32)
    scale = 1.0 / (255.0 * f * f)
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
