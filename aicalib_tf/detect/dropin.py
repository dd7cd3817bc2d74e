"""A drop-in for ``cv2.findChessboardCorners``, on the CNN pipeline (:func:`detect_corners`)."""

from __future__ import annotations

import numpy as np

from aicalib_tf.detect.pipeline import detect_corners

__all__ = ["find_chessboard_corners"]


def find_chessboard_corners(image, pattern_size: tuple[int, int], corners=None, flags: int = 0, *,
                            model=None) -> tuple[bool, np.ndarray | None]:
    """Drop-in for ``cv2.findChessboardCorners(image, patternSize[, corners[, flags]])``.

    Returns (found, corners): corners (cols·rows, 1, 2) float32 in OpenCV's order, or None when no full
    board is found. ``corners`` is OpenCV's optional output array: an (cols·rows, 1, 2) float32 array
    passed here is filled in place and returned. ``flags`` takes OpenCV's ``CALIB_CB_*`` values and
    accepts every one of them without effect: they tune OpenCV's thresholding and quad search
    (``ADAPTIVE_THRESH``, ``NORMALIZE_IMAGE``, ``FILTER_QUADS``, ``FAST_CHECK``, and the ``SB``
    detector's ``EXHAUSTIVE``/``ACCURACY``/``LARGER``/``MARKER``), which this detector does not have;
    its corners are always refined to sub-pixel accuracy.

    >>> find_chessboard_corners(np.zeros((60, 80), np.uint8), (9, 6), None, 0)
    (False, None)
    """
    if isinstance(flags, bool) or not isinstance(flags, (int, np.integer)) or flags < 0:
        raise TypeError(f"flags must be a non-negative int of cv2.CALIB_CB_* values, got {flags!r}")
    det = detect_corners(image, pattern_size, model=model)
    if not det.complete:
        return False, None
    found = det.corners.reshape(-1, 1, 2).astype(np.float32)
    if isinstance(corners, np.ndarray) and corners.shape == found.shape and corners.dtype == np.float32 \
            and corners.flags.writeable:
        corners[...] = found
        return True, corners
    return True, found
