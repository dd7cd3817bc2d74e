"""Run every kernel of the detector once ahead of the first real image, and set a process up
before a stream of frames.

:func:`warm` runs the pipeline on three synthetic views (a whole board, one cut by the frame so
the partial-board stages run too, one crossed by a shadow edge so the shadow-robust fit runs),
which reaches the kernels a detection uses (checked against OpenCV's 13 photos). With the kernels
compiled ahead of time (:mod:`aicalib_tf.kernels`) that costs little; where they run on numba's
JIT (no C compiler at install), it compiles each into numba's on-disk cache (up to a few seconds
each), so no later process compiles. ``python -m aicalib_tf.export --warm`` calls it after
building the kernels (``make setup``).
"""

from __future__ import annotations

import time

import cv2
import numpy as np

__all__ = ["warm", "synthetic_board", "shadowed"]


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


def warm(model=None, size: tuple[int, int] = (640, 480)) -> float:
    """Detect three synthetic boards of ``size`` (W, H) px (whole, cut by the frame, and crossed by
    a shadow edge); returns the seconds it took.

    Also the way to start a stream of frames without a stall: the interpreter plans itself for a
    new image size (10–30 ms), and with numba's JIT instead of the compiled kernels, the first
    kernel call of a process sets numba's runtime up (about 0.7 s on this project's 2-core CPU,
    caches compiled or not), so a first frame takes 2–3× the median with the compiled kernels and
    12–16× without (``benchmarks/first_image.py``). ``warm(model, size)`` with the stream's model
    and frame size pays that before the first frame.
    """
    from aicalib_tf.detect.pipeline import detect_corners

    t0 = time.perf_counter()
    for shift in ((0.0, 0.0), (WARM_SHIFT * size[0] / 640, 0.0)):
        detect_corners(synthetic_board(shift=shift, size=size), (9, 6), model=model)
    detect_corners(shadowed(synthetic_board(size=size)), (9, 6), model=model)
    return time.perf_counter() - t0


def shadowed(gray: np.ndarray, factor: float = 0.55) -> np.ndarray:
    """``gray`` (H, W) uint8 with a hard shadow edge across it: the pixels right of a slanted line
    through the centre darkened by ``factor``. Corners on the edge take the shadow-robust fit
    (:mod:`aicalib_tf.detect.corners.shadow`), whose kernels the plain views never reach."""
    h, w = gray.shape
    y, x = np.mgrid[0:h, 0:w]
    dark = x > w / 2 + 0.3 * (y - h / 2)
    return np.where(dark, gray * factor, gray).astype(np.uint8)


WARM_SHIFT = 230.0  # px at 640 px wide: the second view's board is cut by the frame (a partial board)
