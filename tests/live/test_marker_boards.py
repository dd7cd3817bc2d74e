"""The live page with a Kalibr AprilGrid: the loop keeps whole and cut views, and the page gets each
corner's tag id (it writes a tag's id once, at its corners' centre)."""

from __future__ import annotations

import cv2
import numpy as np

from aicalib_tf.geometry.aprilgrid import layout_image, parse_board
from aicalib_tf.live.server import LiveConfig, LiveState, corner_labels

GRID = "aprilgrid:3x3,tag=40mm,spacing=0.3"
Q, AT = 6, 80  # px a lattice unit (6 px a tag bit), where the grid's first corner lies


def _frame(cut: int) -> tuple[np.ndarray, dict]:
    """A 640x480 frame of :data:`GRID` with its ``cut`` left px hidden, and {lattice id: (x, y) px} of
    the corners left in view."""
    board = parse_board(GRID)
    m = board.fraction[0] * Q + 6
    img = layout_image(board, Q, m)
    frame = np.full((480, 640), 140, np.uint8)
    frame[AT - m: AT - m + img.shape[0], AT - m: AT - m + img.shape[1]] = img
    frame[:, :cut] = 140
    truth = {tuple(i): (AT - 0.5 + i[0] * Q, AT - 0.5 + i[1] * Q) for i in board.corner_ids().tolist()}
    return cv2.GaussianBlur(frame, (0, 0), 0.8), {k: xy for k, xy in truth.items() if xy[0] > cut}


def test_an_aprilgrid_runs_the_loop_and_the_page_gets_tag_ids(tmp_path):
    from aicalib_tf.calib.workflow import make_detector

    board = parse_board(GRID)
    cfg = LiveConfig(board.pattern_size, board.square_size, "mm", out=str(tmp_path / "calib"), model="plumb_bob",
                     board=GRID)
    state = LiveState(cfg, make_detector("cnn", board))
    for cut in (0, 145):  # the whole grid, then one cut by the frame's left edge
        frame, truth = _frame(cut)
        update = state.add_gray(frame)
        assert update["examined"] and len(update["ids"]) == len(update["corners"]), update
        assert update["missing"]  # what the views still lack, as for a chessboard
        want = board.tag_of(list(truth))  # each seen corner's tag
        assert sorted(update["ids"]) == sorted(want.tolist())
        assert all(update["ids"].count(k) == 4 for k in set(update["ids"]))  # the tags seen whole
        corners = np.asarray(update["corners"])
        nearest = np.min([np.hypot(*(corners - xy).T) for xy in truth.values()], axis=1)
        assert nearest.max() < 0.5
    assert len(set(_frame(145)[1]) ^ set(_frame(0)[1])) == 12  # the cut hides one column of tags
    assert state.session.views


def test_corner_labels_per_board():
    chess = LiveConfig((9, 6))
    assert corner_labels(chess) is None
    charuco = LiveConfig((5, 4), board="charuco:6x5,square=30mm,marker=20mm,dict=DICT_4X4_50")
    assert corner_labels(charuco)([[0, 0], [4, 3], [1, 2]]) == [0, 19, 11]
    grid = corner_labels(LiveConfig((37, 37), board="aprilgrid:3x3,tag=40mm,spacing=0.3,first=5"))
    # tag 5 is bottom-left (Kalibr's order): its corners are lattice (0..10, 26..36); tag 13 top-right
    assert grid([[0, 36], [10, 26], [36, 0], [26, 10], [13, 13]]) == [5, 5, 13, 13, 9]
