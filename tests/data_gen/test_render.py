"""The renderer against hand-computed pixels and against brute-force supersampling."""

import cv2
import numpy as np
import pytest

from data_gen.board import Board
from aicalib_tf.geometry.camera import Camera
from aicalib_tf.geometry.pose import project_points
from data_gen.render import fibonacci_lattice, render_board

from .brute_force import BACKGROUND, brute_force_render

BLACK, WHITE, BG = 0.1, 0.9, 0.5
TOL = 1.0 / 89 + 1e-6  # one lattice sample of coverage


def _fronto_parallel(cx, cy, size=(64, 48)):
    """1 board unit = 1 px: u = X + cx, v = Y + cy. Inner corner (0, 0) sits at pixel (cx, cy)."""
    cam = Camera(np.array([[100.0, 0, cx], [0, 100.0, cy], [0, 0, 1]]), np.zeros(5), size)
    board = Board((3, 3), square_size=8.0, margin=0.5, black=BLACK, white=WHITE)
    return cam, board, np.zeros(3), np.array([0.0, 0.0, 100.0])


def test_lattice_projections_are_all_distinct():
    lat = fibonacci_lattice(89)
    assert len(np.unique(np.floor(lat[:, 0] * 89))) == 89
    assert len(np.unique(np.floor(lat[:, 1] * 89))) == 89


def test_pixel_centre_convention_by_hand():
    # Corner (0, 0) exactly on the centre of pixel (20, 20): the board edges x = 20 and
    # y = 20 + 8k run through pixel centres, so those pixels are exactly half black, half white.
    cam, board, rvec, tvec = _fronto_parallel(20.0, 20.0)
    img = render_board(cam, board, rvec, tvec, np.full((48, 64), BG, np.float32))
    half = (BLACK + WHITE) / 2
    assert img[22, 20] == pytest.approx(half, abs=TOL * (WHITE - BLACK))  # edge x = 20 through centre
    assert img[20, 22] == pytest.approx(half, abs=TOL * (WHITE - BLACK))  # edge y = 20
    assert img[20, 20] == pytest.approx(half, abs=TOL * (WHITE - BLACK))  # the X-junction itself
    assert img[21, 21] == pytest.approx(BLACK, abs=1e-6)  # square (i=1, j=1): black
    assert img[21, 19] == pytest.approx(WHITE, abs=1e-6)  # square (i=0, j=1): white
    assert img[19, 19] == pytest.approx(BLACK, abs=1e-6)  # square (i=0, j=0): black
    # Paper ends at X = -8 - 4 = -12, i.e. u = 8, through the centre of pixel 8.
    assert img[20, 8] == pytest.approx((WHITE + BG) / 2, abs=TOL * (WHITE - BG))
    assert img[20, 7] == pytest.approx(BG, abs=1e-6)
    # The labels agree: projectPoints puts corner (0, 0) at (20.0, 20.0).
    assert np.allclose(project_points(board.object_points()[:1], rvec, tvec, cam), [[20.0, 20.0]])


@pytest.mark.parametrize("frac", [0.25, 0.6, 0.9])
def test_partial_coverage_by_hand(frac):
    # Edge at u = 20.5 - frac: pixel 20 ([19.5, 20.5]) is covered by the square left of the
    # edge for (1 - frac) and by the right one for frac.
    cx = 20.5 - frac
    cam, board, rvec, tvec = _fronto_parallel(cx, 20.0)
    img = render_board(cam, board, rvec, tvec, np.full((48, 64), BG, np.float32))
    # Row 24 is in square row j = 1 (Y = 4): left of the edge i = 0 (white), right i = 1 (black).
    expected = (1 - frac) * WHITE + frac * BLACK
    assert img[24, 20] == pytest.approx(expected, abs=TOL * (WHITE - BLACK))


def test_adaptive_renderer_matches_brute_force():
    w, h = 120, 90
    cam = Camera(np.array([[110.0, 0, 61.3], [0, 111.0, 43.7], [0, 0, 1]]), np.array([-0.3, 0.06, 0.001, -0.001, 0.0]), (w, h))
    board = Board((5, 4), square_size=10.0, margin=0.4, black=0.12, white=0.88)
    R = cv2.Rodrigues(np.array([0.5, 0.3, 0.0]))[0] @ cv2.Rodrigues(np.array([0.0, 0.0, 0.4]))[0]
    tvec = np.array([0.0, 0.0, 90.0]) - R @ board.centre()
    rvec = cv2.Rodrigues(R)[0].ravel()
    img = render_board(cam, board, rvec, tvec, np.full((h, w), BACKGROUND, np.float32))
    ref = brute_force_render(cam, board, rvec, tvec, 16)
    diff = np.abs(img - ref)
    assert diff.max() < (1 / 16 + 1 / 89) * (board.white - board.black)
    assert diff.mean() < 2e-3
    assert (diff > 0).sum() > 100  # the board really is there, with many edge pixels


def test_background_shape_is_checked():
    cam, board, rvec, tvec = _fronto_parallel(20.0, 20.0)
    with pytest.raises(ValueError, match="background"):
        render_board(cam, board, rvec, tvec, np.zeros((10, 10), np.float32))


def test_point_sampling_takes_each_pixel_from_its_centre_alone():
    # Corner (0, 0) 0.3 px right of and 0.2 px below pixel (20, 20)'s centre: area sampling mixes the edge
    # pixels; one sample at each centre gives every pixel the class of its centre, so edges step.
    cam, board, rvec, tvec = _fronto_parallel(20.3, 20.2)
    bg = np.full((48, 64), BG, np.float32)
    point = render_board(cam, board, rvec, tvec, bg, samples=1)
    area = render_board(cam, board, rvec, tvec, bg)
    assert set(np.unique(point).tolist()) <= {np.float32(BLACK), np.float32(WHITE), np.float32(BG)}
    mixed = ~np.isin(area, [np.float32(BLACK), np.float32(WHITE), np.float32(BG)])
    assert mixed.sum() > 50 and np.array_equal(point[~mixed], area[~mixed])
    # pixel (20, 21)'s centre lies left of the edge x = 20.3: in the white square left of corner (0, 0)'s row
    assert point[21, 20] == np.float32(WHITE) and point[21, 21] == np.float32(BLACK)
