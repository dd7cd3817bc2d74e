import importlib.util
from pathlib import Path

import cv2
import numpy as np

from aicalib_tf.bench.conditions import condition_samples, select_conditions

_spec = importlib.util.spec_from_file_location(
    "partial_ambiguity", Path(__file__).parents[2] / "benchmarks" / "partial_ambiguity.py")
pa = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(pa)


def test_moved_pose_puts_the_mapped_board_point_where_the_old_one_was():
    rvec, tvec = np.array([0.3, -0.2, 0.1]), np.array([10.0, -5.0, 400.0])
    R = cv2.Rodrigues(rvec)[0]
    q = np.array([[c, r, 0.0] for r in range(6) for c in range(9)]) * 25.0
    for _, A, b in pa.rivals(np.array([[0, 0], [3, 2]]))[:6]:
        r2, t2 = pa.moved_pose(rvec, tvec, A, b, 25.0)
        g = q.copy()
        g[:, :2] = q[:, :2] @ A.T + 25.0 * b
        np.testing.assert_allclose(g @ cv2.Rodrigues(r2)[0].T + t2, q @ R.T + tvec, atol=1e-9)


def test_rivals_keep_every_id_on_the_pattern():
    ids = np.array([[0, 0], [1, 0], [0, 1], [1, 1]])
    for _, A, b in pa.rivals(ids):
        m = ids @ A.T + b
        assert m[:, 0].min() >= 0 and m[:, 0].max() <= 8 and m[:, 1].min() >= 0 and m[:, 1].max() <= 5


def test_a_corner_of_the_board_in_view_is_ambiguous_and_a_long_strip_is_not():
    # evaluate partial #0 shows one corner of the board with two sides cut by the frame (a quarter
    # turn reads it as another corner); the visible corners of #3 span every column and row, so only
    # the 180° turn is a rival, and the colours rule it out
    cond = select_conditions("partial")[0]
    images = dict(condition_samples(cond, 4))
    corner = pa.analyse(cond, 0, images[0].image, tol=2)
    assert corner["ties"] >= 1 and not corner["unique"] and corner["determined"] == 0
    strip = pa.analyse(cond, 3, images[3].image, tol=2)
    assert strip["ties"] == 0 and strip["determined"] == strip["visible"] > 0
