"""calib.files: every lens model round-trips through camera.json, camera.yaml and camera_info.yaml; undistort."""

from __future__ import annotations

import dataclasses
import json
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from aicalib_tf.calib import files as F
from aicalib_tf.calib.fit import Calibration
from aicalib_tf.calib.quality import lens_of
from aicalib_tf.geometry import lens as L

SIZE = (640, 480)
DIST = {"plumb_bob": [-0.2, 0.05, 0.001, -0.002, 0.01],
        "rational_polynomial": [-0.2, 0.05, 0.001, -0.002, 0.01, 0.02, -0.01, 0.003],
        "thin_prism": [-0.2, 0.05, 0.001, -0.002, 0.01, 0.02, -0.01, 0.003, 1e-4, -2e-4, 3e-4, 1e-5],
        "equidistant": [0.05, -0.01, 0.002, -0.0003], "ds": [-0.2, 0.6], "eucm": [0.62, 1.1],
        "splined_equidistant": [0.05, -0.01, 0.002, -0.0003] + (0.01 * np.cos(0.3 * np.arange(200))).tolist()}
HAS_MODEL = "model" in {f.name for f in dataclasses.fields(Calibration)}


def _cal(model: str) -> Calibration:
    n = 4 + len(DIST[model])
    extra = {}
    if HAS_MODEL:
        extra = {"model": model, "covariance": np.diag(np.arange(1.0, n + 1)) * 1e-3,
                 "model_table": ({"model": model, "n_params": n, "rms": 0.1, "cv_rms": 0.12, "cv_se": 0.01,
                                  "chosen": True, "note": ""},),
                 "quality": {"verdict": "good to 0.1 px (1σ) over 80% of the image"}}
    elif model not in ("plumb_bob", "rational_polynomial"):
        pytest.skip(f"this build's Calibration cannot hold a {model} lens (no model field yet)")
    f = 300.0 if L.get_model(model).IS_FISHEYE else 520.0
    return Calibration(K=np.array([[f, 0, 321.5], [0, f * 1.01, 238.25], [0, 0, 1]]), dist=np.array(DIST[model]),
                       image_size=SIZE, pattern_size=(9, 6), square_size=25.0, rms=0.123456789012,
                       views=("a.png", "b.png"), rvecs=np.array([[0.1, -0.2, 0.3], [0.0, 0.1, -0.05]]),
                       tvecs=np.array([[10.0, 20.0, 500.0], [-30.0, 5.0, 700.0]]),
                       per_view_rms=np.array([0.1, 0.15]), corner_counts=np.array([54, 40]),
                       std={"fx": 0.5}, square_unit="mm", meta={"detector": "test"}, **extra)


@pytest.mark.parametrize("model", L.MODELS)
def test_round_trip_every_model(tmp_path, model):
    cal = _cal(model)
    F.save_calibration(cal, tmp_path)
    back = F.load_calibration(tmp_path)
    assert lens_of(back) == lens_of(cal) and lens_of(back).model == model
    np.testing.assert_array_equal(back.K, cal.K)
    np.testing.assert_array_equal(back.dist, cal.dist)
    np.testing.assert_array_equal(back.rvecs, cal.rvecs)
    assert back.views == cal.views and back.rms == cal.rms and back.std == cal.std
    if HAS_MODEL:
        np.testing.assert_array_equal(back.covariance, cal.covariance)
        assert list(back.model_table) == list(cal.model_table) and back.quality == cal.quality
    data = json.loads((tmp_path / "camera.json").read_text())
    assert data["model"] == model and data["distortion_model"] == L.ROS_NAMES[model]
    # camera.yaml: OpenCV reads it, with the ROS model name; our loader gets the model back from it
    fs = cv2.FileStorage(str(tmp_path / "camera.yaml"), cv2.FILE_STORAGE_READ)
    assert fs.getNode("distortion_model").string() == L.ROS_NAMES[model]
    np.testing.assert_allclose(fs.getNode("camera_matrix").mat(), cal.K)
    assert fs.getNode("distortion_coefficients").mat().size == len(DIST[model])
    fs.release()
    from_yaml = F.load_calibration(tmp_path / "camera.yaml")
    assert lens_of(from_yaml).model == model
    np.testing.assert_allclose(from_yaml.dist, cal.dist, rtol=1e-12)
    info = (tmp_path / "camera_info.yaml").read_text()
    assert f"distortion_model: {L.ROS_NAMES[model]}\n" in info
    assert f"distortion_coefficients:\n  rows: 1\n  cols: {len(DIST[model])}\n" in info


def test_old_files_without_a_model_load_as_plumb_bob(tmp_path):
    cal = _cal("plumb_bob")
    data = json.loads(F.to_json(cal))
    for key in ("model", "distortion_model", "covariance", "model_table", "quality"):
        data.pop(key)
    (tmp_path / "camera.json").write_text(json.dumps(data))
    assert lens_of(F.load_calibration(tmp_path)).model == "plumb_bob"
    (tmp_path / "camera.json").write_text(json.dumps(dict(data, distortion_coefficients=[0.1, 0.2, 0.3])))
    with pytest.raises(ValueError, match="camera.json"):
        F.load_calibration(tmp_path)


def _curvature(pts: np.ndarray) -> float:
    """Largest distance (px) of points (N, 2) from their total-least-squares line."""
    c = pts - pts.mean(axis=0)
    normal = np.linalg.svd(c, full_matrices=False)[2][1]
    return float(np.max(np.abs(c @ normal)))


def _fisheye():
    """A stand-in calibration: undistort needs only the lens (works before Calibration has a model)."""
    return SimpleNamespace(model="equidistant", K=np.array([[300.0, 0, 321.5], [0, 303.0, 238.25], [0, 0, 1]]),
                           dist=np.array(DIST["equidistant"]), image_size=SIZE)


def test_undistort_equidistant_straightens_lines():
    cal = _fisheye()
    lens = lens_of(cal)
    line = np.stack([np.linspace(-1.2, 1.2, 4000), np.full(4000, -0.45), np.full(4000, 1.0)], axis=1)
    px = lens.project(line)
    px = px[np.all(np.isfinite(px), 1) & (px[:, 0] > 2) & (px[:, 0] < SIZE[0] - 3) & (px[:, 1] > 2)]
    assert _curvature(px) > 10.0  # the fisheye image of the line is curved
    img = np.zeros(SIZE[::-1], np.float32)
    img[np.round(px[:, 1]).astype(int), np.round(px[:, 0]).astype(int)] = 1.0
    out = F.undistort(cv2.GaussianBlur(img, (0, 0), 1.0), cal, alpha=0.5)
    assert out.shape == img.shape and out.dtype == img.dtype
    cols = np.flatnonzero(out.max(axis=0) > 0.05)
    rows = np.arange(SIZE[1], dtype=np.float64)
    ys = np.array([np.sum(rows * out[:, c]) / np.sum(out[:, c]) for c in cols])
    assert len(cols) > 200 and _curvature(np.stack([cols, ys], 1)) < 1.0


def test_undistort_camera_matrix_for_equidistant_and_errors():
    cal = _fisheye()
    K0, K1 = F.undistort_camera_matrix(cal, 0.0), F.undistort_camera_matrix(cal, 1.0)
    assert K0[0, 0] == pytest.approx(cal.K[0, 0]) and K1[0, 0] < K0[0, 0]
    half = np.degrees(np.arctan(((SIZE[0] - 1) / 2 + 0.5) / K1[0, 0]))
    assert half == pytest.approx(min(lens_of(cal).field_of_view()["horizontal"] / 2, 75.0), abs=0.2)
    with pytest.raises(ValueError, match="alpha"):
        F.undistort_camera_matrix(cal, 1.5)
    with pytest.raises(ValueError, match="640x480"):
        F.undistort(np.zeros((10, 10), np.uint8), cal)


def test_the_image_circle_round_trips_and_older_files_load_without_it(tmp_path):
    from aicalib_tf.geometry.image_circle import ImageCircle

    circle = ImageCircle(321.25, 238.5, 230.125)
    cal = dataclasses.replace(_cal("equidistant"), image_circle=circle)
    F.save_calibration(cal, tmp_path)
    data = json.loads((tmp_path / "camera.json").read_text())
    assert data["image_circle"] == {"cx": 321.25, "cy": 238.5, "radius": 230.125}
    assert F.load_calibration(tmp_path).image_circle == circle
    del data["image_circle"]  # a file written before the circle was kept
    (tmp_path / "camera.json").write_text(json.dumps(data))
    assert F.load_calibration(tmp_path).image_circle is None
    assert F.load_calibration(tmp_path / "camera.yaml").image_circle is None
    data["image_circle"] = {"cx": 1.0, "cy": 2.0, "radius": -3.0}
    (tmp_path / "camera.json").write_text(json.dumps(data))
    with pytest.raises(ValueError, match=r"camera.json.*image_circle.radius"):
        F.load_calibration(tmp_path)


def test_undistort_is_black_outside_the_image_circle():
    from aicalib_tf.geometry.image_circle import ImageCircle

    cal = dataclasses.replace(_cal("equidistant"), image_circle=ImageCircle(321.5, 238.25, 120.0))
    img = np.full((SIZE[1], SIZE[0]), 200, np.uint8)
    out = F.undistort(img, cal, alpha=1.0)
    plain = F.undistort(img, dataclasses.replace(cal, image_circle=None), alpha=1.0)
    assert (out == 0).sum() > (plain == 0).sum() and out[238, 321] == 200
