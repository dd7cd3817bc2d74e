"""The corner map: how the default CNN's output encodes corners (numpy, a numba loop; no TensorFlow).

The fully convolutional network sees an image of (H, W) px and outputs a map of
(H // STRIDE, W // STRIDE, 3) cells. Cell (i, j) covers the pixel centres x in
[STRIDE·j − 0.5, STRIDE·(j+1) − 0.5) and y in [STRIDE·i − 0.5, STRIDE·(i+1) − 0.5). Its channels are

* 0: the corner weight, the probability that an inner chessboard corner (an X-junction) lies in the cell;
* 1, 2: where in the cell, as fractions (fx, fy) in [0, 1]: x = STRIDE·(j + fx) − 0.5.

Coordinates are OpenCV's (x, y) with the centre of pixel (0, 0) at (0.0, 0.0).
"""

from __future__ import annotations

import numpy as np

__all__ = ["STRIDE", "standardize", "padded_shape", "network_input", "encode_corners", "decode_map"]

STRIDE = 4


def standardize(gray: np.ndarray, mean: float | None = None, std: float | None = None, *,
                out: np.ndarray | None = None) -> np.ndarray:
    """Zero-mean, unit-variance copy of a grey image: the network's input.

    gray : (H, W) float or uint8. mean, std : the statistics to use (default: ``gray``'s own; a
    crop passes its whole image's). out : (H, W) float32 to write into (a view into a larger
    array, say), or None for a new array. Returns (H, W) float32 (``out`` when given). A constant
    image becomes all zeros.
    """
    from aicalib_tf.cnn.corner_map_kernels import mean_std

    g = np.asarray(gray, dtype=np.float32)
    if mean is None or std is None:
        own = mean_std(g)
        mean, std = own[0] if mean is None else mean, own[1] if std is None else std
    mean, std = float(mean), float(std)
    out = np.subtract(g, mean, out=out, dtype=np.float32)
    return np.divide(out, max(std, 1e-3), out=out)


def padded_shape(height: int, width: int) -> tuple[int, int]:
    """(H, W) rounded up to multiples of STRIDE, the size the network is run at."""
    return (-(-int(height) // STRIDE) * STRIDE, -(-int(width) // STRIDE) * STRIDE)


def network_input(gray: np.ndarray) -> np.ndarray:
    """(1, H', W', 1) float32: ``gray`` (H, W) standardised and edge-padded at the bottom and right
    to :func:`padded_shape`, the batch a corner-map model runs on."""
    g = np.asarray(gray, dtype=np.float32)
    h, w = g.shape
    ph, pw = padded_shape(h, w)
    out = np.empty((1, ph, pw, 1), np.float32)
    body = standardize(g, out=out[0, :h, :w, 0])  # written straight into the padded batch
    if pw > w:  # edge padding: the last column, then the last row (with its padded corner)
        out[0, :h, w:, 0] = body[:, w - 1 : w]
    if ph > h:
        out[0, h:, :, 0] = out[0, h - 1 : h, :, 0]
    return out


def encode_corners(corners: np.ndarray, image_size: tuple[int, int]) -> np.ndarray:
    """Training target for the corners of one image.

    corners : (N, 2) float (x, y) px; points outside the image are ignored.
    image_size : (width, height) px, multiples of STRIDE.
    Returns (height // STRIDE, width // STRIDE, 3) float32: weight 1 and the (fx, fy) fractions in
    each cell holding a corner, zeros elsewhere. If two corners share a cell the later one wins.
    """
    w, h = (int(v) for v in image_size)
    target = np.zeros((h // STRIDE, w // STRIDE, 3), np.float32)
    pts = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    if pts.size == 0:
        return target
    u = (pts + 0.5) / STRIDE  # cell units
    cell = np.floor(u).astype(np.int64)
    ok = (cell[:, 0] >= 0) & (cell[:, 0] < w // STRIDE) & (cell[:, 1] >= 0) & (cell[:, 1] < h // STRIDE)
    cell, frac = cell[ok], (u - np.floor(u))[ok]
    target[cell[:, 1], cell[:, 0], 0] = 1.0
    target[cell[:, 1], cell[:, 0], 1:] = frac.astype(np.float32)
    return target


POOL_DISTANCE = 1.0  # px: cells whose points agree this closely share one corner's weight
POOL_FLOOR = 0.2  # a neighbour below this weight adds nothing


def decode_map(cmap: np.ndarray, threshold: float = 0.5, min_distance: float = 2.5) -> tuple[np.ndarray, np.ndarray]:
    """Corner points from a corner map.

    cmap : (h, w, 3) float, as the network outputs it.
    threshold : minimum corner weight. A corner near a cell border splits its weight between
        the cells that touch it (at a cell's corner, four cells of about 0.25–0.5 each), so a
        cell's weight is pooled with the neighbouring cells (weight ≥ ``POOL_FLOOR``) whose
        points lie within ``POOL_DISTANCE`` px of its own before the threshold applies (capped at 1).
    min_distance : px; of two points closer than this in neighbouring cells, only the stronger
        stays, placed at the weight-weighted mean of the points pooled into it.
    Returns points (N, 2) float32 (x, y) px and scores (N,) float32 (pooled weights), strongest first.

    Only cells of weight ≥ min(threshold, POOL_FLOOR) can survive (a weaker cell is either below
    the threshold alone or pooled from a stronger, close neighbour that suppresses it), so only
    those are looked at, in a compiled loop (:func:`aicalib_tf.cnn.corner_map_kernels.decode_cells`: a 640×480
    image's map holds some 20,000 cells, about a hundred of them above the floor).
    """
    from aicalib_tf.cnn.corner_map_kernels import decode_cells

    m = np.ascontiguousarray(cmap, dtype=np.float32)
    if m.ndim != 3 or m.shape[2] != 3:
        raise ValueError(f"corner map must be (h, w, 3), got shape {m.shape}")
    f32 = np.float32
    x, y, score, own = decode_cells(m, f32(threshold), f32(min_distance), f32(POOL_DISTANCE), f32(POOL_FLOOR), f32(STRIDE))
    order = np.lexsort((-own, -score))  # strongest pooled weight first, then own weight
    return np.stack([x, y], axis=1)[order], score[order]
