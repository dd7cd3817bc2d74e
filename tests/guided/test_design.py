"""The design of a view subset: the predicted uncertainty of a subset, and backward elimination."""

import cv2
import numpy as np

from aicalib_tf.calib.quality import _compensated_jacobian, grid_points, view_information
from aicalib_tf.geometry.lens import Lens
from aicalib_tf.geometry.pattern import board_points, pattern_ids
from aicalib_tf.guided.design import design_weight, elimination_order, predicted_mse

SIZE = (640, 480)
LENS = Lens("plumb_bob", [[500, 0, 319.5], [0, 500, 239.5], [0, 0, 1]], [-0.2, 0.05, 0, 0, 0], SIZE)


def _info(yaw_deg: float, pitch_deg: float, shift=(0.0, 0.0), distance=400.0) -> np.ndarray:
    """A 9x6 board of 25 mm squares centred on the axis (shifted by ``shift`` mm), turned by yaw/pitch."""
    P = board_points(pattern_ids((9, 6)), 25.0)
    P = P - P.mean(axis=0)
    R = cv2.Rodrigues(np.radians([pitch_deg, yaw_deg, 0.0]))[0]
    return view_information(LENS, P @ R.T + np.array([shift[0], shift[1], distance]))


def _weight() -> np.ndarray:
    G, ok = _compensated_jacobian(LENS, grid_points(SIZE), None)
    return design_weight(G, ok)


def test_a_singular_information_is_never_preferred():
    A = _weight()
    one = _info(0, 0)
    assert predicted_mse(one, A) == float("inf")  # one view cannot fix fx, fy, cx, cy and the distortion
    several = sum(_info(y, p, s) for y, p, s in [(30, 0, (-80, 0)), (-30, 0, (80, 0)), (0, 30, (0, -60)),
                                                  (0, -30, (0, 60)), (20, 20, (0, 0))])
    assert np.isfinite(predicted_mse(several, A))


def test_elimination_drops_repeats_before_the_views_that_fix_the_lens():
    tilted = [(35, 0, (-90, -40)), (-35, 0, (90, 40)), (0, 35, (60, -60)), (0, -35, (-60, 60)), (25, 25, (0, 0))]
    repeats = [(0, 0, (dx, 0)) for dx in (-6, -3, 0, 3, 6, 9)]  # the board held facing the camera, barely moved
    infos = [_info(*t) for t in repeats] + [_info(*t) for t in tilted]
    order = elimination_order(infos, _weight(), keep=3)
    assert sorted(order) == list(range(len(infos)))
    last5 = set(order[-5:])
    assert len(last5 & set(range(6, 11))) >= 4, order  # the tilted views are kept
    # every size of the nested design is at least as good as the first k views given (repeats first)
    A = _weight()
    for k in (5, 7, 9):
        design = predicted_mse(sum(infos[i] for i in order[-k:]), A)
        given = predicted_mse(sum(infos[:k]), A)
        assert design <= given


def test_elimination_is_a_no_op_down_to_keep():
    infos = [_info(10 * i, 0) for i in range(3)]
    assert sorted(elimination_order(infos, _weight(), keep=3)) == [0, 1, 2]
    assert elimination_order([], _weight()) == []
