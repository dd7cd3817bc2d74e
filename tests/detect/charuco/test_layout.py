"""A ChArUco description of the wrong size: the markers' layout refuses it and names the size they fit."""

import cv2
import numpy as np
import pytest

from aicalib_tf.detect.charuco.layout import fitting_sizes, layout_mismatch, pair_offsets
from aicalib_tf.geometry.charuco import parse_board

TRUE = "charuco:7x5,square=30mm,marker=22mm,dict=DICT_4X4_50"


def _seen(board, rvec=(0.3, -0.2, 0.1), t=(-90.0, -60.0, 400.0), f=600.0):
    """The board's markers as a pinhole camera sees them: ids (M,), corners (M, 4, 2) px."""
    pts = board.marker_corners().reshape(-1, 3)
    K = np.array([[f, 0, 320], [0, f, 240], [0, 0, 1.0]])
    px, _ = cv2.projectPoints(pts, np.array(rvec), np.array(t), K, None)
    return board.marker_ids(), px.reshape(-1, 4, 2)


def test_neighbours_offsets_are_their_squares_difference():
    board = parse_board(TRUE)
    ids, corners = _seen(board)
    pairs, offsets = pair_offsets(board, corners)
    squares = board.marker_squares()
    assert len(pairs) >= 20
    np.testing.assert_allclose(offsets, squares[pairs[:, 1]] - squares[pairs[:, 0]], atol=0.2)


@pytest.mark.parametrize("spec", ["10x8", "9x7", "8x5", "5x7", "6x5"])
def test_a_description_of_another_size_is_refused_naming_the_printed_size(spec):
    printed = parse_board(TRUE)
    ids, corners = _seen(printed)
    wrong = parse_board(TRUE.replace("7x5", spec))
    keep = ids < wrong.first_id + wrong.n_markers  # what OpenCV reads: ids in the description's range
    why = layout_mismatch(wrong, ids[keep], corners[keep])
    assert why is not None and f"contradict {spec} squares" in why and "they fit 7x5 squares" in why, why


def test_the_right_description_and_one_with_unseen_rows_are_read():
    ids, corners = _seen(parse_board(TRUE))
    assert layout_mismatch(parse_board(TRUE), ids, corners) is None
    assert layout_mismatch(parse_board(TRUE.replace("7x5", "7x6")), ids, corners) is None  # rows past the last id
    board = parse_board(TRUE)
    pairs, offsets = pair_offsets(board, corners)
    assert fitting_sizes(board, ids, pairs, offsets)[0] == (7, 5)


def test_detection_and_calibration_refuse_a_wrong_size(tmp_path, capsys):
    from aicalib_tf.calibrate import main
    from aicalib_tf.detect.pipeline import detect_charuco
    from data_gen.presets import get_preset
    from data_gen.sample import make_sample

    for i in range(3):
        s = make_sample(get_preset("clean", board=TRUE), 5, i, size=(640, 480))
        cv2.imwrite(str(tmp_path / f"view{i}.png"), (np.clip(s.image, 0, 1) * 255).astype(np.uint8)
                    if s.image.dtype != np.uint8 else s.image)
    refused = {}
    assert detect_charuco(tmp_path / "view0.png", TRUE.replace("7x5", "10x8"), refused=refused) == []
    assert "they fit 7x5 squares" in next(iter(refused.values()))
    code = main([str(tmp_path / "*.png"), "--board", TRUE.replace("7x5", "10x8"), "--out", str(tmp_path / "out"),
                 "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "fit 7x5 squares" in err and not (tmp_path / "out" / "camera.json").exists(), err
