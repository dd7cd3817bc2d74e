"""Absurd calibrations are refused or marked failed, never written as good (view_checks, rig.sanity)."""

from __future__ import annotations

import numpy as np
import pytest

from aicalib_tf.calib.files import undistort
from aicalib_tf.calib.fit import CalibrationError, View, calibrate_camera
from aicalib_tf.calib.rig.fit import calibrate_rig
from aicalib_tf.calib.rig.sanity import rig_problems
from aicalib_tf.calib.view_checks import duplicates, view_problem
from tests.calib.rig.synthetic import PATTERN, SQUARE, pinhole, rig_pose, rig_views
from tests.calib.synthetic import synthetic_views

SIZE = (800, 600)


@pytest.fixture(scope="module")
def lens():
    return pinhole(size=SIZE)


@pytest.fixture(scope="module")
def rig_inputs(lens):
    R, T = rig_pose(0.12)
    return [lens, pinhole(f=620.0, size=SIZE, k1=-0.05)], [np.eye(3), R], [np.zeros(3), T]


def test_identical_views_count_once(lens):
    views = synthetic_views(lens, n=3, noise=0.1, seed=4)
    copies = [View(f"copy{k}.jpg", views[0].corners, views[0].ids) for k in range(12)]
    with pytest.raises(CalibrationError, match="3 usable views; need at least 3|1 usable views"):
        calibrate_camera(copies + [views[0]], PATTERN, SQUARE, SIZE, model="plumb_bob")
    cal = calibrate_camera(views + copies, PATTERN, SQUARE, SIZE, model="plumb_bob")
    assert len(cal.views) == 3 and sum("same view" in why for why in cal.rejected.values()) == 12


def test_near_duplicates_within_a_pixel_are_one_view(lens):
    v = synthetic_views(lens, n=1, seed=5)[0]
    moved = View("b", v.corners + 0.3, v.ids)
    apart = View("c", v.corners + [2.0, 0.0], v.ids)
    assert duplicates([v, moved, apart]) == {"b": v.name}


def test_collinear_or_outside_corners_are_refused_before_fitting():
    ids = np.stack(np.meshgrid(np.arange(9), np.arange(6)), -1).reshape(-1, 2)
    line = np.stack([ids[:, 0] * 30.0 + ids[:, 1] * 5.0 + 50, ids[:, 0] * 15.0 + ids[:, 1] * 2.5 + 40], 1)
    assert "one line in the image" in view_problem(line, ids, PATTERN, SIZE)
    spread = np.stack([ids[:, 0] * 30.0 + 50, ids[:, 1] * 30.0 + 40], 1)
    assert view_problem(spread, ids, PATTERN, SIZE) is None
    assert "outside the 800x600 image" in view_problem(spread + [700, 0], ids, PATTERN, SIZE)


def test_collinear_views_never_reach_the_fit():
    ids = np.stack(np.meshgrid(np.arange(9), np.arange(6)), -1).reshape(-1, 2)
    views = [View(f"v{k}", np.stack([ids[:, 0] * 30.0 + ids[:, 1] * 5.0 + k, ids[:, 0] * 15.0 + ids[:, 1] * 2.5], 1) + 60,
                  ids) for k in range(5)]
    with pytest.raises(CalibrationError, match="0 usable views"):
        calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob")


@pytest.mark.parametrize("square", [1e-30, 1e30])
def test_the_square_size_only_scales_the_poses(lens, square):
    views = synthetic_views(lens, n=10, noise=0.1, seed=6)
    ref = calibrate_camera(views, PATTERN, 1.0, SIZE, model="plumb_bob")
    cal = calibrate_camera(views, PATTERN, square, SIZE, model="plumb_bob")
    assert np.allclose(cal.K, ref.K, rtol=1e-9) and np.allclose(cal.tvecs / square, ref.tvecs, rtol=1e-9)


def test_undistort_refuses_an_array_it_cannot_remap(lens):
    cal = calibrate_camera(synthetic_views(lens, n=6, seed=7), PATTERN, SQUARE, SIZE, model="plumb_bob")
    for bad in (np.zeros((600, 800), bool), np.zeros((600, 800), np.complex64), np.zeros((600, 800, 3, 2), np.uint8)):
        with pytest.raises(ValueError, match="undistort takes"):
            undistort(bad, cal)


def test_a_good_rig_has_no_problem(rig_inputs):
    lenses, Rs, Ts = rig_inputs
    views = rig_views(lenses, Rs, Ts, n=12, noise=0.1, seed=1)
    rig = calibrate_rig(views, PATTERN, SQUARE, SIZE, models="plumb_bob")
    assert rig_problems(rig) == []


def test_one_camera_given_twice_has_no_baseline(rig_inputs):
    lenses, Rs, Ts = rig_inputs
    views = rig_views(lenses, Rs, Ts, n=12, noise=0.1, seed=1)[0]
    rig = calibrate_rig([views, views], PATTERN, SQUARE, SIZE, models="plumb_bob")
    problems = rig_problems(rig)
    assert any("same images" in p for p in problems), problems


def test_unrelated_pairs_are_a_failed_rig(rig_inputs):
    """Camera 1's frames paired with camera 0's frames of other moments (pairing by file number gone wrong)."""
    lenses, Rs, Ts = rig_inputs
    a, b = rig_views(lenses, Rs, Ts, n=14, noise=0.1, seed=3)
    names = [v.name for v in b]
    shuffled = [View(names[(k + 5) % len(names)], v.corners, v.ids) for k, v in enumerate(b)]
    try:
        rig = calibrate_rig([a, shuffled], PATTERN, SQUARE, SIZE, models="plumb_bob")
    except CalibrationError:
        return  # refused outright is as good as failed
    assert rig_problems(rig), "unrelated pairs passed the sanity checks"
