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

__all__ = ["STRIDE", "standardize", "padded_shape", "network_input", "encode_corners", "decode_map"]

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


def network_input(gray: np.ndarray) -> np.ndarray:
    """(1, H', W', 1) float32: ``gray`` (H, W) standardised and edge-padded at the bottom and right
    to :func:`padded_shape`, the batch a corner-map model runs on."""
    g = standardize(gray)
    h, w = g.shape
    ph, pw = padded_shape(h, w)
    if (ph, pw) != (h, w):
        g = np.pad(g, ((0, ph - h), (0, pw - w)), mode="edge")
    return g[None, :, :, None]


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
    the threshold alone or pooled from a stronger, close neighbour that suppresses it), so the
    work is done on those cells only.
    """
    m = np.asarray(cmap, dtype=np.float32)
    if m.ndim != 3 or m.shape[2] != 3:
        raise ValueError(f"corner map must be (h, w, 3), got shape {m.shape}")
    h, w = m.shape[:2]
    p_all = m[..., 0]
    ci, cj = np.nonzero(p_all >= min(threshold, POOL_FLOOR))
    pad = np.pad(m, ((1, 1), (1, 1), (0, 0)))
    pad[..., 0] = np.pad(p_all, 1, constant_values=-1.0)

    def cell(di: int, dj: int):
        """Weight and point (x, y) px of the cells at offset (di, dj) from the candidates."""
        v = pad[ci + 1 + di, cj + 1 + dj]
        col, row = (cj + dj).astype(np.float32), (ci + di).astype(np.float32)
        return v[:, 0], STRIDE * (col + v[:, 1]) - 0.5, STRIDE * (row + v[:, 2]) - 0.5

    p, x, y = cell(0, 0)
    pooled, sx, sy = p.copy(), p * x, p * y
    keep = np.ones(len(p), dtype=bool)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di == 0 and dj == 0:
                continue
            q, qx, qy = cell(di, dj)
            d2 = (qx - x) ** 2 + (qy - y) ** 2
            close = d2 < min_distance**2
            qc = np.where((d2 < POOL_DISTANCE**2) & (q >= POOL_FLOOR), q, 0.0)
            pooled += qc
            sx += qc * qx
            sy += qc * qy
            # suppress a cell when a close neighbour is stronger; ties broken by position
            stronger = (q > p) | ((q == p) & ((di, dj) < (0, 0)))
            keep &= ~(stronger & close)
    keep &= pooled >= threshold
    score = np.minimum(pooled, 1.0)
    order = np.lexsort((-p[keep], -score[keep]))  # strongest pooled weight first, then own weight
    px = sx[keep] / np.maximum(pooled[keep], 1e-12)
    py = sy[keep] / np.maximum(pooled[keep], 1e-12)
    pts = np.stack([px, py], axis=1)[order]
    return pts.astype(np.float32), score[keep][order].astype(np.float32)
