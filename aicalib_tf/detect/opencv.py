"""OpenCV's chessboard detectors, wrapped behind one signature for fair comparisons.

Both take an (H, W) uint8 grey image and ``pattern_size = (cols, rows)`` and return
``(found, corners)`` with corners (cols·rows, 2) float32 (x, y) px in OpenCV order, or None.
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["opencv_classic", "opencv_sb", "CLASSIC_FLAGS", "MIN_CLASSIC_SIDE"]

CLASSIC_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
MIN_CLASSIC_SIDE = 16  # findChessboardCorners' threshold block (a tenth of the short side, odd, > 1) needs 15 px
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3)


def opencv_classic(image: np.ndarray, pattern_size: tuple[int, int], *, half_window: int = 5, flags: int = CLASSIC_FLAGS):
    """``cv2.findChessboardCorners`` then ``cv2.cornerSubPix`` (half-window px, 30 it / 1e-3).

    The classic pipeline of ../shared/data/README.md. Returns (found, (N, 2) float32 | None); not
    found in an image under :data:`MIN_CLASSIC_SIDE` px a side (OpenCV's adaptive threshold asserts there).
    """
    if min(image.shape[:2]) < MIN_CLASSIC_SIDE:
        return False, None
    ok, corners = cv2.findChessboardCorners(image, tuple(pattern_size), flags=flags)
    if not ok:
        return False, None
    corners = cv2.cornerSubPix(image, corners, (half_window, half_window), (-1, -1), _SUBPIX_CRITERIA)
    return True, corners.reshape(-1, 2)


def opencv_sb(image: np.ndarray, pattern_size: tuple[int, int], *, flags: int = 0):
    """``cv2.findChessboardCornersSB`` (sector-based, subpixel built in). Returns (found, corners | None)."""
    ok, corners = cv2.findChessboardCornersSB(image, tuple(pattern_size), flags=flags)
    if not ok:
        return False, None
    return True, corners.reshape(-1, 2)
