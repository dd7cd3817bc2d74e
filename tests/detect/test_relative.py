"""A board larger than the frame (no edge in view): ids relative to the visible grid, on request."""

import cv2
import numpy as np

from aicalib_tf.detect.chessboard.partial import _fit_pattern
from aicalib_tf.detect.detection import UNDECIDED
from aicalib_tf.detect.pipeline import detect_corners
from aicalib_tf.detect.warm import synthetic_board

BIG = dict(square=100, angle=8.0)  # 12 x 9 squares of 100 px: every edge of the board is out of a 640x480 frame


def test_a_board_larger_than_the_frame_comes_back_only_when_asked():
    img = synthetic_board(**BIG)
    plain = detect_corners(img, (9, 6))
    assert not plain.found and plain.reason == UNDECIDED and not plain.relative
    det = detect_corners(img, (9, 6), relative=True)
    assert det.found and det.relative and not det.complete
    assert len(det.corners) >= 20 and det.ids.min() == 0
    assert det.ids[:, 0].max() < 9 and det.ids[:, 1].max() < 6
    # one lattice: a homography from the ids predicts every corner, one id step is one 100 px square
    H, _ = cv2.findHomography(det.ids.astype(np.float64), det.corners.astype(np.float64))
    pred = cv2.perspectiveTransform(det.ids.reshape(-1, 1, 2).astype(np.float64), H).reshape(-1, 2)
    assert np.abs(pred - det.corners).max() < 0.1
    step = np.linalg.norm(cv2.perspectiveTransform(np.array([[[1.0, 0.0]]]), H) - cv2.perspectiveTransform(np.zeros((1, 1, 2)), H))
    assert abs(step - 100.0) < 0.5


def test_relative_ids_keep_handedness_when_turned_to_fit():
    ij = np.array([[0, 0], [1, 0], [0, 1], [0, 7]])  # 2 wide, 8 tall: only fits a 9x6 pattern turned
    ids = _fit_pattern(ij, (9, 6))
    assert ids.max(axis=0).tolist() == [7, 1]
    a, b = ids[1] - ids[0], ids[2] - ids[0]  # the (i, j) steps, turned
    assert a[0] * b[1] - a[1] * b[0] == 1  # the same handedness as (1, 0), (0, 1)
    assert _fit_pattern(np.array([[0, 0], [9, 0], [0, 6]]), (9, 6)) is None
