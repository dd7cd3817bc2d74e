"""``python -m aicalib_tf.check`` end to end on OpenCV's left photos: holds, moved, video, bad input."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from aicalib_tf.calib.files import save_calibration
from aicalib_tf.calib.fit import View, calibrate_camera
from aicalib_tf.calib.workflow import make_detector
from aicalib_tf.check import main, video_frames
from aicalib_tf.io import load_image

LEFT = Path(__file__).resolve().parent / "data" / "opencv_left"


@pytest.fixture(scope="module")
def calibration(tmp_path_factory):
    """camera.json/camera.yaml of the left photos (plumb_bob, through the API)."""
    detect = make_detector("cnn", (9, 6))
    views = [View(f.name, *detect(load_image(f))) for f in sorted(LEFT.glob("*.jpg"))]
    cal = calibrate_camera(views, (9, 6), 25.0, (640, 480), model="plumb_bob", square_unit="mm")
    return save_calibration(cal, tmp_path_factory.mktemp("cal") / "calib")


def _run(capsys, *argv):
    rc = main([str(a) for a in argv] + ["--workers", "1"])
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_the_same_photos_hold(calibration, tmp_path, capsys):
    rc, out, err = _run(capsys, calibration, LEFT / "*.jpg", "--out", tmp_path / "check.json")
    assert rc == 0, out + err
    assert "the calibration HOLDS" in out and "13 views: 13 used, 0 skipped" in out
    assert "corner noise per axis: these views" in out and "detects (95% of the time)" in out
    d = json.loads((tmp_path / "check.json").read_text())
    assert d["holds"] is True and len(d["views"]) == 13 and abs(d["drift"]["fx"]) < 0.3 * d["drift_std"]["fx"]
    assert d["written_by"] == "aicalib_tf.check" and d["noise"]["check_px"] > 0
    # real photos scatter more than independent corner noise: the 13 views, not the corners, set the tests' scale
    nu = d["drift_test"]["scale_dof"]
    assert d["inflation"] > 2 and nu < 40 and d["lens_test"]["scale_dof"] == nu
    assert f"from 13 views, F with {nu:.0f} degrees of freedom" in out


def test_photos_shifted_by_8px_do_not_hold(calibration, tmp_path, capsys):
    shift = np.float64([[1, 0, 8], [0, 1, 0]])  # the image content moves: the principal point moves 8 px
    for f in sorted(LEFT.glob("*.jpg")):
        img = cv2.imread(str(f))
        cv2.imwrite(str(tmp_path / f"{f.stem}.png"), cv2.warpAffine(img, shift, (640, 480), borderMode=cv2.BORDER_REPLICATE))
    rc, out, err = _run(capsys, calibration / "camera.json", tmp_path / "*.png")
    assert rc == 1, out + err
    assert "DOES NOT HOLD" in out and "why: the intrinsics drifted" in out


def test_a_video_is_sampled(calibration, tmp_path, capsys):
    video = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, (640, 480))
    if not writer.isOpened():
        pytest.skip("this OpenCV build writes no MJPG video")
    for f in sorted(LEFT.glob("*.jpg")):
        for _ in range(2):  # each photo twice: every second frame is a different photo
            writer.write(cv2.imread(str(f)))
    writer.release()
    assert [k for k, _ in video_frames(str(video), every=2, limit=20)] == list(range(0, 26, 2))
    rc, out, err = _run(capsys, calibration, video, "--every", "2")
    assert rc == 0, out + err
    assert "13 views: 13 used" in out


def test_yaml_without_covariance_says_so(calibration, capsys):
    rc, out, err = _run(capsys, calibration / "camera.yaml", LEFT / "left0[1-6].jpg")
    assert rc == 0, out + err
    assert "carries no uncertainty" in out


@pytest.mark.parametrize("case", ["no calibration", "bad calibration", "no photos", "too few views", "wrong size"])
def test_bad_input_is_one_line_and_exit_2(calibration, tmp_path, capsys, case):
    cal, photos = calibration, [LEFT / "*.jpg"]
    if case == "no calibration":
        cal = tmp_path / "nothing"
    elif case == "bad calibration":
        cal = tmp_path / "camera.json"
        cal.write_text("{not json")
    elif case == "no photos":
        photos = [tmp_path / "*.jpg"]
    elif case == "too few views":
        photos = [LEFT / "left01.jpg", LEFT / "left02.jpg"]
    else:
        cv2.imwrite(str(tmp_path / "small.png"), np.zeros((240, 320), np.uint8))
        photos = [tmp_path / "small.png"]
    rc, out, err = _run(capsys, cal, *photos)
    assert rc == 2 and out == ""
    assert err.startswith("error: ") and err.count("\n") == 1, err
    if case == "wrong size":
        assert "small.png: image is 320x240, the calibration is for 640x480" in err


def _edited(calibration, tmp_path, edit) -> Path:
    d = json.loads((calibration / "camera.json").read_text())
    edit(d)
    path = tmp_path / "camera.json"
    path.write_text(json.dumps(d))
    return path


def _scaled_covariance(d, factor):
    d["covariance"] = (np.eye(len(d["covariance"])) * factor).tolist()


def _not_psd(d):
    c = np.array(d["covariance"])
    c[0, 1] = c[1, 0] = 10 * np.sqrt(c[0, 0] * c[1, 1])
    d["covariance"] = c.tolist()


@pytest.mark.parametrize("edit, expected", [
    (lambda d: _scaled_covariance(d, 1e300), "field covariance gives σ"),
    (lambda d: _scaled_covariance(d, -1.0), "field covariance holds a negative variance"),
    (_not_psd, "field covariance is not positive semi-definite"),
    (lambda d: d["camera_matrix"][0].__setitem__(0, 1e300), "field camera_matrix fx 1e+300 px is not a focal length"),
    (lambda d: d["camera_matrix"][0].__setitem__(0, True), "field camera_matrix must be a 3x3 matrix of numbers"),
], ids=["covariance 1e300", "negative variance", "not psd", "fx 1e300", "fx true"])
def test_an_absurd_calibration_is_refused_naming_the_file_and_field(calibration, tmp_path, capsys, edit, expected):
    path = _edited(calibration, tmp_path, edit)
    rc, out, err = _run(capsys, path, LEFT / "left01.jpg", LEFT / "left02.jpg", LEFT / "left03.jpg")
    assert rc == 2 and out == "" and err.count("\n") == 1, err
    assert err.startswith(f"error: {path}: ") and expected in err
    assert "nan" not in err.lower() and "Traceback" not in err


@pytest.mark.parametrize("target", ["the calibration", "a photo", "a foreign file", "a folder"])
def test_out_never_replaces_an_input_or_a_file_it_did_not_write(calibration, tmp_path, capsys, target):
    photos = tmp_path / "photos"
    photos.mkdir()
    for f in sorted(LEFT.glob("left0[1-3].jpg")):
        (photos / f.name).write_bytes(f.read_bytes())
    notes = tmp_path / "notes.txt"
    notes.write_text("mine")
    out = {"the calibration": calibration / "camera.json", "a photo": photos / "left01.jpg", "a foreign file": notes,
           "a folder": photos}[target]
    before = {p: p.read_bytes() for p in [calibration / "camera.json", notes, *photos.iterdir()]}
    rc, stdout, err = _run(capsys, calibration, photos / "*.jpg", "--out", out)
    assert rc == 2 and stdout == "" and err.count("\n") == 1, err
    assert err.startswith(f"error: {out}: ")
    assert {p: p.read_bytes() for p in before} == before


def test_out_replaces_an_earlier_result(tmp_path):
    from aicalib_tf.check import WRITTEN_BY, check_out_file

    old = tmp_path / "check.json"
    old.write_text(json.dumps({"written_by": WRITTEN_BY, "holds": True}))
    assert check_out_file(str(old), [tmp_path / "camera.json"]) == old.resolve()
    assert check_out_file(str(tmp_path / "new.json"), []) == (tmp_path / "new.json").resolve()
    link = tmp_path / "link.json"
    link.symlink_to(tmp_path / "camera.json")
    with pytest.raises(ValueError, match="one of the inputs"):
        check_out_file(str(link), [tmp_path / "camera.json"])
    with pytest.raises(ValueError, match="does not exist"):
        check_out_file(str(tmp_path / "no" / "check.json"), [])


def test_a_circle_grid_calibration_is_refused_with_one_line(calibration, tmp_path, capsys):
    path = _edited(calibration, tmp_path, lambda d: d["meta"].__setitem__("board", "circles:4x11,spacing=20mm,asymmetric"))
    rc, out, err = _run(capsys, path, LEFT / "left01.jpg", LEFT / "left02.jpg", LEFT / "left03.jpg")
    assert rc == 2 and err.count("\n") == 1 and "circle grid" in err and "Traceback" not in err, err
