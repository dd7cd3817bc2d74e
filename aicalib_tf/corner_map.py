"""The corner map: how the default CNN's output encodes corners (pure numpy, no TensorFlow).

The fully convolutional network sees an image of (H, W) px and outputs a map of
(H // STRIDE, W // STRIDE, 3) cells. Cell (i, j) covers the pixel centres x in
[STRIDE·j − 0.5, STRIDE·(j+1) − 0.5) and y in [STRIDE·i − 0.5, STRIDE·(i+1) − 0.5). Its channels are

* 0: the corner weight, the probability that an inner chessboard corner (an X-junction) lies in the cell;
* 1, 2: where in the cell, as fractions (fx, fy) in [0, 1]: x = STRIDE·(j + fx) − 0.5.

Coordinates are OpenCV's (x, y) with the centre of pixel (0, 0) at (0.0, 0.0).
"""

from __future__ import annotations

import numpy as np

__all__ = ["STRIDE", "standardize", "padded_shape", "encode_corners", "decode_map"]

STRIDE = 4


def standardize(gray: np.ndarray, mean: float | None = None, std: float | None = None) -> np.ndarray:
    """Zero-mean, unit-variance copy of a grey image: the network's input.

    gray : (H, W) float or uint8. mean, std : the statistics to use (default: ``gray``'s own; a
    crop passes its whole image's). Returns (H, W) float32. A constant image becomes all zeros.
    """
    g = np.asarray(gray, dtype=np.float32)
    mean = float(g.mean()) if mean is None else float(mean)
    std = float(g.std()) if std is None else float(std)
    return (g - mean) / max(std, 1e-3)


def padded_shape(height: int, width: int) -> tuple[int, int]:
    """(H, W) rounded up to multiples of STRIDE, the size the network is run at."""
    return (-(-int(height) // STRIDE) * STRIDE, -(-int(width) // STRIDE) * STRIDE)


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


def decode_map(cmap: np.ndarray, threshold: float = 0.5, min_distance: float = 2.5) -> tuple[np.ndarray, np.ndarray]:
    """Corner points from a corner map.

    cmap : (h, w, 3) float, as the network outputs it.
    threshold : minimum corner weight.
    min_distance : px; of two points closer than this in neighbouring cells, only the stronger stays
        (a corner on a cell border can light up both cells).
    Returns points (N, 2) float32 (x, y) px and scores (N,) float32, strongest first.
    """
    m = np.asarray(cmap, dtype=np.float32)
    if m.ndim != 3 or m.shape[2] != 3:
        raise ValueError(f"corner map must be (h, w, 3), got shape {m.shape}")
    h, w = m.shape[:2]
    jj, ii = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    x = STRIDE * (jj + m[..., 1]) - 0.5
    y = STRIDE * (ii + m[..., 2]) - 0.5
    p = m[..., 0]
    keep = p >= threshold
    # Suppress a cell when a neighbouring cell is stronger and its point is close.
    pad_p = np.pad(p, 1, constant_values=-1.0)
    pad_x = np.pad(x, 1)
    pad_y = np.pad(y, 1)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di == 0 and dj == 0:
                continue
            q = pad_p[1 + di : 1 + di + h, 1 + dj : 1 + dj + w]
            qx = pad_x[1 + di : 1 + di + h, 1 + dj : 1 + dj + w]
            qy = pad_y[1 + di : 1 + di + h, 1 + dj : 1 + dj + w]
            # ties are broken by position so exactly one of two equal cells survives
            stronger = (q > p) | ((q == p) & ((di, dj) < (0, 0)))
            close = (qx - x) ** 2 + (qy - y) ** 2 < min_distance**2
            keep &= ~(stronger & close)
    order = np.argsort(-p[keep], kind="stable")
    pts = np.stack([x[keep], y[keep]], axis=1)[order]
    return pts.astype(np.float32), p[keep][order].astype(np.float32)
