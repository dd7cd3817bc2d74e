import numpy as np
import pytest

from data_gen.board import Board, sample_board
from aicalib_tf.geometry.pattern import parse_pattern


def test_object_points_follow_opencv_order():
    b = Board((4, 3), square_size=2.0)
    pts = b.object_points()
    assert pts.shape == (12, 3)
    # index = r*cols + c, corner (c, r) at (c*s, r*s, 0)
    assert np.allclose(pts[1], [2.0, 0.0, 0.0])
    assert np.allclose(pts[4], [0.0, 2.0, 0.0])
    assert np.allclose(pts[-1], [6.0, 4.0, 0.0])


def test_classify_squares_margin_and_outside():
    b = Board((3, 3), square_size=1.0, margin=0.5)
    X = np.array([-0.5, 0.5, 0.5, -1.25, -2.0, np.nan])
    Y = np.array([-0.5, -0.5, 0.5, 0.0, 0.0, 0.0])
    # top-left square black; its right neighbour white; diagonal black; margin white; outside; no plane
    assert b.classify(X, Y).tolist() == [0, 1, 0, 1, 2, 2]


@pytest.mark.parametrize("bad", [(1, 5), (2, 2), (21, 15), (16, 16), (9,)])
def test_bad_patterns_are_rejected(bad):
    with pytest.raises(ValueError, match="pattern_size"):
        Board(bad)


def test_pattern_limits_and_parse():
    assert Board((3, 3)).pattern_size == (3, 3)
    assert Board((20, 15)).pattern_size == (20, 15)
    assert parse_pattern("9x6") == (9, 6)
    with pytest.raises(ValueError, match="COLSxROWS"):
        parse_pattern("9-6")


def test_sampled_boards_have_paper_grey_levels():
    rng = np.random.default_rng(0)
    for _ in range(50):
        b = sample_board(rng, cols_range=(3, 20), rows_range=(3, 15))
        assert 0.0 < b.black < 0.3 and 0.65 < b.white < 1.0
        assert 3 <= b.rows <= b.cols <= 20 and b.rows <= 15
