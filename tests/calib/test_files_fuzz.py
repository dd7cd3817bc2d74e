"""calib.files / calib.rig.files on hostile input: every bad file is a ValueError naming the file, never a crash.

Random bytes, truncations, deep nesting and mutated fields go to ``load_calibration``,
``load_rig`` and ``load_stereo_yml``: each must return a valid calibration or raise
ValueError / FileNotFoundError naming the file. Regression tests pin what a fuzzing campaign found:
a segfault inside cv2.FileStorage, SystemError tracebacks, NaN in the JSON, values accepted out of range.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from aicalib_tf.calib import files as F
from aicalib_tf.calib.fit import calibrate_camera
from aicalib_tf.calib.rig.files import load_rig, load_stereo_yml, save_rig
from aicalib_tf.calib.rig.result import RigCalibration
from aicalib_tf.geometry.lens import Lens
from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views
from tests.calib.test_files import _cal

ROOT = Path(__file__).resolve().parents[2]
FUZZ = settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def _strict(text: str):
    """A browser's JSON.parse: NaN and Infinity are not JSON."""
    def refuse(name):
        raise AssertionError(f"{name} in JSON")
    return json.loads(text, parse_constant=refuse)


def _rig() -> RigCalibration:
    cams = (_cal("plumb_bob"), _cal("equidistant"))
    R1 = Rotation.from_euler("y", -3, degrees=True).as_matrix()
    return RigCalibration(names=("cam0", "cam1"), cameras=cams, R=np.stack([np.eye(3), R1]),
                          T=np.array([[0.0, 0, 0], [-120.0, 0.5, 1.0]]), pose_covariance=np.zeros((2, 6, 6)),
                          frames=("f0", "f1"), frame_rms=np.array([0.1, math.nan]), frame_cameras=((0, 1), (0, 1)),
                          rms=0.12, pattern_size=(9, 6), square_size=25.0, square_unit="mm",
                          quality={"in_sample_rms_px": math.nan, "verdict": "ok"})


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """A calibration folder (camera.yaml, camera.json, camera_info.yaml) and a rig folder (rig/)."""
    out = tmp_path_factory.mktemp("cal")
    F.save_calibration(_cal("rational_polynomial"), out)
    save_rig(_rig(), out / "rig")
    return out


def _load_any(path: Path, loader):
    """Run a loader; any exception but ValueError/FileNotFoundError naming ``path`` fails the test."""
    try:
        return loader(path)
    except (ValueError, FileNotFoundError) as exc:
        assert str(path.name) in str(exc), exc
        assert "\n" not in str(exc), exc
        return None


LOADERS = {"camera.yaml": F.load_calibration, "camera.json": F.load_calibration, "rig.json": load_rig}


# --- fuzzing --------------------------------------------------------------------------------------

@FUZZ
@given(data=st.binary(max_size=600), name=st.sampled_from(["camera.yaml", "camera.json", "rig.json"]))
def test_random_bytes_are_refused_cleanly(tmp_path, data, name):
    (tmp_path / name).write_bytes(data)
    _load_any(tmp_path / name, LOADERS[name])


@FUZZ
@given(name=st.sampled_from(["camera.yaml", "camera.json", "rig/rig.json", "rig/intrinsics.yml",
                             "rig/extrinsics.yml"]), cut=st.floats(0, 1), data=st.data())
def test_truncated_and_mutated_files_are_refused_cleanly(folder, tmp_path, name, cut, data):
    text = (folder / name).read_text()
    keep = text[: int(len(text) * cut)]
    if data.draw(st.booleans()):  # mutate a few characters instead of truncating
        chars = list(text)
        for _ in range(data.draw(st.integers(1, 5))):
            k = data.draw(st.integers(0, len(chars) - 1))
            chars[k] = data.draw(st.sampled_from(list("[]{}:,-\"' \n.0123456789eNaIf#!x\x00")))
        keep = "".join(chars)
    target = tmp_path / Path(name).name
    if name.startswith("rig/") and name.endswith(".yml"):
        for other in ("intrinsics.yml", "extrinsics.yml"):
            (tmp_path / other).write_text((folder / "rig" / other).read_text())
        target.write_text(keep)
        _load_any(target, lambda p: load_stereo_yml(p.parent))
        return
    target.write_text(keep)
    _load_any(target, load_rig if name.endswith("rig.json") else F.load_calibration)


_NUMBERS = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**30, 10**30),
                     st.just(None), st.text(max_size=3), st.lists(st.integers(-3, 3), max_size=4), st.booleans())


def _paths(value, prefix=()):
    """Every (path of keys/indices) of a JSON value's leaves and containers."""
    yield prefix
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(value, list):
        for k, v in enumerate(value):
            yield from _paths(v, prefix + (k,))


def _set(value, path, new):
    for key in path[:-1]:
        value = value[key]
    value[path[-1]] = new


@FUZZ
@given(name=st.sampled_from(["camera.json", "rig/rig.json"]), data=st.data(), new=_NUMBERS)
def test_mutated_json_fields_are_refused_or_valid(folder, tmp_path, name, data, new):
    doc = json.loads((folder / name).read_text())
    path = data.draw(st.sampled_from([p for p in _paths(doc) if p]))
    _set(doc, path, new)
    target = tmp_path / Path(name).name
    target.write_text(json.dumps(doc))  # Python's json writes NaN for a float nan: the loader must refuse it
    loaded = _load_any(target, load_rig if name.endswith("rig.json") else F.load_calibration)
    cams = () if loaded is None else getattr(loaded, "cameras", (loaded,))
    for cal in cams:  # whatever loads is a usable camera
        assert isinstance(cal.lens, Lens) and np.all(np.isfinite(cal.rvecs)) and cal.square_size > 0


# --- regressions ----------------------------------------------------------------------------------

def test_deep_or_binary_yaml_is_refused_without_a_crash_or_a_hang(tmp_path):
    """A 100 KB YAML nested 50,000 deep crashed the process inside cv2.FileStorage (SIGSEGV), and a
    ``!!binary`` value inside a matrix's data sent it into an endless loop."""
    deep = tmp_path / "camera.yaml"
    deep.write_text("%YAML:1.0\n---\ncamera_matrix: " + "[" * 50_000 + "]" * 50_000 + "\n")
    dash = tmp_path / "x" / "intrinsics.yml"
    dash.parent.mkdir()
    dash.write_text("%YAML:1.0\n---\nM1:\n  " + "- " * 50_000 + "1\n")
    (dash.parent / "extrinsics.yml").write_text("%YAML:1.0\n---\nR: 1\n")
    binary = tmp_path / "b" / "camera.yaml"
    binary.parent.mkdir()
    binary.write_text("M1: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
                      "   data: [ 520., 0., !!binary 0., 525.20000000000005, 238.25, 0., 0., 1. ]\n")
    code = ("import sys\nfrom aicalib_tf.calib.files import load_calibration\n"
            "from aicalib_tf.calib.rig.files import load_stereo_yml\n"
            "for f, arg in ((load_calibration, sys.argv[1]), (load_stereo_yml, sys.argv[2]), (load_calibration, sys.argv[3])):\n"
            "    try:\n        f(arg)\n    except ValueError as e:\n        print(e)\n")
    out = subprocess.run([sys.executable, "-c", code, str(deep), str(dash.parent), str(binary)], capture_output=True,
                         text=True, cwd=ROOT, timeout=60)
    assert out.returncode == 0, (out.returncode, out.stderr[-500:])  # -11 would be the segfault
    lines = out.stdout.splitlines()
    assert len(lines) == 3 and "camera.yaml: nested more than 64" in lines[0], lines
    assert "intrinsics.yml: nested more than 64" in lines[1] and "holds the YAML tag '!!binary'" in lines[2], lines


@pytest.mark.parametrize("text", ["", "\n\n", "garbage: [ : }", "%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n"
                                  "   rows: 3\n   cols: 3\n   dt: d\n   data: [ 1., 2."])
@pytest.mark.parametrize("name", ["camera.yaml", "intrinsics.yml", "extrinsics.yml"])
def test_empty_truncated_or_garbage_yaml_is_a_value_error(folder, tmp_path, text, name):
    """cv2.FileStorage raised SystemError ("returned a result with an exception set") on these."""
    for other in ("intrinsics.yml", "extrinsics.yml"):
        (tmp_path / other).write_text((folder / "rig" / other).read_text())
    (tmp_path / name).write_text(text)
    with pytest.raises(ValueError, match=f"{name}: (empty file|not an OpenCV YAML file)"):
        load_stereo_yml(tmp_path) if name.endswith(".yml") else F.load_calibration(tmp_path / name)


@pytest.mark.parametrize("old, new, message", [
    ("image_width: 640", "image_width: 1e20", "field image_width must be an integer in \\[1, 100000\\]"),
    ("image_width: 640", "image_width: 1e400", "field image_width must be an integer"),
    ("image_height: 480", "image_height: abc", "field image_height must be an integer"),
    ("square_size: 25.", "square_size: 0.", "field square_size must be a positive finite number, got 0.0"),
    ("square_size: 25.", "square_size: -25.", "field square_size must be a positive finite number, got -25.0"),
    ("board_width: 9", "board_width: 0", "field board_width must be an integer in \\[2, "),
    ("dt: d", "dt: u", "field camera_matrix has dt 'u', which cannot hold its values"),
    ("dt: d", "dt: s", "field camera_matrix has dt 's', which cannot hold its values"),
    ("rows: 3", "rows: 300000000", "field camera_matrix has 9 values for 300000000x3"),
    ("distortion_model: rational_polynomial", "distortion_model: plumb_bob\nx: 1", None),
    ("distortion_model: rational_polynomial", "distortion_model: nonsense", "field distortion_model does not name"),
    ("10., 20., 500.", ".Nan, 20., 500.", "field extrinsic_parameters must be finite"),
    ("avg_reprojection_error: 0.123456789012", "avg_reprojection_error: .Nan",
     "field avg_reprojection_error must be a finite number >= 0, got nan"),
])
def test_camera_yaml_fields_are_checked(folder, tmp_path, old, new, message):
    text = (folder / "camera.yaml").read_text()
    assert old in text
    (tmp_path / "camera.yaml").write_text(text.replace(old, new, 1))
    if message is None:  # rational_polynomial's 8 coefficients under plumb_bob: the extras are non-zero
        message = "field distortion_coefficients does not fit the lens model"
    with pytest.raises(ValueError, match=f"camera.yaml: {message}"):
        F.load_calibration(tmp_path / "camera.yaml")


def test_integer_matrices_are_read_exactly_or_refused(folder, tmp_path):
    text = (folder / "camera.yaml").read_text()
    K = "camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: {}\n   data: [ 500, 0, 320, 0, 500, 240, 0, 0, 1 ]"
    start = text.index("camera_matrix:")
    end = text.index("distortion_model:")
    for dt, ok in (("i", True), ("w", True), ("u", False)):
        (tmp_path / "camera.yaml").write_text(text[:start] + K.format(dt) + "\n" + text[end:])
        if ok:
            assert F.load_calibration(tmp_path / "camera.yaml").K[0, 2] == 320.0
        else:  # OpenCV would clamp fx = 500 to 255
            with pytest.raises(ValueError, match="dt 'u'"):
                F.load_calibration(tmp_path / "camera.yaml")


@pytest.mark.parametrize("path, value, message", [
    (("board", "square_size"), -25, "field board.square_size must be a positive finite number, got -25"),
    (("board", "square_size"), 0, "field board.square_size must be a positive finite number"),
    (("board", "pattern_size"), [0, 0], "field board.pattern_size must be \\[cols, rows\\]"),
    (("image_width",), 1e20, "field image_width must be an integer in \\[1, 100000\\], got 1e\\+20"),
    (("views", 0, "rvec"), [None, 0, 0], "field views\\[0\\].rvec must be"),
    (("views", 0, "tvec"), [1, 2], "field views\\[0\\].tvec must be a 3 matrix"),
    (("covariance",), [[1, 0], [0, 1]], "field covariance must be a 12x12 matrix, got shape \\(2, 2\\)"),
    (("camera_matrix", 2), [0, 0, 2], "field camera_matrix must be \\[\\[fx, 0, cx\\]"),
    (("camera_matrix", 0, 0), -5, "field camera_matrix must have focal lengths fx, fy > 0"),
    (("distortion_coefficients",), [0.1, 0.2], "field distortion_coefficients does not fit"),
    (("model",), "pinhole", "field model must be one of"),
    (("views",), {"a": 1}, "field views must be a list"),
    (("board",), [9, 6], "field board must be an object"),
    (("covariance", 3, 3), None, "field covariance must be a 12x12 matrix of numbers"),
    (("rejected",), {"a.png": 3}, "field rejected.a.png must be a string"),
    (("std", "fx"), "big", "field std.fx must be a finite number or null"),
    (("model_table", 0, "cv_rms"), "x", "field model_table\\[0\\].cv_rms must be a finite number or null"),
])
def test_camera_json_fields_are_checked(folder, tmp_path, path, value, message):
    doc = json.loads((folder / "camera.json").read_text())
    _set(doc, path, value)
    (tmp_path / "camera.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=f"camera.json: {message}"):
        F.load_calibration(tmp_path)


@pytest.mark.parametrize("text", ["[]", '"camera"', "3", "null"])
def test_json_that_is_not_an_object_is_refused(tmp_path, text):
    for name, loader in (("camera.json", F.load_calibration), ("rig.json", load_rig)):
        (tmp_path / name).write_text(text)
        with pytest.raises(ValueError, match=f"{name}: not a valid aicalib_tf .* file \\(expected a JSON object"):
            loader(tmp_path / name)


@pytest.mark.parametrize("path, value, message", [
    (("names",), [], "field names must be a list of at least 1 items"),
    (("R", 1, 0, 0), math.nan, "not valid JSON \\(NaN is not a JSON number"),
    (("R", 1, 0, 0), None, "field R must be a 2x3x3 matrix of numbers"),
    (("R", 1), [[1, 0, 0], [0, 1, 0], [0, 0, -1]], "field R must be a rotation"),
    (("T",), [[0, 0, 0]], "field T must be a 2x3 matrix"),
    (("cameras", 1, "board", "square_size"), -25, "field cameras\\[1\\].board.square_size must be a positive"),
    (("frame_cameras", 0, 1), 7, "field frame_cameras\\[0\\] must be an integer in \\[0, 1\\]"),
    (("board", "pattern_size"), [9], "field board.pattern_size must be \\[cols, rows\\]"),
])
def test_rig_json_fields_are_checked(folder, tmp_path, path, value, message):
    doc = json.loads((folder / "rig" / "rig.json").read_text())
    _set(doc, path, value)
    (tmp_path / "rig.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=f"rig.json: {message}"):
        load_rig(tmp_path)


@pytest.mark.parametrize("name, old, new, message", [
    ("extrinsics.yml", "R: !!opencv-matrix\n   rows: 3", "R: !!opencv-matrix\n   rows: 1", "field R has 9 values for 1x3"),
    ("intrinsics.yml", "distortion_model2: equidistant", "distortion_model2: thin_prism",
     "field distortion_model2 does not name a lens model with 4 coefficients"),
    ("intrinsics.yml", "M1: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 520.",
     "M1: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ -520.", "field M1 must have focal lengths"),
])
def test_stereo_yml_nodes_are_checked(folder, tmp_path, name, old, new, message):
    for other in ("intrinsics.yml", "extrinsics.yml"):
        text = (folder / "rig" / other).read_text()
        if other == name:
            assert old in text, text[:400]
            text = text.replace(old, new, 1)
        (tmp_path / other).write_text(text)
    with pytest.raises(ValueError, match=f"{name}: {message}"):
        load_stereo_yml(tmp_path)


def test_stereo_yml_with_nan_in_R_is_refused(folder, tmp_path):
    for other in ("intrinsics.yml", "extrinsics.yml"):
        (tmp_path / other).write_text((folder / "rig" / other).read_text())
    text = (tmp_path / "extrinsics.yml").read_text()
    head, tail = text.split("R: !!opencv-matrix", 1)
    tail = re.sub(r"data: \[ [^,]+,", "data: [ .Nan,", tail, count=1)
    (tmp_path / "extrinsics.yml").write_text(head + "R: !!opencv-matrix" + tail)
    with pytest.raises(ValueError, match="extrinsics.yml: field R must be finite"):
        load_stereo_yml(tmp_path)


def test_forced_model_camera_json_is_strict_json_and_round_trips(tmp_path):
    """A forced model's table row has cv_rms = cv_se = NaN: camera.json held bare NaN (not JSON)."""
    lens = Lens("plumb_bob", [[600.0, 0, 399.5], [0, 600.0, 299.5], [0, 0, 1]], [-0.1, 0.01, 0, 0, 0], (800, 600))
    cal = calibrate_camera(synthetic_views(lens, n=6, noise=0.05, seed=3), PATTERN, SQUARE, (800, 600), model="plumb_bob")
    assert math.isnan(cal.model_table[0]["cv_rms"])
    F.save_calibration(cal, tmp_path)
    doc = _strict((tmp_path / "camera.json").read_text())
    assert doc["model_table"][0]["cv_rms"] is None and doc["model_table"][0]["cv_se"] is None
    back = F.load_calibration(tmp_path)
    assert math.isnan(back.model_table[0]["cv_rms"]) and back.model_table[0]["note"] == "forced"
    np.testing.assert_array_equal(back.K, cal.K)
    assert F.to_json(back) == F.to_json(cal)


def test_rig_json_is_strict_json_and_round_trips(folder):
    text = (folder / "rig" / "rig.json").read_text()
    doc = _strict(text)
    assert doc["frame_rms"][1] is None and doc["quality"]["in_sample_rms_px"] is None
    back = load_rig(folder / "rig")
    assert math.isnan(back.frame_rms[1]) and math.isnan(back.quality["in_sample_rms_px"]) and back.frame_cameras == ((0, 1), (0, 1)) and back.names == ("cam0", "cam1")
    np.testing.assert_array_equal(back.R, _rig().R)
    for name in ("cam0", "cam1"):
        _strict((folder / "rig" / name / "camera.json").read_text())


def test_a_ros_camera_info_file_is_named_as_such(folder):
    with pytest.raises(ValueError, match="camera_info.yaml: a ROS camera_info file holds no board"):
        F.load_calibration(folder / "camera_info.yaml")


def test_oversized_and_binary_files_are_refused(tmp_path, monkeypatch):
    from aicalib_tf import jsonio
    (tmp_path / "camera.json").write_bytes(b"\x00\x01")
    with pytest.raises(ValueError, match="camera.json: holds NUL bytes"):
        F.load_calibration(tmp_path)
    (tmp_path / "camera.json").write_bytes(b"\xff\xfe{}")
    with pytest.raises(ValueError, match="camera.json: not UTF-8"):
        F.load_calibration(tmp_path)
    monkeypatch.setattr(jsonio, "MAX_FILE_BYTES", 10)
    (tmp_path / "camera.json").write_text("{" + " " * 20 + "}")
    with pytest.raises(ValueError, match="camera.json: file is larger than"):
        F.load_calibration(tmp_path)
