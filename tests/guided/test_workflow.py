"""The video path of ``python -m aicalib_tf.calibrate``: a rendered video to camera.json, bad input, partial runs."""

import json

import cv2
import numpy as np
import pytest

from aicalib_tf.calibrate import main
from aicalib_tf.guided.workflow import guided_source, parse_target
from data_gen.video import main as render

from .boards import CHARUCO


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    out = tmp_path_factory.mktemp("vid")
    assert render(["--out", str(out), "--seconds", "3", "--size", "400x300", "--pace", "4", "--seed", "3",
                  "--shutter", "0.004", "--quiet"]) == 0
    return out


def _one_error_line(capsys) -> str:
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and err[0].startswith("error: "), err
    return err[0]


def test_a_video_calibrates_end_to_end(video, tmp_path, capsys):
    out = tmp_path / "calib"
    assert main([str(video / "video.avi"), "--pattern", "9x6", "--square", "25mm", "--out", str(out), "--quiet"]) == 0
    cam = json.loads((out / "camera.json").read_text())
    truth = json.loads((video / "labels.jsonl").read_text().splitlines()[0])
    meta = cam["meta"]
    assert meta["kept_frames"] and meta["frames"] == 90 and meta["examined"] < 45 and meta["partial"] is False
    K = np.array(cam["camera_matrix"]["data"] if isinstance(cam["camera_matrix"], dict) else cam["camera_matrix"])
    assert abs(K.ravel()[0] / truth["K"][0][0] - 1) < 0.03
    assert (out / "report.png").is_file() and "views kept" in capsys.readouterr().out


def test_the_dispatch_and_the_target():
    assert guided_source(["a.mp4"], None) == "a.mp4" and guided_source([], "0") == "0"
    assert guided_source(["photos/*.png"], None) is None and guided_source(["a.png", "b.png"], None) is None
    assert parse_target("0.1px") == 0.1 and parse_target("0.25") == 0.25
    with pytest.raises(ValueError, match="--target"):
        parse_target("-1px")


def test_bad_videos_are_one_line_and_exit_2(tmp_path, capsys):
    args = ["--pattern", "9x6", "--out", str(tmp_path / "o"), "--quiet"]
    assert main([str(tmp_path / "missing.mp4")] + args) == 2
    assert "missing.mp4" in _one_error_line(capsys)
    (tmp_path / "junk.avi").write_bytes(b"\x00garbage" * 100)
    assert main([str(tmp_path / "junk.avi")] + args) == 2
    assert "junk.avi: not a readable video" in _one_error_line(capsys)
    w = cv2.VideoWriter(str(tmp_path / "blank.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 30, (160, 120))
    rng = np.random.default_rng(0)
    for _ in range(20):
        w.write(rng.integers(90, 110, (120, 160, 3), dtype=np.uint8))
    w.release()
    assert main([str(tmp_path / "blank.avi")] + args) == 2
    assert "blank.avi: no 9x6 board found" in _one_error_line(capsys)
    assert not (tmp_path / "o").exists()


def test_a_stopped_run_saves_only_with_save_partial(video, tmp_path, monkeypatch, capsys):
    from aicalib_tf import sources

    real = sources.VideoFile.__iter__

    def stops(self):
        for frame in real(self):
            if frame.index == 75:
                raise KeyboardInterrupt
            yield frame

    monkeypatch.setattr(sources.VideoFile, "__iter__", stops)
    args = [str(video / "video.avi"), "--pattern", "9x6", "--square", "25mm", "--quiet"]
    assert main(args + ["--out", str(tmp_path / "a")]) == 130
    assert not (tmp_path / "a").exists()
    assert main(args + ["--out", str(tmp_path / "b"), "--save-partial"]) == 0
    meta = json.loads((tmp_path / "b" / "camera.json").read_text())["meta"]
    assert meta["partial"] is True and meta["stopped"].startswith("stopped early")
    assert "PARTIAL" in (tmp_path / "b" / "report.txt").read_text()


def test_a_missing_camera_is_one_line(tmp_path, capsys):
    assert main(["--camera", "63", "--pattern", "9x6", "--out", str(tmp_path / "o"), "--quiet"]) == 2
    assert "camera 63: cannot open it" in _one_error_line(capsys)


def test_a_charuco_video_calibrates_end_to_end(charuco_pair, tmp_path, capsys):
    out = tmp_path / "calib"
    assert main([str(charuco_pair / "video_cam0.avi"), "--board", CHARUCO, "--out", str(out), "--quiet"]) == 0
    cam = json.loads((out / "camera.json").read_text())
    truth = json.loads((charuco_pair / "labels_cam0.jsonl").read_text().splitlines()[0])
    assert truth["board"] == CHARUCO and truth["pattern_size"] == [5, 4] and truth["square_size"] == 40.0
    meta = cam["meta"]
    assert meta["board"] == CHARUCO and len(meta["kept_frames"]) >= 3 and meta["partial"] is False
    assert any(v["corners"] < 20 for v in cam["views"])  # boards cut by the frame are views
    K = np.array(cam["camera_matrix"]["data"] if isinstance(cam["camera_matrix"], dict) else cam["camera_matrix"])
    assert abs(K.ravel()[0] / truth["K"][0][0] - 1) < 0.02
    assert abs(K.ravel()[2] - truth["K"][0][2]) < 3 and abs(K.ravel()[5] - truth["K"][1][2]) < 3
    assert "views kept" in capsys.readouterr().out


def test_a_charuco_board_missing_bad_or_on_a_missing_camera_is_one_line(video, tmp_path, capsys):
    assert main([str(video / "video.avi"), "--board", CHARUCO, "--out", str(tmp_path / "o"), "--quiet"]) == 2
    assert "no ChArUco board (charuco:6x5" in _one_error_line(capsys)
    assert main([str(video / "video.avi"), "--board", "charuco:7x5,square=30mm,marker=40mm,dict=DICT_4X4_50",
                 "--out", str(tmp_path / "o"), "--quiet"]) == 2
    assert "marker (40) must be smaller than square (30)" in _one_error_line(capsys)
    assert main(["--camera", "63", "--board", CHARUCO, "--out", str(tmp_path / "o"), "--quiet"]) == 2
    assert "camera 63: cannot open it" in _one_error_line(capsys)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("n", ["0", "-1", "2"])
def test_max_views_under_three_is_refused(video, tmp_path, capsys, n):
    out = tmp_path / "o"
    assert main([str(video / "video.avi"), "--pattern", "9x6", "--max-views", n, "--out", str(out), "--quiet"]) == 2
    assert f"--max-views must be an integer of at least 3, got {n}" in _one_error_line(capsys)
    assert not out.exists()
    assert main(["--rig", f"cam0={video}/video.avi", f"cam1={video}/video.avi", "--pattern", "9x6", "--max-views", n,
                 "--out", str(out), "--quiet"]) == 2
    assert "--max-views must be" in _one_error_line(capsys)
