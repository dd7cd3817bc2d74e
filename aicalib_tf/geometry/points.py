"""Distances between sets of image points (pure numpy).

Points are (N, 2) (x, y) px. numpy reduces over an axis of length 2 slowly (``(d ** 2).sum(-1)``
of a (60, 60, 2) array takes about seven times as long as adding its two planes), and the
detector asks for these distances many times per image.
"""

from __future__ import annotations

import numpy as np

__all__ = ["sq_distances"]


def sq_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(M, N) squared distances (px²) between points a (M, 2) and b (N, 2).

    The same values, bit for bit, as ``((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)``.
    """
    a, b = np.asarray(a), np.asarray(b)
    dx = a[:, None, 0] - b[None, :, 0]
    dy = a[:, None, 1] - b[None, :, 1]
    return dx * dx + dy * dy
