import cv2
import numpy as np

from aicalib_tf.detect.chessboard.grid_growth import TOLERANCE
from aicalib_tf.detect.chessboard.step_trend import TREND_LIMIT, turned


def _line(ratios, start=100 + 50j, step=40 + 0j):
    """Points (K, 2) of a line whose k-th step is the one before times ratios[k-1] (complex)."""
    z = [start, start + step]
    for r in ratios:
        step = step * r
        z.append(z[-1] + step)
    z = np.array(z)
    return np.stack([z.real, z.imag], 1)


def test_bent_extrapolation_follows_steps_that_turn_and_shrink_at_a_steady_ratio():
    # points z_k = c + r^k e^{ik·θ}: each step is the last one turned by θ and scaled by r, as a line's
    # steps towards a fisheye's rim are, nearly; the steps' ratio predicts the next point exactly
    z = 100 + 40 * (0.7 * np.exp(0.3j)) ** np.arange(4)
    p = np.stack([z.real, z.imag], 1)
    got = turned(p[2][None], p[1][None], p[0][None])[0]
    assert np.allclose(got, p[3], atol=1e-9)
    quadratic = 3 * p[2] - 3 * p[1] + p[0]
    assert np.hypot(*(quadratic - p[3])) > 1.0


def test_the_ratios_trend_follows_steps_that_shrink_faster_towards_the_rim():
    # the ratio falls by 0.75 a step (steps of 40, 36, 24, 12, 4.7 px): the constant ratio misses the
    # corner by 0.43 tolerances (a corner 4.7 px on lies within 0.39 of it), its trend lands on it
    r = 0.9 * np.exp(0.15j) * (0.75 * np.exp(0.05j)) ** np.arange(4)
    p = _line(r)
    p1, p2, p3, p4 = (p[k][None] for k in (-2, -3, -4, -5))
    tol = TOLERANCE * np.hypot(*(p1 - p2)[0])
    assert np.hypot(*(turned(p1, p2, p3)[0] - p[-1])) > 0.4 * tol
    assert np.allclose(turned(p1, p2, p3, p4)[0], p[-1], atol=1e-9)


def test_a_change_of_ratio_beyond_the_limit_is_followed_only_to_it():
    # steps of 40, 40, 80: the ratio doubled in one step (noise on a short step, say); the next step
    # is the last one times 2 · TREND_LIMIT, not 2 · 2
    p = _line([1.0, 2.0])
    p1, p2, p3, p4 = (p[k][None] for k in (-1, -2, -3, -4))
    got = turned(p1, p2, p3, p4)[0]
    assert np.isclose(np.hypot(*(got - p1[0])), 80 * 2 * TREND_LIMIT)


def test_true_corners_of_a_close_up_squeezed_6_times_assemble_into_their_lattice():
    # closeup-unified (seed 41) #39: an EUCM circle, the board's steps from 67 px down to 8 px at the
    # rim, seen in one order; the constant ratio stops the growth at 35 of 54 corners, the ratio's
    # trend reaches all
    from dataclasses import replace

    from aicalib_tf.detect.chessboard.grid import assemble_grids
    from data_gen.presets import get_preset
    from data_gen.sample import draw_scene

    p = replace(get_preset("closeup_laws"), lens=("ds", "eucm"))
    sc = draw_scene(p, 41, 39, size=(640, 480), pattern=(9, 6))
    gray = cv2.GaussianBlur(sc.render().astype(np.float32), (0, 0), 1.0)
    grids = assemble_grids(sc.corners[np.random.default_rng(1).permutation(54)], gray=gray, limit=10, bend=True)
    assert len(grids[0]) == 54 and sorted(grids[0].shape) == [6, 9]


def test_a_line_the_trend_misses_is_asked_again_where_the_ratio_alone_predicts():
    # three lines with steps of 10, 10, 14 px (a corner off by noise, say): the trend predicts a 27 px
    # step, 7.8 px (1.9 tolerances) beyond the next corners; the ratio alone predicts them
    from aicalib_tf.detect.chessboard.grid_growth import GrowingGrid, _grow_side

    ys = [0.0, 10.0, 20.0, 34.0]
    pts = np.array([(10.0 * j, y) for y in ys for j in range(3)] + [(10.0 * j, 53.6) for j in range(3)])
    lat = GrowingGrid(pts, np.ones(len(pts), bool), bend=True)
    for k in range(12):
        lat.take((k // 3, k % 3), k)
    assert _grow_side(lat, 0, 1)
    assert [lat.cells[(4, j)] for j in range(3)] == [12, 13, 14]
