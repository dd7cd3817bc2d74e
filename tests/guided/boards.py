"""Synthetic board frames with known corners for the guided-loop tests."""

import cv2
import numpy as np

from aicalib_tf.detect.warm import synthetic_board

PATTERN = (9, 6)


def board_frame(shift=(0.0, 0.0), angle=12.0, square=20, size=(640, 480)):
    """(gray (H, W) uint8, corners (54, 2) px, ids (54, 2)) of :func:`synthetic_board`'s board."""
    cols, rows = PATTERN
    gray = synthetic_board(PATTERN, square, size, angle, shift)
    bw, bh = (cols + 3) * square, (rows + 3) * square
    M = cv2.getRotationMatrix2D((bw / 2, bh / 2), angle, 1.0)
    M[:, 2] += (size[0] / 2 - bw / 2 + shift[0], size[1] / 2 - bh / 2 + shift[1])
    ids = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), -1).reshape(-1, 2)
    pts = (ids + 2) * square - 0.5
    corners = pts @ M[:, :2].T + M[:, 2]
    return gray, corners, ids


def motion_blurred(gray, length=12):
    """``gray`` blurred by a horizontal motion of ``length`` px."""
    k = np.full((1, length), 1.0 / length, np.float32)
    return cv2.filter2D(gray, -1, k, borderType=cv2.BORDER_REPLICATE)


class FakeDetector:
    """Returns the corners set in ``next`` (the frame's truth) for the next call."""

    relative = False

    def __init__(self):
        self.next = None

    def __call__(self, gray):
        return self.next


CHARUCO = "charuco:6x5,square=40mm,marker=30mm,dict=DICT_4X4_50"  # the board of the ``charuco_pair`` fixture
