"""The shadow-robust symmetric fit (aicalib_tf.detect.corners.shadow) on exact renders."""

import cv2
import numpy as np

from aicalib_tf.detect.corners.refine import refine_saddle
from aicalib_tf.detect.corners.shadow import asymmetry, refine_symmetric, shadow_asymmetry


def test_symmetric_fit_with_a_shadow_term_on_an_exact_shadowed_corner():
    # a corner at (24.3, 24.6) (x8 supersampled), times a shadow of 60 % whose edge passes 1.5 px from it
    s, h = 8, 48
    yy, xx = (np.mgrid[0:h * s, 0:h * s] + 0.5) / s - 0.5
    u = (xx - 24.3) * np.cos(0.3) + (yy - 24.6) * np.sin(0.3)
    v = -(xx - 24.3) * np.sin(0.5) + (yy - 24.6) * np.cos(0.5)
    board = np.where((u > 0) ^ (v > 0), 0.9, 0.1)
    shade = 1.0 - 0.6 * ((xx - 24.3) * np.cos(1.2) + (yy - 24.6) * np.sin(1.2) > 1.5)
    img = cv2.resize((board * shade).astype(np.float32), (h, h), interpolation=cv2.INTER_AREA)
    img = cv2.GaussianBlur(img, (0, 0), 0.7)
    start = np.array([[24.8, 24.2], [23.9, 25.0], [24.3, 24.6]])
    saddle, _ = refine_saddle(img, start, sigma=0.0, radius=5)
    assert np.linalg.norm(saddle - [24.3, 24.6], axis=1).max() > 0.5
    assert asymmetry(img, saddle, 5).min() > 0.02
    out, ok = refine_symmetric(img, start, radius=5)
    assert ok.all()
    np.testing.assert_allclose(out, [[24.3, 24.6]] * 3, atol=0.15)  # 0.09 px: blur after the hard edge is not exactly a product


def _supersampled(board_fn, shade_fn, h=48, s=8):
    yy, xx = (np.mgrid[0:h * s, 0:h * s] + 0.5) / s - 0.5
    img = cv2.resize((board_fn(xx, yy) * shade_fn(xx, yy)).astype(np.float32), (h, h), interpolation=cv2.INTER_AREA)
    return cv2.GaussianBlur(img, (0, 0), 0.7)


def test_shadow_asymmetry_tells_a_shadowed_x_junction_from_a_t_junction():
    def x_board(xx, yy):
        return np.where(((xx - 24.3) > 0) ^ ((yy - 24.6) > 0), 0.9, 0.1)

    def t_board(xx, yy):  # a board's edge: squares below y = 24.6, white paper above
        return np.where(yy < 24.6, 0.9, np.where(xx < 24.3, 0.1, 0.9))

    def shadow(xx, yy):
        return 1.0 - 0.6 * ((xx - 24.3) * np.cos(1.2) + (yy - 24.6) * np.sin(1.2) > 1.5)

    def light(xx, yy):
        return np.ones_like(xx)

    c = np.array([[24.3, 24.6]])
    shaded_x = _supersampled(x_board, shadow)
    assert asymmetry(shaded_x, c, 5)[0] > 0.1  # the shadow breaks point symmetry...
    assert shadow_asymmetry(shaded_x, c, 5)[0] < 0.01  # ...in the way a shadow edge does
    assert shadow_asymmetry(_supersampled(x_board, light), c, 5)[0] < 0.001
    for shade in (light, shadow):
        assert shadow_asymmetry(_supersampled(t_board, shade), c, 5)[0] > 0.05
