"""Rig calibration: the joint fit recovers known rigs, ties cameras through partial boards, rejects bad pairs."""

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from aicalib_tf.calib.fit import CalibrationError, View
from aicalib_tf.calib.rig.fit import MIN_SHARED_VIEWS, calibrate_rig
from aicalib_tf.calib.rig.quality import assess_rig, baseline_std, rotation_std_deg
from aicalib_tf.geometry.rectify import rotation_angle_deg
from tests.calib.rig.synthetic import PATTERN, SQUARE, fisheye, pinhole, rig_pose, rig_views

SIZE = (800, 600)


def _truth(lenses, extra=None):
    R1, T1 = rig_pose()
    Rs, Ts = [np.eye(3), R1], [np.zeros(3), T1]
    if extra is not None:
        Rs.append(extra[0])
        Ts.append(extra[1])
    return lenses, Rs, Ts


def test_noiseless_mixed_rig_is_recovered_exactly():
    lenses, Rs, Ts = _truth([pinhole(), fisheye()])
    views = rig_views(lenses, Rs, Ts, n=12, noise=0.0, seed=1)
    rig = calibrate_rig(views, PATTERN, SQUARE, SIZE, models=["plumb_bob", "equidistant"])
    assert rig.rms < 1e-6
    assert rotation_angle_deg(rig.R[1] @ Rs[1].T) < 1e-6
    np.testing.assert_allclose(rig.T[1], Ts[1], atol=1e-8)
    for cal, lens in zip(rig.cameras, lenses):
        np.testing.assert_allclose(cal.K, lens.K, rtol=1e-6)
        np.testing.assert_allclose(cal.dist, lens.dist, atol=1e-6)
    assert [c.model for c in rig.cameras] == ["plumb_bob", "equidistant"]


def test_noisy_rig_errors_are_within_the_predicted_sigma():
    lenses, Rs, Ts = _truth([pinhole(), pinhole(f=640, k1=-0.05)])
    views = rig_views(lenses, Rs, Ts, n=20, noise=0.1, seed=2)
    rig = assess_rig(calibrate_rig(views, PATTERN, SQUARE, SIZE), views)
    b_err = abs(rig.baseline() - np.linalg.norm(Ts[1]))
    assert b_err < 5 * baseline_std(rig) and baseline_std(rig) > 0
    assert rotation_angle_deg(rig.R[1] @ Rs[1].T) < 5 * rotation_std_deg(rig)
    pair = rig.quality["pairs"][0]
    # |Δy| of two cameras' independent corner noise: sqrt(2)·0.1 px, the calibration adds little
    assert 0.1 < pair["in_sample_rms_px"] < 0.2
    assert pair["held_out_rms_px"] == pytest.approx(pair["in_sample_rms_px"], rel=0.25)
    assert rig.quality["folds"] == 5 and "good" in rig.quality["verdict"]
    assert set(pair["per_frame"]) == set(rig.frames)


def test_cameras_that_never_see_the_same_corners_are_still_tied_by_the_board():
    lenses, Rs, Ts = _truth([pinhole(), pinhole()])
    views = rig_views(lenses, Rs, Ts, n=14, noise=0.0, seed=3)
    cut = []
    for k, vs in enumerate(views):  # camera 0 keeps columns 0-3 of each board, camera 1 columns 5-8
        keep = [(v.ids[:, 0] <= 3) if k == 0 else (v.ids[:, 0] >= 5) for v in vs]
        cut.append([View(v.name, v.corners[m], v.ids[m]) for v, m in zip(vs, keep) if m.sum() >= 8])
    assert all(not set(map(tuple, a.ids)) & set(map(tuple, b.ids)) for a in cut[0] for b in cut[1] if a.name == b.name)
    rig = calibrate_rig(cut, PATTERN, SQUARE, SIZE, models="plumb_bob")
    np.testing.assert_allclose(rig.T[1], Ts[1], atol=1e-7)
    assert len(rig.frames) >= MIN_SHARED_VIEWS


def test_a_pair_whose_board_moved_between_exposures_is_rejected():
    lenses, Rs, Ts = _truth([pinhole(), pinhole()])
    views = rig_views(lenses, Rs, Ts, n=16, noise=0.05, seed=4)
    # frame f05 of camera 1: the board moved 1 cm before camera 1's exposure; its own view is fine
    moved = rig_views(lenses, Rs, [Ts[0], Ts[1] + [0.01, 0.0, 0.0]], n=16, noise=0.05, seed=4)[1]
    views[1] = [next(m for m in moved if m.name == v.name) if v.name == "f05" else v for v in views[1]]
    rig = calibrate_rig(views, PATTERN, SQUARE, SIZE, models="plumb_bob")
    assert "f05" in rig.rejected and "outlier pair" in rig.rejected["f05"]
    assert "f05" not in rig.frames
    assert abs(rig.baseline() - np.linalg.norm(Ts[1])) < 2e-4


def test_three_cameras_place_a_camera_through_another():
    R2 = Rotation.from_euler("y", -6, degrees=True).as_matrix()
    lenses, Rs, Ts = _truth([pinhole(), pinhole(), fisheye()], (R2, -R2 @ [0.35, 0.0, 0.0]))
    views = rig_views(lenses, Rs, Ts, n=24, noise=0.0, seed=5)
    # camera 2 never shares a frame with camera 0: it can only be placed through camera 1
    views[0] = [v for v in views[0] if v.name >= "f12"]
    views[2] = [v for v in views[2] if v.name < "f12"]
    assert not {v.name for v in views[2]} & {v.name for v in views[0]}
    rig = calibrate_rig(views, PATTERN, SQUARE, SIZE, models=["plumb_bob", "plumb_bob", "equidistant"])
    np.testing.assert_allclose(rig.T[2], Ts[2], atol=1e-7)
    assert rotation_angle_deg(rig.R[2] @ Rs[2].T) < 1e-5


def test_relative_views_serve_their_camera_only():
    lenses, Rs, Ts = _truth([pinhole(), pinhole()])
    views = rig_views(lenses, Rs, Ts, n=14, noise=0.0, seed=6)
    v = views[1][0]
    views[1][0] = View(v.name, v.corners, v.ids - v.ids.min(axis=0), relative=True)  # ids shifted: a board larger than the frame
    rig = calibrate_rig(views, PATTERN, SQUARE, SIZE, models="plumb_bob")
    np.testing.assert_allclose(rig.T[1], Ts[1], atol=1e-7)
    assert v.name not in rig.frames and rig.rms < 1e-6


def test_bad_rigs_say_what_is_wrong():
    lenses, Rs, Ts = _truth([pinhole(), pinhole()])
    views = rig_views(lenses, Rs, Ts, n=12, noise=0.0, seed=7)
    apart = [views[0], [dataclasses.replace(v, name=v.name + "x") for v in views[1]]]
    with pytest.raises(CalibrationError, match="never see the board at the same time"):
        calibrate_rig(apart, PATTERN, SQUARE, SIZE, models="plumb_bob")
    few = [views[0], [dataclasses.replace(v, name=v.name + "x") if k >= 2 else v for k, v in enumerate(views[1])]]
    with pytest.raises(CalibrationError, match="cam1 shares too few frames"):
        calibrate_rig(few, PATTERN, SQUARE, SIZE, models="plumb_bob")
    with pytest.raises(CalibrationError, match="^cam1: "):
        calibrate_rig([views[0], views[1][:2]], PATTERN, SQUARE, SIZE, models="plumb_bob")
    with pytest.raises(ValueError, match="at least 2 cameras"):
        calibrate_rig([views[0]], PATTERN, SQUARE, SIZE)


def test_the_views_sigmas_weigh_the_joint_fit():
    """Half the frames 20x noisier: with each view's σ the baseline is far nearer the truth than with
    equal weights, and the RMS stays in px."""
    lenses, Rs, Ts = _truth([pinhole(), pinhole(f=640, k1=-0.05)])
    views = rig_views(lenses, Rs, Ts, n=12, noise=0.0, seed=4)
    rng = np.random.default_rng(4)
    noisy = {v.name for v in views[0][::2]}

    def noised(v):
        s = 1.0 if v.name in noisy else 0.05
        return View(v.name, v.corners + s * rng.standard_normal(v.corners.shape), v.ids, sigmas=np.full(len(v.ids), s))

    weighed = [[noised(v) for v in vs] for vs in views]
    equal = [[View(v.name, v.corners, v.ids) for v in vs] for vs in weighed]
    a = calibrate_rig(weighed, PATTERN, SQUARE, SIZE, models="plumb_bob")
    b = calibrate_rig(equal, PATTERN, SQUARE, SIZE, models="plumb_bob")
    assert np.linalg.norm(a.T[1] - Ts[1]) < 0.2 * np.linalg.norm(b.T[1] - Ts[1])
    assert a.rms == pytest.approx(b.rms, rel=0.05)
