"""guided.session: the image circle of the examined frames."""

import numpy as np

from aicalib_tf.guided.session import GuidedCalibration, GuidedConfig


def _no_board(gray):
    return None


def test_the_sessions_image_circle_comes_from_the_examined_frames():
    yy, xx = np.mgrid[:480, :640]
    disk = np.where(np.hypot(xx - 320.0, yy - 240.0) <= 200.0, 170, 2).astype(np.uint8)
    session = GuidedCalibration(GuidedConfig(pattern=(9, 6), gate=False), _no_board)
    assert session.image_circle() is None  # nothing examined yet
    for k in range(3):
        session.add((k, k / 30.0, disk))
    c = session.image_circle()
    assert c is not None and abs(c.cx - 320.0) < 0.5 and abs(c.cy - 240.0) < 0.5 and abs(c.radius - 200.5) < 1.0
    full = GuidedCalibration(GuidedConfig(pattern=(9, 6), gate=False), _no_board)
    full.add((0, 0.0, np.full((480, 640), 120, np.uint8)))
    assert full.image_circle() is None
