"""Rendered hand-eye sets: the chain holds exactly, the robot's noise and swapped rows are as asked, files round-trip."""

import json
import math

import cv2
import numpy as np
import pytest

from aicalib_tf.calib.handeye.poses import read_poses
from aicalib_tf.geometry.transform import inv, rotation_angle
from data_gen.handeye import HandEyeSetConfig, main, render_view, sample_handeye


@pytest.mark.parametrize("setup", ["eye-in-hand", "eye-to-hand"])
def test_the_chain_is_exact(setup):
    s = sample_handeye(HandEyeSetConfig(setup=setup, views=5, seed=1))
    G = s.A_true if setup == "eye-in-hand" else inv(s.A_true)
    assert np.allclose(G @ s.X[None] @ s.C, s.Y[None], atol=1e-12)
    d = np.linalg.norm(s.C[:, :3, 3] + s.C[:, :3, :3] @ s.board.object_points().mean(0) * 1e-3, axis=1)
    assert np.all((d > 0.29) & (d < 0.71))  # the board's centre 0.3-0.7 m from the camera


def test_robot_noise_and_swaps_are_as_asked():
    s = sample_handeye(HandEyeSetConfig(views=40, robot_noise=(0.05, 0.5), swap=4, seed=2))
    ok = [k for k in range(40) if k not in s.swapped]
    D = inv(s.A_true[ok]) @ s.A_reported[ok]
    deg = np.degrees(rotation_angle(D[:, :3, :3]))
    mm = 1e3 * np.linalg.norm(s.A_reported[ok, :3, 3] - s.A_true[ok, :3, 3], axis=1)
    # norms of 3-D Gaussians: RMS = √3 σ
    assert 0.7 < np.sqrt(np.mean(deg ** 2)) / (math.sqrt(3) * 0.05) < 1.3
    assert 0.7 < np.sqrt(np.mean(mm ** 2)) / (math.sqrt(3) * 0.5) < 1.3
    assert len(s.swapped) == 4
    for k in s.swapped:
        assert not np.allclose(s.A_reported[k], s.A_true[k], atol=1e-3)
        assert any(np.allclose(s.A_reported[k], s.A_true[j], atol=1e-2) for j in s.swapped if j != k)


def test_the_whole_board_is_in_the_rendered_image():
    s = sample_handeye(HandEyeSetConfig(views=3, size=(320, 240), seed=3))
    img = render_view(s, 0)
    ok, corners = cv2.findChessboardCorners(img, s.board.pattern_size)
    assert img.shape == (240, 320) and img.dtype == np.uint8 and ok


def test_the_command_line_writes_images_poses_and_truth(tmp_path):
    assert main(["--out", str(tmp_path), "--views", "3", "--size", "320x240", "--swap", "2", "--seed", "4"]) == 0
    truth = json.loads((tmp_path / "truth.json").read_text())
    poses = read_poses(tmp_path / "poses.csv")
    assert poses.names == ("view_00.png", "view_01.png", "view_02.png") and len(truth["swapped"]) == 2
    assert np.allclose(poses.T, truth["T_base_flange_reported"], atol=1e-8)
    assert truth["setup"] == "eye-in-hand" and np.allclose(truth["T_flange_camera"], truth["X"])
    assert len(list((tmp_path / "images").glob("*.png"))) == 3


def test_bad_arguments_exit_2(tmp_path, capsys):
    assert main(["--out", str(tmp_path), "--swap", "3"]) == 2
    assert "swap" in capsys.readouterr().err


def test_a_marker_board_in_metres_renders_at_the_same_size_as_in_mm():
    mm = sample_handeye(HandEyeSetConfig(views=3, seed=4, board="charuco:7x5,square=40mm,marker=30mm,dict=DICT_5X5_100"))
    m = sample_handeye(HandEyeSetConfig(views=3, seed=4, board="charuco:7x5,square=0.04m,marker=0.03m,dict=DICT_5X5_100"))
    assert m.square_m == pytest.approx(0.04) and mm.square_m == pytest.approx(0.04)
    assert np.allclose(m.board.object_points(), mm.board.object_points())  # both in the renderer's mm
    assert np.allclose(m.C, mm.C)
