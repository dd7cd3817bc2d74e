"""Rig files: OpenCV's stereo YAML nodes, camera_info with the rectification, rig.json round trip."""

import json

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from aicalib_tf.calib.rig.fit import calibrate_rig
from aicalib_tf.calib.rig.files import load_rig, load_stereo_yml, save_rig
from aicalib_tf.calib.rig.quality import assess_rig, pair_rectification
from aicalib_tf.geometry.rectify import essential_matrix
from tests.calib.rig.synthetic import PATTERN, SQUARE, fisheye, pinhole, rig_pose, rig_views

SIZE = (800, 600)


@pytest.fixture(scope="module")
def rigs():
    R1, T1 = rig_pose()
    R2 = Rotation.from_euler("y", -5, degrees=True).as_matrix()
    lenses, Rs, Ts = [pinhole(), fisheye(), pinhole(f=500)], [np.eye(3), R1, R2], [np.zeros(3), T1, -R2 @ [0.3, 0, 0]]
    v2 = rig_views(lenses[:2], Rs[:2], Ts[:2], n=10, noise=0.05, seed=11)
    v3 = rig_views(lenses, Rs, Ts, n=12, noise=0.05, seed=12)
    two = assess_rig(calibrate_rig(v2, PATTERN, SQUARE, SIZE, models=["plumb_bob", "equidistant"], square_unit="m"), v2)
    three = assess_rig(calibrate_rig(v3, PATTERN, SQUARE, SIZE, models=["plumb_bob", "equidistant", "plumb_bob"]), v3)
    return two, three


def test_two_camera_files_have_opencvs_nodes(rigs, tmp_path):
    rig = rigs[0]
    save_rig(rig, tmp_path)
    assert not list(tmp_path.rglob("*.tmp*"))
    fs = cv2.FileStorage(str(tmp_path / "intrinsics.yml"), cv2.FILE_STORAGE_READ)
    np.testing.assert_allclose(fs.getNode("M1").mat(), rig.cameras[0].K)
    np.testing.assert_allclose(fs.getNode("D2").mat().ravel(), rig.cameras[1].dist)
    assert fs.getNode("distortion_model1").string() == "plumb_bob"
    assert fs.getNode("distortion_model2").string() == "equidistant"
    fs.release()
    y = load_stereo_yml(tmp_path)
    rect = pair_rectification(rig.lenses, rig.R, rig.T)
    np.testing.assert_allclose(y["R"], rig.R[1])
    np.testing.assert_allclose(y["T"].ravel(), rig.T[1])
    for key in ("R1", "R2", "P1", "P2", "Q"):
        np.testing.assert_allclose(y[key], getattr(rect, key))
    np.testing.assert_allclose(y["E"], essential_matrix(rig.R[1], rig.T[1]))
    assert y["F"].shape == (3, 3)


def test_camera_info_carries_the_rectification(rigs, tmp_path):
    rig = rigs[0]
    save_rig(rig, tmp_path)
    rect = pair_rectification(rig.lenses, rig.R, rig.T)
    text = (tmp_path / "cam1_camera_info.yaml").read_text()
    assert "camera_name: cam1" in text and "distortion_model: equidistant" in text
    data = {}
    for block in text.split("\n"):
        if block.strip().startswith("data:"):
            data.setdefault("rows", []).append(np.array(json.loads(block.split(":", 1)[1])))
    K, D, R, P = data["rows"]
    np.testing.assert_allclose(R.reshape(3, 3), rect.R2)
    np.testing.assert_allclose(P.reshape(3, 4), rect.P2)
    assert (tmp_path / "cam0" / "camera.yaml").is_file() and (tmp_path / "cam1" / "camera.json").is_file()


def test_rig_json_round_trips_exactly(rigs, tmp_path):
    for rig in rigs:
        save_rig(rig, tmp_path / str(len(rig.names)))
        back = load_rig(tmp_path / str(len(rig.names)))
        assert back.names == rig.names and back.frames == rig.frames and back.rejected == rig.rejected
        np.testing.assert_array_equal(back.R, rig.R)
        np.testing.assert_array_equal(back.T, rig.T)
        np.testing.assert_array_equal(back.pose_covariance, rig.pose_covariance)
        for a, b in zip(back.cameras, rig.cameras):
            np.testing.assert_array_equal(a.K, b.K)
            np.testing.assert_array_equal(a.dist, b.dist)
            assert a.model == b.model and a.views == b.views
        assert back.quality["verdict"] == rig.quality["verdict"] and back.square_unit == rig.square_unit


def test_three_cameras_write_one_folder_per_pair(rigs, tmp_path):
    rig = rigs[1]
    save_rig(rig, tmp_path)
    for pair in ("cam0_cam1", "cam0_cam2"):
        y = load_stereo_yml(tmp_path / pair)
        k = int(pair[-1])
        np.testing.assert_allclose(y["T"].ravel(), rig.T[k])
        assert (tmp_path / pair / f"cam{k}_camera_info.yaml").is_file()
    assert not (tmp_path / "intrinsics.yml").exists()


def test_bad_rig_files_name_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="rig.json"):
        load_rig(tmp_path)
    (tmp_path / "rig.json").write_text("{}")
    with pytest.raises(ValueError, match="rig.json: field names is missing"):
        load_rig(tmp_path)
    with pytest.raises(FileNotFoundError, match="intrinsics.yml"):
        load_stereo_yml(tmp_path)
