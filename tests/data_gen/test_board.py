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


def test_a_shaped_board_renders_with_its_exact_corners():
    from dataclasses import replace

    from data_gen.presets import get_preset
    from data_gen.render import board_coordinates
    from data_gen.sample import draw_scene, make_sample

    shape = (0.0, 0.0, 0.05, 0.02, -0.02)  # a twisted board with an S along each axis, squares
    preset = replace(get_preset("calib"), name="calib_shaped", shape=shape)
    scene = draw_scene(preset, 0, 3)
    assert scene.board.bent and scene.board.to_dict()["shape"] == list(shape)
    X, Y = board_coordinates(scene.camera.pixel_to_ray(scene.corners), scene.rvec, scene.tvec, scene.board)
    np.testing.assert_allclose(np.stack([X, Y], 1), scene.board.object_points()[:, :2], atol=1e-9)
    z = scene.board.object_points()[:, 2] / scene.board.square_size
    # the grid's four corners (u, v = ±1): twist u·v, cubic_x P3(u) = u, cubic_y P3(v) = v
    np.testing.assert_allclose(z[[0, 8, 45, 53]], [0.05 - 0.02 + 0.02, -0.05 + 0.02 + 0.02, -0.05 - 0.02 - 0.02,
                                                  0.05 + 0.02 - 0.02], atol=1e-12)
    sample, flat = make_sample(preset, 0, 3), make_sample("calib", 0, 3)
    assert sample.label["board"]["shape"] == list(shape) and "shape" not in flat.label["board"]
    assert np.max(np.linalg.norm(sample.corners - flat.corners, axis=1)) > 0.2  # the labels follow the shape
    with pytest.raises(ValueError, match="shape"):
        replace(scene.board, shape=(0.0,) * 8)
