"""Block means straight from 8-bit pixels, compiled (numba): :func:`aicalib_tf.detect.pyramid.downscale`'s
maths without converting the whole image to float first.

A 1920×1080 uint8 frame converted to float32 and then averaged in 8×8 blocks costs two passes
over 8 MB; here one pass reads the 2 MB of bytes. Grey levels are those of the image gate
(:func:`aicalib_tf.io.as_gray_float`): v / 255, colour weighted 0.114 B + 0.587 G + 0.299 R.
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.kernels import kernel

__all__ = ["block_mean_grey", "block_mean_colour"]


@kernel("u1[:, ::1], i8")
def block_mean_grey(img, f):
    """(H // f, W // f) float32: each f×f block's mean of img (H, W) uint8, over 255."""
    h, w = img.shape[0] // f, img.shape[1] // f
    out = np.empty((h, w), np.float32)
    cols = np.empty(w * f, np.int32)  # a band of f rows summed down each column (vectorised)
    scale = 1.0 / (255.0 * f * f)
    for i in range(h):
        for c in range(w * f):
            cols[c] = img[i * f, c]
        for r in range(i * f + 1, i * f + f):
            for c in range(w * f):
                cols[c] += img[r, c]
        for j in range(w):
            s = 0
            for c in range(j * f, j * f + f):
                s += cols[c]
            out[i, j] = s * scale
    return out


@kernel("u1[:, :, ::1], i8")
def block_mean_colour(img, f):
    """(H // f, W // f) float32: each f×f block's mean grey level of img (H, W, 3|4) uint8 BGR(A),
    each channel's block sum weighted as OpenCV's BGR-to-grey weights, over 255 (alpha ignored)."""
    h, w = img.shape[0] // f, img.shape[1] // f
    nc = img.shape[2]
    row = img.shape[1] * nc
    out = np.empty((h, w), np.float32)
    flat = img.reshape(img.shape[0], row)
    cols = np.empty(w * f * nc, np.int32)  # as block_mean_grey, every channel of a band at once
    scale = 1.0 / (255.0 * f * f)
    for i in range(h):
        for c in range(w * f * nc):
            cols[c] = flat[i * f, c]
        for r in range(i * f + 1, i * f + f):
            for c in range(w * f * nc):
                cols[c] += flat[r, c]
        for j in range(w):
            b = g = red = 0
            for c in range(j * f, j * f + f):
                b += cols[c * nc]
                g += cols[c * nc + 1]
                red += cols[c * nc + 2]
            out[i, j] = min((0.114 * b + 0.587 * g + 0.299 * red) * scale, 1.0)
    return out
