"""Kalibr AprilGrids through the multi-camera workflows, end to end on data_gen renders: ``calibrate --rig``
on a stereo rig's photos, ``check`` against one of the rig's cameras, ``handeye`` on a rendered set."""

import json
import math

import cv2
import numpy as np
import pytest

from aicalib_tf.geometry.aprilgrid import parse_board
from aicalib_tf.geometry.rectify import rotation_angle_deg

SPEC = "aprilgrid:4x3,tag=50mm,spacing=0.3"


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    """(folder with left/, right/ and out/ (the rig's calibration), truth, the command's exit code)."""
    from aicalib_tf.calibrate import main
    from data_gen.rig import make_rig_sequence

    root = tmp_path_factory.mktemp("aprilgrid_rig")
    truth, frames = make_rig_sequence(4, pairs=4, lenses=("pinhole", "pinhole"), size=(480, 360),
                                      baseline=(100.0, 400.0), board=parse_board(SPEC))
    for side, k in (("left", 0), ("right", 1)):
        (root / side).mkdir()
        for f, frame in enumerate(frames):
            cv2.imwrite(str(root / side / f"{side}{f + 1:02d}.png"), frame[k].image)
    rc = main(["--rig", f"cam0={root}/left/*.png", f"cam1={root}/right/*.png", "--board", SPEC,
               "--out", str(root / "out"), "--workers", "1", "--quiet"])
    return root, truth, rc


def test_an_aprilgrid_rig_recovers_its_baseline_within_its_sigma(rig):
    root, truth, rc = rig
    assert rc == 0
    result = json.loads((root / "out" / "rig.json").read_text())
    assert result["quality"]["status"] == "ok" and result["meta"]["board"] == SPEC
    pair = result["quality"]["pairs"][0]
    baseline = float(np.linalg.norm(np.asarray(result["T"])[1]))
    assert abs(baseline - truth.baseline()) < 3 * pair["baseline_std"], (baseline, truth.baseline(), pair)
    assert rotation_angle_deg(np.asarray(result["R"])[1] @ truth.R[1].T) < 3 * pair["rotation_std_deg"]
    for cam in ("cam0", "cam1"):  # each camera's own file names the board, as a single camera's does
        assert json.loads((root / "out" / cam / "camera.json").read_text())["meta"]["board"] == SPEC


def test_check_reads_the_aprilgrid_of_a_rig_camera(rig, tmp_path, capsys):
    from aicalib_tf.check import main

    root, _, rc = rig
    assert rc == 0
    code = main([str(root / "out" / "cam0" / "camera.json"), str(root / "left" / "*.png"), "--out",
                 str(tmp_path / "check.json"), "--workers", "1"])
    out = capsys.readouterr().out
    assert code == 0 and "the calibration HOLDS" in out, out
    assert json.loads((tmp_path / "check.json").read_text())["holds"] is True


def test_handeye_on_an_aprilgrid_set_recovers_both_transforms(tmp_path, capsys):
    from aicalib_tf.geometry.transform import inv, rotation_angle
    from aicalib_tf.handeye import main
    from data_gen.handeye import HandEyeSetConfig, write_handeye_set

    data = tmp_path / "set"
    write_handeye_set(HandEyeSetConfig(views=6, size=(400, 300), board=SPEC, seed=11, distance=(0.3, 0.5)), data)
    rc = main([str(data / "images" / "*.png"), "--poses", str(data / "poses.csv"), "--board", SPEC, "--setup",
               "eye-in-hand", "--out", str(tmp_path / "he"), "--model", "plumb_bob", "--workers", "1", "--quiet"])
    assert rc == 0, capsys.readouterr().out
    truth = json.loads((data / "truth.json").read_text())
    res = json.loads((tmp_path / "he" / "handeye.json").read_text())
    assert len(res["views"]) == 6
    for name in ("T_flange_camera", "T_base_board"):  # the board's frame: the detector's ids match data_gen's corners
        X, Xe = np.array(truth[name]), np.array(res[name]["matrix"])
        assert math.degrees(rotation_angle((inv(X) @ Xe)[:3, :3])) < 0.1, name
        assert 1e3 * np.linalg.norm(X[:3, 3] - Xe[:3, 3]) < 1.0, name
