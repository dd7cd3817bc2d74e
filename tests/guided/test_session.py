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


def test_the_sessions_guidance_stays_inside_the_image_circle():
    import cv2

    from aicalib_tf.geometry.lens import Lens
    from aicalib_tf.geometry.pattern import board_points, pattern_ids
    from aicalib_tf.guided.guidance import candidate_points
    from tests.guided.boards import PATTERN, FakeDetector

    size, f, r = (640, 480), 140.0, 140.0 * np.radians(80.0)  # a 160° circular fisheye
    lens = Lens("equidistant", [[f, 0, 319.5], [0, f, 239.5], [0, 0, 1]], [0.0, 0.0, 0.0, 0.0], size)
    yy, xx = np.mgrid[:480, :640]
    disk = np.where(np.hypot(xx - 319.5, yy - 239.5) <= r, 150, 3).astype(np.uint8)
    ids = pattern_ids(PATTERN)
    P = board_points(ids, 25.0)
    P = P - P.mean(axis=0)
    rng = np.random.default_rng(5)
    det = FakeDetector()
    session = GuidedCalibration(GuidedConfig(PATTERN, 25.0, gate=False, max_views=30), det)
    u, k = None, 0
    while len(session.views) < 10 and k < 60:  # boards inside the circle, tilted
        yaw, pitch = rng.uniform(-35, 35, 2)
        at = rng.uniform([-160, -120], [160, 120])
        corners = lens.project(P @ cv2.Rodrigues(np.radians([pitch, yaw, 0.0]))[0].T + [at[0], at[1], 300.0])
        inside = np.hypot(corners[:, 0] - 319.5, corners[:, 1] - 239.5).max() < r - 5
        det.next = (corners + rng.normal(0, 0.05, corners.shape), ids) if inside else None
        u = session.add((k, k / 30, disk))
        k += 1
    circle = session.image_circle()
    assert circle is not None and abs(circle.radius - r) < 2.0
    assert u.guidance is not None and "image circle" in u.guidance.text, u.guidance
    assert not any("corner" in m for m in u.missing), u.missing
    est = Lens(u.estimate.model, u.estimate.K, u.estimate.dist, size)
    for distance in (250.0, 300.0, 400.0):  # the suggested board exists inside the circle near the boards' distance
        assert candidate_points(est, u.guidance.region, u.guidance.tilt, distance, PATTERN, 25.0, circle) is not None


def test_a_marker_boards_partial_views_are_kept_and_calibrate():
    """A ChArUco-like detector names the corners it sees by their board ids (absolute, not relative to
    the visible grid): a board cut by the frame's edge is a view, and the loop keeps and fits such views."""
    import cv2

    from aicalib_tf.geometry.pattern import board_points, pattern_ids

    pattern, square, size = (10, 7), 30.0, (640, 480)
    K = np.array([[520.0, 0, 319.5], [0, 520.0, 239.5], [0, 0, 1]])
    dist = np.array([-0.2, 0.05, 0, 0, 0])
    ids = pattern_ids(pattern)
    obj = board_points(ids, square)
    rng = np.random.default_rng(7)
    frames = []
    while len(frames) < 14:
        rvec = np.radians(rng.uniform([-35, -35, -20], [35, 35, 20]))
        tvec = np.array([rng.uniform(-150, 150), rng.uniform(-120, 120), rng.uniform(450, 700)]) - [135, 90, 0]
        px = cv2.projectPoints(obj, rvec, tvec, K, dist)[0].reshape(-1, 2)
        inside = (px[:, 0] > 4) & (px[:, 0] < size[0] - 4) & (px[:, 1] > 4) & (px[:, 1] < size[1] - 4)
        if 20 <= inside.sum() < len(ids):  # only boards cut by the frame
            frames.append((px[inside] + rng.normal(0, 0.05, (inside.sum(), 2)), ids[inside]))

    class Marker:
        relative, sigmas, k = False, None, 0

        def __call__(self, gray):
            self.k += 1
            return frames[self.k - 1]

    session = GuidedCalibration(GuidedConfig(pattern=pattern, square=square, model="plumb_bob", gate=False,
                                             max_views=20), Marker())
    gray = np.full(size[::-1], 128, np.uint8)
    updates = [session.add((k, k / 30.0, gray)) for k in range(len(frames))]
    assert sum(u.kept for u in updates) >= 6, [u.reason for u in updates]
    assert all(len(v.ids) < len(ids) for v in session.views)  # every kept view is a partial board
    cal = session.result()
    assert abs(cal.K[0, 0] / 520.0 - 1) < 0.01 and abs(cal.K[0, 2] - 319.5) < 3
