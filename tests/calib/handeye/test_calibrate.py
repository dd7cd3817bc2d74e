"""Hand-eye calibration on corner-level synthetic sets (data_gen.handeye's truth, projected corners): the
closed form, the robust start, the joint fit in both setups, outlier rows, refusals, the poses files."""

from __future__ import annotations

import math

import numpy as np
import pytest

from aicalib_tf.calib.bundle import CalibrationError
from aicalib_tf.calib.fit import View
from aicalib_tf.calib.handeye.calibrate import calibrate_handeye
from aicalib_tf.calib.handeye.fit import chain_G
from aicalib_tf.calib.handeye.poses import match_poses, parse_poses
from aicalib_tf.calib.handeye.solve import board_flips, closed_form, robust_start
from aicalib_tf.cli import InputError
from aicalib_tf.geometry.pattern import pattern_ids
from aicalib_tf.geometry.transform import inv, matrix_to_quat, quat_to_matrix, rotation_angle, to_T
from data_gen.handeye import HandEyeSetConfig, sample_handeye


def _views(s, noise_px=0.1, seed=0, flip_every=0):
    """Projected corners of a set with Gaussian noise; every ``flip_every``-th view read turned by 180°."""
    rng = np.random.default_rng(seed)
    ids = pattern_ids(s.board.pattern_size)
    obj = s.board.object_points() * 1e-3
    views, poses = [], {}
    for k, C in enumerate(s.C):
        uv = s.camera.lens.project(obj @ C[:3, :3].T + C[:3, 3]) + rng.normal(0, noise_px, (len(ids), 2))
        if flip_every and k % flip_every == 1:
            uv = uv[::-1]
        views.append(View(f"v{k:02d}.png", uv, ids))
        poses[f"v{k:02d}.png"] = s.A_reported[k]
    return views, poses


def _errors(X, Xe):
    return math.degrees(rotation_angle((inv(X) @ Xe)[:3, :3])), 1e3 * np.linalg.norm(X[:3, 3] - Xe[:3, 3])


def test_closed_form_is_exact_without_noise():
    s = sample_handeye(HandEyeSetConfig(views=6, robot_noise=(1e-12, 1e-12), seed=3))
    X, Y = closed_form(chain_G("eye-in-hand", s.A_true), s.C)
    assert np.allclose(X, s.X, atol=1e-9) and np.allclose(Y, s.Y, atol=1e-9)


def test_robust_start_finds_swapped_rows_and_turned_boards():
    s = sample_handeye(HandEyeSetConfig(views=12, swap=2, seed=4))
    flips = board_flips(s.board.pattern_size, s.square_m)
    Cs = np.stack([s.C, s.C @ flips[1]], axis=1)
    Cs[5] = Cs[5, ::-1]  # view 5 read turned: its first candidate is the turned pose
    X, Y, inl, order = robust_start(chain_G("eye-in-hand", s.A_reported), Cs, np.random.default_rng(0))
    assert set(np.flatnonzero(~inl)) == set(s.swapped)
    assert order[5] == 1 and order[[k for k in range(12) if k not in (5, *s.swapped)]].sum() == 0
    assert _errors(s.X, X)[0] < 0.2


@pytest.mark.parametrize("setup", ["eye-in-hand", "eye-to-hand"])
def test_joint_fit_recovers_the_transform_and_names_swapped_rows(setup):
    s = sample_handeye(HandEyeSetConfig(setup=setup, views=12, swap=2, seed=5))
    views, poses = _views(s, flip_every=3)
    r = calibrate_handeye(views, poses, setup, s.camera.lens, s.square_m, pattern_size=s.board.pattern_size,
                          halves=False)
    assert set(r.rejected) == {f"v{k:02d}.png" for k in s.swapped}
    rot, mm = _errors(s.X, r.X)
    assert rot < 0.05 and mm < 0.5, (rot, mm)
    s_mm, s_deg = r.std_X
    assert np.all(s_mm > 0) and np.all(s_deg > 0) and s_deg.max() < 0.1 and s_mm.max() < 1.0
    assert r.X.shape == (4, 4) and r.cov_X.shape == (6, 6) and len(r.views) == 10


def test_free_intrinsics_and_the_verdict():
    s = sample_handeye(HandEyeSetConfig(views=10, lens="strong", seed=6))
    views, poses = _views(s)
    from aicalib_tf.geometry.lens import Lens

    start = Lens(s.camera.model, s.camera.K * [[1.01, 1, 1], [1, 1.01, 1], [1, 1, 1]], s.camera.dist * 0.9,
                 s.camera.image_size)
    r = calibrate_handeye(views, poses, "eye-in-hand", start, s.square_m, pattern_size=s.board.pattern_size,
                          free_intrinsics=True)
    assert abs(r.lens.fx - s.camera.K[0, 0]) < 1.0
    assert _errors(s.X, r.X)[0] < 0.05
    assert r.quality["halves"]["agree"] and r.quality["status"] in ("ok", "check")
    assert len(r.quality["spread"]["rms_deg"]) == 3


def test_rotations_about_one_axis_are_refused():
    s = sample_handeye(HandEyeSetConfig(views=6, seed=7))
    views, _ = _views(s)
    # a robot that only turns about its flange's z: the camera's views follow from the chain
    A = np.array([s.A_true[0] @ to_T([0, 0, 0.3 * k], [0.01 * k, 0, 0]) for k in range(6)])
    poses = {v.name: A[k] for k, v in enumerate(views)}
    with pytest.raises(CalibrationError, match="one axis"):
        calibrate_handeye(views, poses, "eye-in-hand", s.camera.lens, s.square_m, pattern_size=(9, 6))


def test_fewer_than_three_views_are_refused():
    s = sample_handeye(HandEyeSetConfig(views=3, seed=8))
    views, poses = _views(s)
    with pytest.raises(CalibrationError, match="fewer than 3"):
        calibrate_handeye(views[:2], poses, "eye-in-hand", s.camera.lens, s.square_m)


def test_quaternions_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(20):
        R = to_T(rng.normal(0, 2, 3), [0, 0, 0])[:3, :3]
        q = matrix_to_quat(R)
        assert np.allclose(quat_to_matrix(q), R, atol=1e-12) and q[3] >= 0


CSV = "image,x,y,z,qx,qy,qz,qw\nimgs/a.png,0.5,0.1,0.3,0,0,0,1\nb.png,0.4,0.0,0.2,0,0,0.7071068,0.7071068\n"


def test_csv_json_yaml_and_matrices_read_alike():
    a = parse_poses(CSV, "poses.csv")
    assert a.names == ("imgs/a.png", "b.png") and np.allclose(a.T[1, :3, :3] @ [1, 0, 0], [0, 1, 0], atol=1e-6)
    j = parse_poses('[{"image": "imgs/a.png", "x": 0.5, "y": 0.1, "z": 0.3, "qx": 0, "qy": 0, "qz": 0, "qw": 1},'
                    ' {"image": "b.png", "matrix": ' + str(a.T[1].tolist()) + '}]', "poses.json")
    y = parse_poses("poses:\n  - image: imgs/a.png\n    x: 0.5\n    y: 0.1\n    z: 0.3\n    qx: 0\n    qy: 0\n"
                    "    qz: 0\n    qw: 1\n  - image: b.png\n    matrix: " + str(a.T[1].ravel().tolist()) + "\n",
                    "poses.yaml")
    assert np.allclose(j.T, a.T) and np.allclose(y.T, a.T)


@pytest.mark.parametrize("text, match", [
    ("image,x,y,z,qx,qy,qz\na.png,0,0,0,0,0,0\n", "missing column.*qw"),
    ("image,x,y,z,qx,qy,qz,qw\na.png,0,nan,0,0,0,0,1\n", "row 2 .*y is 'nan'"),
    ("image,x,y,z,qx,qy,qz,qw\na.png,0,0,0,0,0,0,0.9\n", "row 2 .*quaternion norm 0.9"),
    ("image,x,y,z,qx,qy,qz,qw\na.png,512,31,402,0,0,0,1\n", "row 2 .*millimetres"),
    ("image,x,y,z,qx,qy,qz,qw\na.png,0,0,0,0,0,0,1\na.png,0,0,0,0,0,0,1\n", "second pose for image a.png"),
])
def test_bad_poses_name_the_file_row_and_problem(text, match):
    with pytest.raises(InputError, match=match) as e:
        parse_poses(text, "poses.csv")
    assert str(e.value).startswith("poses.csv")


def test_nearly_unit_quaternions_are_normalised_with_a_warning():
    p = parse_poses("image,x,y,z,qx,qy,qz,qw\na.png,0,0,0,0,0,0,1.0005\n", "poses.csv")
    assert np.allclose(p.T[0], np.eye(4)) and "normalised" in p.warnings[0]


def test_rows_match_images_by_name_then_stem_and_the_rest_is_listed():
    p = parse_poses(CSV + "c.jpg,0,0,0,0,0,0,1\nzz.png,0,0,0,0,0,0,1\n", "poses.csv")
    matched, images, rows = match_poses(p, ["a.png", "b.png", "c.png", "d.png"])
    assert set(matched) == {"a.png", "b.png", "c.png"} and images == ["d.png"] and rows == ["zz.png"]


def test_the_views_sigmas_weigh_the_joint_fit_and_the_outlier_limits():
    """Every other view 20x noisier: with each view's σ, X is several times nearer the truth, and a noisy
    view is judged against its own noise, not taken for a robot pose that disagrees."""
    s = sample_handeye(HandEyeSetConfig(views=12, seed=8, robot_noise=(1e-5, 1e-5)))
    rng = np.random.default_rng(8)
    ids = pattern_ids(s.board.pattern_size)
    obj = s.board.object_points() * 1e-3
    weighed, equal, poses = [], [], {}
    for k, C in enumerate(s.C):
        noise = 2.0 if k % 2 else 0.1
        uv = s.camera.lens.project(obj @ C[:3, :3].T + C[:3, 3]) + rng.normal(0, noise, (len(ids), 2))
        weighed.append(View(f"v{k:02d}.png", uv, ids, sigmas=np.full(len(ids), noise)))
        equal.append(View(f"v{k:02d}.png", uv, ids))
        poses[f"v{k:02d}.png"] = s.A_reported[k]
    a, b = (calibrate_handeye(vs, poses, "eye-in-hand", s.camera.lens, s.square_m, pattern_size=s.board.pattern_size,
                              halves=False) for vs in (weighed, equal))
    assert not a.rejected and len(a.views) == 12
    assert _errors(s.X, a.X)[1] < 0.3 * _errors(s.X, b.X)[1] and _errors(s.X, a.X)[0] < 0.5 * _errors(s.X, b.X)[0]
