"""Placing a partial grid on the pattern (model-free): what a placement draws, and what the image rules out."""

import cv2
import numpy as np

from aicalib_tf.detect.chessboard import placement
from data_gen import make_sample


def test_a_placement_draws_squares_paper_and_unknown():
    uv = np.array([[-0.5, -0.5],  # board square (0, 0): black
                   [0.5, -0.5],  # (1, 0): white
                   [0.5, 0.5],  # (1, 1): black
                   [0.5, 0.05],  # 0.05 from a square's edge: blur, unknown
                   [0.5, -1.07],  # 0.07 beyond the top side: white paper
                   [0.5, -1.5],  # further out: margin or background, unknown
                   [-1.07, -1.07],  # beyond a corner of the board: unknown
                   [8.5, 5.5],  # board square (9, 6), the last: white
                   [9.07, 2.5]])  # beyond the right side: paper
    assert placement._expected(uv, (9, 6)).tolist() == [0, 1, 0, -1, 1, -1, -1, 1, 1]


def test_the_image_rules_out_a_turned_placement_of_a_board_corner():
    # the 4x4 corners at a board's corner (0, 0), the whole board in view: borders and colours
    # leave two placements (the grid's i along the columns or along the rows); drawn around the
    # grid, the turned one puts squares where the image shows white paper and background
    s = make_sample("clean", 3, 0, pattern=(9, 6), size=(640, 480))
    gray = cv2.GaussianBlur(s.image.astype(np.float32) / 255.0, (0, 0), 1.0)
    ids = np.array([(c, r) for r in range(4) for c in range(4)])
    pts = s.corners[ids[:, 1] * 9 + ids[:, 0]].astype(np.float64)
    turned = np.stack([3 - ids[:, 1], ids[:, 0]], 1)  # a 90° turn (handedness kept), on the same corners
    bad = placement._contradicted(ids, pts, [ids, turned], (9, 6), gray, black=0)
    assert bad[0] == 0 and bad[1] >= placement.RENDER_MIN


def test_a_grid_without_contrast_contradicts_no_placement():
    # equal black and white greys leave nothing to normalise by: no evidence either way (not NaN)
    s = make_sample("clean", 3, 0, pattern=(9, 6), size=(640, 480))
    ids = np.array([(c, r) for r in range(4) for c in range(4)])
    pts = s.corners[ids[:, 1] * 9 + ids[:, 0]].astype(np.float64)
    turned = np.stack([3 - ids[:, 1], ids[:, 0]], 1)
    flat = np.full((480, 640), 0.5, np.float32)
    with np.errstate(all="raise"):
        assert placement._contradicted(ids, pts, [ids, turned], (9, 6), flat, black=0) == [0, 0]
