"""Frame selection: the motion gate, blur, near-duplicates, and the session's keep/skip reasons."""

import cv2
import numpy as np

from aicalib_tf.guided.selection import MotionGate, blur_px, board_pose, near_duplicate
from aicalib_tf.guided.session import GuidedCalibration, GuidedConfig

from .boards import PATTERN, FakeDetector, board_frame, motion_blurred


def test_blur_width_grows_with_motion_blur():
    gray, corners, ids = board_frame()
    sharp = blur_px(gray, corners, ids)
    assert 1.0 < sharp < 3.0
    assert blur_px(motion_blurred(gray, 12), corners, ids) > 2.5 * sharp


def test_motion_gate_skips_fast_and_unchanged_frames():
    gate = MotionGate(moving=2.0, changed=1.5, max_gap=100)
    a, _, _ = board_frame()
    b, _, _ = board_frame(shift=(150, 60), angle=30)
    assert gate.check(a) == ""  # the first frame is examined
    assert gate.check(a) == "unchanged since the last frame examined"
    assert gate.check(b) == "moving fast (blurred)"  # a jump between consecutive frames
    assert gate.check(b) == ""  # now steady, and new


def test_near_duplicates_are_found_by_place_size_and_tilt():
    g, c, ids = board_frame()
    p0 = board_pose(c, ids, 1.0, (640, 480))
    p1 = board_pose(c + 3.0, ids, 1.0, (640, 480))
    g2, c2, _ = board_frame(shift=(150, 80))
    p2 = board_pose(c2, ids, 1.0, (640, 480))
    assert near_duplicate(p1, [p0], (640, 480)) == 0
    assert near_duplicate(p2, [p0], (640, 480)) is None


def test_session_keeps_new_views_and_says_why_it_skips_others():
    det = FakeDetector()
    session = GuidedCalibration(GuidedConfig(PATTERN, 1.0, gate=False), det)
    frames = [board_frame(), board_frame(), board_frame(shift=(150, 80)), board_frame(shift=(-150, -80))]
    frames[3] = (motion_blurred(frames[3][0], 14),) + frames[3][1:]
    reasons = []
    for k, (gray, corners, ids) in enumerate(frames):
        det.next = (corners, ids)
        u = session.add((k, k / 30, gray))
        reasons.append((u.kept, u.reason))
    det.next = None
    u = session.add((4, 4 / 30, frames[0][0]))
    assert reasons[0] == (True, "new view") and reasons[2] == (True, "new view")
    assert reasons[1] == (False, "near-duplicate of frame 0")
    assert not reasons[3][0] and reasons[3][1].startswith("blurred")
    assert (u.examined, u.kept, u.reason) == (True, False, "no board")
    assert session.kept_frames == [0, 2] and session.skipped["blurred"] == 1
    assert any("not covered" in m for m in u.missing)


def test_final_views_are_the_design_over_every_view_seen():
    from aicalib_tf.geometry.lens import Lens
    from aicalib_tf.geometry.pattern import board_points, pattern_ids

    size = (640, 480)
    lens = Lens("plumb_bob", [[500, 0, 319.5], [0, 500, 239.5], [0, 0, 1]], [-0.2, 0.05, 0, 0, 0], size)
    ids = pattern_ids(PATTERN)
    P = board_points(ids, 25.0)
    P = P - P.mean(axis=0)
    rng = np.random.default_rng(4)
    det = FakeDetector()
    cfg = GuidedConfig(PATTERN, 25.0, model="plumb_bob", gate=False, min_views=6, max_views=12, target_px=1e-6)
    session = GuidedCalibration(cfg, det)
    gray = np.full(size[::-1], 128, np.uint8)
    for k in range(40):  # tilted views spread over the image, then the board held still in the middle
        yaw, pitch = rng.uniform(-40, 40, 2) if k < 20 else rng.uniform(-3, 3, 2)
        at = rng.uniform([-120, -80], [120, 80]) if k < 20 else rng.uniform(-5, 5, 2)
        R = cv2.Rodrigues(np.radians([pitch, yaw, 0.0]))[0]
        corners = lens.project(P @ R.T + [at[0], at[1], 450.0]) + rng.normal(0, 0.1, (len(ids), 2))
        det.next = (corners, ids)
        session.add((k, k / 30, gray))
    seen = {v.name for v in session.ranked_views()}
    assert {v.name for v in session.views} <= seen and len(seen) > len(session.views)
    final = session.final_views()
    assert len(final) == cfg.max_views  # the target cannot be reached: the best max_views of the views seen
    assert {v.name for v in final} == {v.name for v in session.ranked_views()[: cfg.max_views]}
    cal = session.result(views=final)
    assert abs(cal.K[0, 0] / 500 - 1) < 0.01
