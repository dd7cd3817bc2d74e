"""The corner map: how the default CNN's output encodes corners (pure numpy, no TensorFlow).

The fully convolutional network sees an image of (H, W) px and outputs a map of
(H // STRIDE, W // STRIDE, 3) cells. Cell (i, j) covers the pixel centres x in
[STRIDE·j − 0.5, STRIDE·(j+1) − 0.5) and y in [STRIDE·i − 0.5, STRIDE·(i+1) − 0.5). Its channels are

* 0: the corner weight, the probability that an inner chessboard corner (an X-junction) lies in the cell;
* 1, 2: where the corner is, as fractions (fx, fy) of the cell: x = STRIDE·(j + fx) − 0.5. In [0, 1]
  (inside the cell) for models trained on the cell's own corner only; in [−1, 2] (the cell or one of
  its eight neighbours) for models whose cells next to a corner's cell also point at it
  (``encode_corners(..., reach=1)``): a cell that fires beside the corner's own then still places it.

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


def encode_corners(corners: np.ndarray, image_size: tuple[int, int], reach: int = 0) -> np.ndarray:
    """Training target for the corners of one image.

    corners : (N, 2) float (x, y) px; points outside the image are ignored.
    image_size : (width, height) px, multiples of STRIDE.
    reach : 0 or 1. With 0, returns (height // STRIDE, width // STRIDE, 3) float32: weight 1 and
        the (fx, fy) fractions in each cell holding a corner, zeros elsewhere. With 1, a fourth
        channel marks the cells whose position is trained: each corner's own cell (weight 1, as
        before) and, for the other cells within one cell of a corner's, the fractions of the
        corner nearest to the cell's centre, in [−1, 2] (weight 0).
    If two corners share a cell the later one wins.
    """
    w, h = (int(v) for v in image_size)
    gw, gh = w // STRIDE, h // STRIDE
    target = np.zeros((gh, gw, 4 if reach else 3), np.float32)
    pts = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    u = (pts + 0.5) / STRIDE  # cell units
    cell = np.floor(u).astype(np.int64)
    ok = (cell[:, 0] >= 0) & (cell[:, 0] < gw) & (cell[:, 1] >= 0) & (cell[:, 1] < gh)
    if reach:
        _encode_neighbours(target, u[ok], int(reach))
    cell, frac = cell[ok], (u - np.floor(u))[ok]
    target[cell[:, 1], cell[:, 0], 0] = 1.0
    target[cell[:, 1], cell[:, 0], 1:3] = frac.astype(np.float32)
    if reach:
        target[cell[:, 1], cell[:, 0], 3] = 1.0
    return target


def _encode_neighbours(target: np.ndarray, u: np.ndarray, reach: int) -> None:
    """Write into ``target`` (gh, gw, 4) the fractions of the corner nearest to each cell's centre,
    over the cells within ``reach`` cells of a corner's cell; u : (N, 2) corners in cell units."""
    gh, gw = target.shape[:2]
    if len(u) == 0:
        return
    d = np.arange(-reach, reach + 1)
    step = np.stack(np.meshgrid(d, d), -1).reshape(-1, 2)  # (K, 2) cell offsets (dx, dy)
    cells = (np.floor(u).astype(np.int64)[:, None, :] + step[None]).reshape(-1, 2)  # (N·K, 2)
    frac = np.repeat(u, len(step), axis=0) - cells
    ok = (cells[:, 0] >= 0) & (cells[:, 0] < gw) & (cells[:, 1] >= 0) & (cells[:, 1] < gh)
    cells, frac = cells[ok], frac[ok]
    if len(cells) == 0:
        return
    dist = ((frac - 0.5) ** 2).sum(1)
    key = cells[:, 1] * gw + cells[:, 0]
    order = np.lexsort((dist, key))  # by cell, nearest corner first
    first = order[np.r_[True, key[order][1:] != key[order][:-1]]]
    target[cells[first, 1], cells[first, 0], 1:3] = frac[first].astype(np.float32)
    target[cells[first, 1], cells[first, 0], 3] = 1.0


POOL_DISTANCE = 1.0  # px: cells whose points agree this closely share one corner's weight
POOL_FLOOR = 0.2  # a neighbour below this weight adds nothing


def decode_map(cmap: np.ndarray, threshold: float = 0.5, min_distance: float = 2.5, reach: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Corner points from a corner map.

    cmap : (h, w, 3) float, as the network outputs it.
    threshold : minimum corner weight. A corner near a cell border splits its weight between
        the cells that touch it (at a cell's corner, four cells of about 0.25–0.5 each), so a
        cell's weight is pooled with the neighbouring cells (weight ≥ ``POOL_FLOOR``) whose
        points lie within ``POOL_DISTANCE`` px of its own before the threshold applies (capped at 1).
    min_distance : px; of two points closer than this in neighbouring cells, only the stronger
        stays, placed at the weight-weighted mean of the points pooled into it.
    reach : the map's position reach (:func:`aicalib_tf.model.cell_reach`): cells up to
        ``1 + reach`` apart can place the same corner, so pooling and suppression look that far.
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
    r = 1 + int(reach)
    pad = np.pad(m, ((r, r), (r, r), (0, 0)))
    pad[..., 0] = np.pad(p_all, r, constant_values=-1.0)

    def cell(di: int, dj: int):
        """Weight and point (x, y) px of the cells at offset (di, dj) from the candidates."""
        v = pad[ci + r + di, cj + r + dj]
        col, row = (cj + dj).astype(np.float32), (ci + di).astype(np.float32)
        return v[:, 0], STRIDE * (col + v[:, 1]) - 0.5, STRIDE * (row + v[:, 2]) - 0.5

    p, x, y = cell(0, 0)
    pooled, sx, sy = p.copy(), p * x, p * y
    keep = np.ones(len(p), dtype=bool)
    for di in range(-r, r + 1):
        for dj in range(-r, r + 1):
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
