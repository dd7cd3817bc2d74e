"""python -m aicalib_tf.handeye end to end on a rendered set: files, truth recovered, swapped rows named,
bad input as one line and exit 2, --save-partial."""

import json
import math

import cv2
import numpy as np
import pytest

from aicalib_tf.geometry.transform import inv, rotation_angle
from aicalib_tf.handeye import main, parse_robot_sigma
from data_gen.handeye import HandEyeSetConfig, write_handeye_set


@pytest.fixture(scope="module")
def handeye_set(tmp_path_factory):
    out = tmp_path_factory.mktemp("handeye_set")
    write_handeye_set(HandEyeSetConfig(views=9, size=(640, 480), swap=2, seed=11), out)
    return out


def _run(capsys, data, out, *extra, poses=None):
    rc = main([str(data / "images" / "*.png"), "--poses", str(poses or data / "poses.csv"), "--pattern", "9x6",
               "--square", "40mm", "--setup", "eye-in-hand", "--out", str(out), "--detector", "opencv",
               "--model", "plumb_bob", "--workers", "1", "--quiet", *map(str, extra)])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def test_a_rendered_set_is_calibrated_and_its_swapped_rows_named(handeye_set, tmp_path, capsys):
    rc, out, err = _run(capsys, handeye_set, tmp_path / "he")
    assert rc == 0, err
    truth = json.loads((handeye_set / "truth.json").read_text())
    res = json.loads((tmp_path / "he" / "handeye.json").read_text())
    assert {r["image"] for r in res["rejected"]} == set(truth["swapped"])
    X, Xe = np.array(truth["T_flange_camera"]), np.array(res["T_flange_camera"]["matrix"])
    assert math.degrees(rotation_angle((inv(X) @ Xe)[:3, :3])) < 0.1
    assert 1e3 * np.linalg.norm(X[:3, 3] - Xe[:3, 3]) < 1.0
    assert np.array(res["T_flange_camera"]["covariance"]).shape == (6, 6) and len(res["views"]) == 7
    assert {"robot_residual_mm", "robot_residual_deg", "rms_px"} <= set(res["views"][0])
    line = (tmp_path / "he" / "static_transform.txt").read_text().splitlines()[1].split()
    assert line[:2] == ["flange", "camera"] and np.allclose([float(v) for v in line[2:5]], Xe[:3, 3], atol=1e-6)
    fs = cv2.FileStorage(str(tmp_path / "he" / "handeye.yaml"), cv2.FILE_STORAGE_READ)
    assert np.allclose(fs.getNode("T_flange_camera").mat(), Xe)
    assert (tmp_path / "he" / "report.png").stat().st_size > 10_000
    assert "T_flange_camera" in out and "verdict" in out


@pytest.mark.parametrize("rows, match", [
    ("image,x,y,z,qx,qy,qw\nview_00.png,0,0,0,0,0,1\n", "poses.csv: missing column"),
    ("image,x,y,z,qx,qy,qz,qw\nview_00.png,512,10,300,0,0,0,1\n", "poses.csv row 2 .*millimetres"),
    ("image,x,y,z,qx,qy,qz,qw\nview_00.png,0.5,0.1,0.3,0,0,0,1\nview_01.png,0.5,0.1,0.3,0,0,0,1\n",
     "only 2 of 9 images have a robot pose"),
])
def test_bad_poses_are_one_line_and_exit_2(handeye_set, tmp_path, capsys, rows, match):
    poses = tmp_path / "poses.csv"
    poses.write_text(rows)
    rc, _, err = _run(capsys, handeye_set, tmp_path / "he", poses=poses)
    lines = [ln for ln in err.splitlines() if ln.startswith("error")]
    assert rc == 2 and len(lines) == 1 and __import__("re").search(match, lines[0]), err
    assert not (tmp_path / "he").exists()


def test_rotations_about_one_axis_fail_and_save_partial_writes_the_failure(handeye_set, tmp_path, capsys):
    rows = ["image,x,y,z,qx,qy,qz,qw"] + [f"view_{k:02d}.png,{0.4 + 0.01 * k},0.1,0.3,0,0,{math.sin(0.2 * k):.9f},"
                                          f"{math.cos(0.2 * k):.9f}" for k in range(9)]
    (tmp_path / "poses.csv").write_text("\n".join(rows) + "\n")
    rc, _, err = _run(capsys, handeye_set, tmp_path / "he", poses=tmp_path / "poses.csv")
    assert rc == 2 and "one axis" in err and not (tmp_path / "he").exists()
    rc, _, err = _run(capsys, handeye_set, tmp_path / "he", "--save-partial", poses=tmp_path / "poses.csv")
    res = json.loads((tmp_path / "he" / "handeye.json").read_text())
    assert rc == 2 and res["status"] == "failed" and "one axis" in res["error"]


def test_robot_sigma_is_parsed_with_units():
    assert parse_robot_sigma("0.01deg,0.05mm") == (0.01, 0.05)
    assert np.allclose(parse_robot_sigma("0.001rad,0.1m"), (0.0572957795, 100.0))
    with pytest.raises(ValueError, match="robot-sigma"):
        parse_robot_sigma("fast")


def test_known_intrinsics_are_held(handeye_set, tmp_path, capsys):
    from aicalib_tf.calib.fit import View, calibrate_camera
    from aicalib_tf.calib.files import save_calibration
    from aicalib_tf.geometry.pattern import pattern_ids
    from data_gen.handeye import sample_handeye

    s = sample_handeye(HandEyeSetConfig(views=9, size=(640, 480), swap=2, seed=11))  # the fixture's truth
    obj, ids = s.board.object_points() * 1e-3, pattern_ids((9, 6))
    views = [View(f"v{k}", s.camera.lens.project(obj @ C[:3, :3].T + C[:3, 3]), ids) for k, C in enumerate(s.C)]
    save_calibration(calibrate_camera(views, (9, 6), 0.04, (640, 480), model="plumb_bob"), tmp_path / "cam")
    rc, out, err = _run(capsys, handeye_set, tmp_path / "he", "--intrinsics", tmp_path / "cam" / "camera.json")
    res = json.loads((tmp_path / "he" / "handeye.json").read_text())
    assert rc == 0, err
    assert res["camera"]["fitted"] is False and np.allclose(res["camera"]["K"], s.camera.K, atol=1e-3)
    assert "held fixed" in out
