"""Calibration from rendered ChArUco views (partial by nature) recovers the true camera."""

import numpy as np

from aicalib_tf.calib.fit import View, calibrate_camera
from aicalib_tf.calib.workflow import make_detector
from aicalib_tf.geometry.charuco import parse_board
from data_gen.presets import get_preset
from data_gen.sample import make_sequence

B = "charuco:9x7,square=30mm,marker=22mm,dict=DICT_4X4_50"


def test_charuco_views_recover_the_true_camera():
    board = parse_board(B)
    preset = get_preset("calib", board=B, views_per_camera=8, distortion=("mild",), rules=())
    seq = make_sequence(preset, 2, 0, size=(640, 480))
    detect = make_detector("cnn", board)
    views = []
    for k, s in enumerate(seq):
        hit = detect(s.image)
        if hit is not None and len(hit[0]) >= 6:
            views.append(View(f"v{k}", *hit))
    assert len(views) >= 6
    for v in views:  # ids as the truth has them
        truth = seq[int(v.name[1:])].corners
        assert np.abs(v.corners - truth[v.ids[:, 1] * 8 + v.ids[:, 0]]).max() < 0.3
    cal = calibrate_camera(views, board.pattern_size, board.square, (640, 480), model="plumb_bob")
    K = np.asarray(seq[0].label["K"])
    assert abs(cal.K[0, 0] / K[0, 0] - 1) < 0.01 and abs(cal.K[1, 1] / K[1, 1] - 1) < 0.01
    assert np.hypot(*(cal.K[:2, 2] - K[:2, 2])) < 3.0
    assert cal.rms < 0.3
