"""ChArUco board descriptions: parsing, errors, and the layout against OpenCV's own boards."""

import cv2
import numpy as np
import pytest

from aicalib_tf.geometry.charuco import CharucoBoard, is_charuco, layout_image, parse_board


def test_parse_round_trip_and_units():
    b = parse_board("charuco:11x8,square=30mm,marker=2.2cm,dict=dict_5x5_100,legacy,first=2")
    assert b.squares == (11, 8) and b.pattern_size == (10, 7)
    assert b.square == 30 and b.marker == pytest.approx(22) and b.unit == "mm"
    assert b.dictionary == "DICT_5X5_100" and b.legacy and b.first_id == 2
    assert parse_board(b.describe()) == b
    assert b.n_markers == 44 and b.object_points().shape == (70, 3)
    assert b.object_points()[11].tolist() == [30.0, 30.0, 0.0]  # id 11 = (col 1, row 1)
    assert is_charuco(" charuco:3x3") and not is_charuco("9x6")


@pytest.mark.parametrize("text, words", [
    ("charuco:11x8,square=30mm,marker=30mm,dict=DICT_5X5_100", "smaller than square"),
    ("charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_10", "unknown ArUco dictionary"),
    ("charuco:11x8,square=30mm,marker=22mm,dict=DICT_4X4_50,first=10", "holds 50 markers"),
    ("charuco:11x8,square=30mm,dict=DICT_4X4_50", "missing marker="),
    ("charuco:11x8,square=30furlong,marker=22mm,dict=DICT_4X4_50", "square must be a length"),
    ("charuco:11,square=30mm,marker=22mm,dict=DICT_4X4_50", "XxY"),
    ("charuco:11x8,square=30mm,marker=22mm,dict=DICT_4X4_50,colour=red", "unexpected"),
    ("charuco:2x2,square=30mm,marker=22mm,dict=DICT_4X4_50", "pattern_size"),
    ("chess:9x6", "charuco:"),
    ("charuco:11x8,square=1e308mm,marker=1e307mm,dict=DICT_4X4_50", "too large"),
    ("charuco:11x8,square=200km,marker=22mm,dict=DICT_4X4_50", "square must be a length"),
])
def test_bad_descriptions_are_errors(text, words):
    with pytest.raises(ValueError, match=words):
        parse_board(text)


@pytest.mark.parametrize("legacy", [False, True])
@pytest.mark.parametrize("squares", [(5, 4), (5, 5), (4, 4), (6, 5), (11, 8)])
def test_layout_matches_opencv(squares, legacy):
    b = CharucoBoard(squares, 36.0, 28.0, "DICT_5X5_100", legacy, first_id=3)
    cv = b.to_opencv()
    assert (np.asarray(cv.getIds()).ravel() == b.marker_ids()).all()
    # OpenCV's frame is ours shifted by one square
    assert np.allclose(np.asarray(cv.getObjPoints()), b.marker_corners() + [36.0, 36.0, 0.0], atol=1e-4)
    assert np.allclose(np.asarray(cv.getChessboardCorners()), b.object_points() + [36.0, 36.0, 0.0], atol=1e-4)
    p = 36  # px per square: the 7-bit markers tile 28 px exactly
    ref = cv.generateImage((squares[0] * p, squares[1] * p), marginSize=0, borderBits=1)
    assert np.array_equal(layout_image(b, p), ref)


def test_legacy_changes_the_layout_of_even_row_boards_only():
    even = [CharucoBoard((5, 4), 30, 22, "DICT_4X4_50", legacy=f).marker_squares()[0].tolist() for f in (False, True)]
    odd = [CharucoBoard((5, 5), 30, 22, "DICT_4X4_50", legacy=f).marker_squares()[0].tolist() for f in (False, True)]
    assert even == [[1, 0], [0, 0]] and odd == [[1, 0], [1, 0]]


def test_every_predefined_dictionary_is_accepted():
    names = [n for n in dir(cv2.aruco) if n.startswith("DICT_")]
    for n in names:
        b = CharucoBoard((4, 4), 30, 22, n)
        assert b.bits >= 4
