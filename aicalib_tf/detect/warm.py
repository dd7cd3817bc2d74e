"""Compile the detector's numba kernels into their on-disk caches ahead of the first real image.

Every kernel is ``@njit(cache=True)``: the first process that reaches one compiles it (up to a few
seconds) and writes the machine code beside the module (``__pycache__``); later processes load it.
:func:`warm` runs the pipeline on two synthetic views (a whole board, and one cut by the frame so
the partial-board stages run too), which reaches the kernels a detection uses.
``python -m aicalib_tf.export --warm`` calls it after an install.
"""

from __future__ import annotations

import time

import cv2
import numpy as np

__all__ = ["warm", "synthetic_board"]


def synthetic_board(pattern_size=(9, 6), square: int = 40, size=(640, 480), angle: float = 12.0,
                    shift=(0.0, 0.0)) -> np.ndarray:
    """A grey uint8 (H, W) image of a chessboard with ``pattern_size`` inner corners, rotated by
    ``angle`` degrees about the image centre and moved by ``shift`` (x, y) px; white paper around it."""
    cols, rows = pattern_size
    board = np.full(((rows + 3) * square, (cols + 3) * square), 255, np.uint8)
    for r in range(rows + 1):
        for c in range(cols + 1):
            if (r + c) % 2 == 0:
                y, x = (r + 1) * square, (c + 1) * square
                board[y : y + square, x : x + square] = 0
    w, h = size
    M = cv2.getRotationMatrix2D((board.shape[1] / 2, board.shape[0] / 2), angle, 1.0)
    M[:, 2] += (w / 2 - board.shape[1] / 2 + shift[0], h / 2 - board.shape[0] / 2 + shift[1])
    return cv2.warpAffine(board, M, (w, h), flags=cv2.INTER_AREA, borderValue=200)


def warm(model=None) -> float:
    """Detect two synthetic boards (whole, and cut by the frame); returns the seconds it took."""
    from aicalib_tf.detect.pipeline import detect_corners

    t0 = time.perf_counter()
    for shift in ((0.0, 0.0), (230.0, 0.0)):
        detect_corners(synthetic_board(shift=shift), (9, 6), model=model)
    return time.perf_counter() - t0
