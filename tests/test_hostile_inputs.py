"""Regression tests of the third hostile-input campaign (benchmarks/hostile_inputs.py): each case
keeps the property (exit 0, 1 or 2; one error line naming the file or field; no traceback; a
complete set of output files or none)."""

from __future__ import annotations

import dataclasses
import json

import cv2
import numpy as np
import pytest

from aicalib_tf import board, compare
from aicalib_tf.calib.files import save_calibration, undistort_camera_matrix
from aicalib_tf.calib.fit import fit_views
from aicalib_tf.detect.opencv import opencv_classic
from aicalib_tf.geometry import lens as L
from aicalib_tf.geometry.lens_registry import get_model
from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views

SIZE = (640, 480)
LENS = L.Lens("plumb_bob", [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]], [-0.25, 0.08, 0.001, -0.0005, 0.0], SIZE)
NARROW_SPLINE = "splined_equidistant_nx=8_ny=6_fov=120_smooth=1"  # a spline of a lens under 180°: not IS_FISHEYE


@pytest.fixture(scope="module")
def cal():
    return fit_views(synthetic_views(LENS, 6, 0.2, seed=3), PATTERN, SQUARE, SIZE, "plumb_bob")


def _one_error(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "bug in aicalib_tf" not in err[0], err
    return err[0]


def test_a_spline_of_a_narrow_lens_is_saved_with_its_maps(cal, tmp_path):
    """OpenCV holds no spline: its undistorted camera matrix cannot come from getOptimalNewCameraMatrix."""
    spec = get_model(NARROW_SPLINE)
    assert not spec.IS_FISHEYE
    spline = dataclasses.replace(cal, model=NARROW_SPLINE, dist=np.zeros(spec.n_coeffs))
    K = undistort_camera_matrix(spline)
    assert np.all(np.isfinite(K)) and abs(K[0, 0] - cal.K[0, 0]) < 1e-6
    save_calibration(spline, tmp_path)
    assert {"camera.json", "undistort_map_x.npy", "undistort_map_y.npy"} <= {p.name for p in tmp_path.iterdir()}


@pytest.mark.parametrize("value", [1e308, -1e7])
def test_an_absurd_distortion_coefficient_is_refused_naming_the_field(cal, tmp_path, capsys, value):
    for name in ("a", "b"):
        save_calibration(cal, tmp_path / name)
    doc = json.loads((tmp_path / "b" / "camera.json").read_text())
    doc["distortion_coefficients"][0] = value
    (tmp_path / "b" / "camera.json").write_text(json.dumps(doc))
    (tmp_path / "b" / "camera.yaml").unlink()
    png = tmp_path / "d.png"
    assert compare.main([str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(png)]) == 2
    line = _one_error(capsys)
    assert "camera.json: field distortion_coefficients" in line and "not a lens coefficient" in line
    assert not png.exists()


@pytest.mark.parametrize("spec, words", [
    ("circles:4x11,spacing=20mm,asymmetric,symmetric", "both symmetric and asymmetric"),
    ("circles:4x11,spacing=20mm,spacing=40mm,symmetric", "unexpected 'spacing=40mm'"),
    ("circles:4x11,spacing=1e308mm,symmetric", "under 1e6"),
    ("aprilgrid:6x6,tag=1e308mm,spacing=0.3", "under 1e6"),
])
def test_contradictory_or_huge_board_fields_are_one_line(spec, words, tmp_path, capsys):
    out = tmp_path / "b.png"
    assert board.main([spec, "--out", str(out)]) == 2
    assert words in _one_error(capsys)
    assert not out.exists()


@pytest.mark.parametrize("shape", [(1, 640), (480, 1), (2, 2), (14, 14)])
def test_opencv_classic_finds_nothing_in_a_sliver_of_an_image(shape):
    img = np.full(shape, 128, np.uint8)
    assert opencv_classic(img, (9, 6)) == (False, None)


def test_calibrate_with_opencv_counts_a_1xn_photo_as_no_board(tmp_path, capsys):
    from aicalib_tf import calibrate

    photo = tmp_path / "row.png"
    cv2.imwrite(str(photo), np.full((1, 640), 200, np.uint8))
    out = tmp_path / "cal"
    assert calibrate.main([str(photo), "--pattern", "9x6", "--detector", "opencv", "--out", str(out), "--quiet",
                           "--workers", "1"]) == 2
    assert "no 9x6 board found" in _one_error(capsys)
    assert not out.exists()


@pytest.fixture(scope="module")
def two_cals(cal, tmp_path_factory):
    root = tmp_path_factory.mktemp("two")
    for name in ("a", "b"):
        save_calibration(cal, root / name)
    return root


@pytest.mark.parametrize("out, js, words", [
    ("d.png", ".", "--json {root}: is a folder"),
    (".", "d.json", "--out {root}: is a folder"),
    ("d.png", "a/camera.json", "is a file of a compared calibration"),
    ("b/camera.yaml", "d.json", "is a file of a compared calibration"),
    ("same", "same", "--out and --json name the same file"),
])
def test_compare_refuses_outputs_that_are_folders_or_its_inputs_before_writing(two_cals, capsys, out, js, words):
    before = {p: p.read_bytes() for p in two_cals.rglob("*") if p.is_file()}
    argv = [str(two_cals / "a"), str(two_cals / "b"), "--out", str(two_cals / out), "--json", str(two_cals / js)]
    assert compare.main(argv) == 2
    assert words.format(root=two_cals) in _one_error(capsys)
    assert {p: p.read_bytes() for p in two_cals.rglob("*") if p.is_file()} == before  # nothing written or replaced


@pytest.mark.parametrize("text", ["1e308deg,1mm", "1e400deg,1mm", "0.01deg,5m", "2rad,1mm"])
def test_an_absurd_robot_sigma_is_refused(text):
    from aicalib_tf.handeye import parse_robot_sigma

    with pytest.raises(ValueError, match="--robot-sigma must be under 90deg,1m"):
        parse_robot_sigma(text)


@pytest.mark.parametrize("text", [
    "%YAML:1.0\n---\nposes: " + "[" * 1000 + "]" * 1000 + "\n",  # was a RecursionError ("a bug in aicalib_tf")
    "%YAML:1.0\n---\nposes: " + "[" * 100000 + "]" * 100000 + "\n",  # was a segmentation fault in OpenCV's parser
    "%YAML:1.0\n---\n" + "".join("  " * i + f"k{i}:\n" for i in range(3000)),
    "%YAML:1.0\n---\nposes: !!binary |\n  AAAA\n",
])
def test_a_deep_or_tagged_poses_yaml_is_one_line_naming_the_file(text):
    from aicalib_tf.calib.handeye.poses import parse_poses
    from aicalib_tf.cli import InputError

    with pytest.raises(InputError, match=r"^poses\.yaml: (nested more than 64 levels|holds the YAML tag)"):
        parse_poses(text, "poses.yaml", "yaml")


@pytest.mark.parametrize("content", [b"", b"\x00" * 64, b"TFL3" + bytes(range(256)) * 4])
def test_a_broken_tflite_file_is_refused_naming_it(tmp_path, content):
    from aicalib_tf.cnn.runtime import RuntimeModel

    path = tmp_path / "broken.tflite"
    path.write_bytes(content)
    with pytest.raises(ValueError, match=r"broken\.tflite: not a readable \.tflite model"):
        RuntimeModel(path)
