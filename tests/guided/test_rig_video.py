"""The rig video path of ``python -m aicalib_tf.calibrate --rig cam0=left.avi cam1=right.avi``: a rendered
stereo pair to rig.json, cameras out of sync, missing and mixed inputs."""

import json

import cv2
import numpy as np
import pytest

from aicalib_tf.calibrate import main
from aicalib_tf.guided.rig_video import is_rig_video, pair_overlap, parse_tolerance
from data_gen.video import main as render


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    out = tmp_path_factory.mktemp("rigvid")
    assert render(["--out", str(out), "--seconds", "3", "--fps", "15", "--size", "640x480", "--pace", "3",
                   "--seed", "3", "--shutter", "0.004", "--rig-baseline", "120", "--quiet"]) == 0
    return out


def _one_error_line(capsys) -> str:
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and err[0].startswith("error: "), err
    return err[0]


def _args(a, b, out):
    return ["--rig", f"cam0={a}", f"cam1={b}", "--pattern", "9x6", "--square", "25mm", "--out", str(out), "--quiet"]


def test_a_stereo_video_pair_calibrates_end_to_end(pair, tmp_path, capsys):
    out = tmp_path / "rig"
    assert main(_args(pair / "video_cam0.avi", pair / "video_cam1.avi", out)) == 0
    text = capsys.readouterr().out
    rig = json.loads((out / "rig.json").read_text())
    truth = json.loads((pair / "meta.json").read_text())["rig"]
    assert rig["quality"]["status"] == "ok", text
    baseline = float(np.linalg.norm(np.asarray(rig["T"])[1]))
    assert abs(baseline / truth["baseline"] - 1) < 0.02, (baseline, truth["baseline"])
    meta = rig["meta"]
    assert meta["frames"] == {"cam0": 45, "cam1": 45} and meta["examined"]["cam0"] < 45
    assert meta["kept_frames"]["cam0"] and meta["kept_frames"]["cam1"] and meta["frames_used"]
    assert "cam0-cam1: 45 frame pairs" in text and "unpaired: 0 of cam0, 0 of cam1" in text
    for name in ("intrinsics.yml", "extrinsics.yml", "cam0_camera_info.yaml", "report.png", "report.txt",
                 "cam1/camera.yaml"):
        assert (out / name).is_file(), name


def test_videos_out_of_sync_are_refused_with_the_offset(pair, tmp_path, capsys):
    slow = tmp_path / "slow.avi"  # cam1's frames at 12 fps: its clock runs away from cam0's
    cap = cv2.VideoCapture(str(pair / "video_cam1.avi"))
    w = cv2.VideoWriter(str(slow), cv2.VideoWriter_fourcc(*"MJPG"), 12, (640, 480))
    ok, img = cap.read()
    while ok:
        w.write(img)
        ok, img = cap.read()
    w.release()
    cap.release()
    out = tmp_path / "o"
    assert main(_args(pair / "video_cam0.avi", slow, out)) == 2
    line = _one_error_line(capsys)
    assert "out of sync" in line and "video_cam0.avi" in line and "slow.avi" in line and " s apart" in line, line
    assert not out.exists()


def test_a_missing_or_mixed_input_is_one_line(pair, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(_args(pair / "video_cam0.avi", tmp_path / "missing.mp4", out)) == 2
    assert "missing.mp4" in _one_error_line(capsys)
    assert main(_args(pair / "video_cam0.avi", tmp_path / "*.png", out)) == 2
    assert "give every camera a video" in _one_error_line(capsys)
    assert main(_args(pair / "video_cam0.avi", pair / "video_cam0.avi", out)) == 2
    assert "the same video" in _one_error_line(capsys)
    assert not out.exists()


def test_tolerance_and_dispatch():
    assert parse_tolerance("10ms") == pytest.approx(0.01) and parse_tolerance("0.02s") == pytest.approx(0.02)
    assert parse_tolerance("5") == pytest.approx(0.005)
    with pytest.raises(ValueError, match="--sync-tolerance"):
        parse_tolerance("fast")
    assert is_rig_video([("a", "l.mp4"), ("b", "rtsp://x/y")]) and not is_rig_video([("a", "l/*.png"), ("b", "r/*.png")])


def test_a_camera_that_ran_longer_is_not_out_of_sync():
    a, b = np.arange(100) / 30.0, 0.002 + np.arange(160) / 30.0  # b kept recording for 2 s more
    p = pair_overlap(a, b, tolerance_s=0.01)
    assert len(p.pairs) == 100 and p.unpaired_b == list(range(100, 160)) and abs(p.offset_s - 0.002) < 1e-9
    with pytest.raises(ValueError, match="out of sync"):
        pair_overlap(a, 0.05 + b, tolerance_s=0.01)
    with pytest.raises(ValueError, match="never recorded at the same time"):
        pair_overlap(a, 10 + b, tolerance_s=0.01)


def test_a_stopped_rig_run_saves_only_with_save_partial(pair, tmp_path, monkeypatch, capsys):
    from aicalib_tf import sources

    real = sources.VideoFile.__iter__

    def stops(self):
        for frame in real(self):
            if frame.index == 40 and self.name.endswith("video_cam1.avi"):
                raise KeyboardInterrupt
            yield frame

    monkeypatch.setattr(sources.VideoFile, "__iter__", stops)
    assert main(_args(pair / "video_cam0.avi", pair / "video_cam1.avi", tmp_path / "a")) == 130
    assert not (tmp_path / "a").exists()
    out = tmp_path / "b"
    assert main(_args(pair / "video_cam0.avi", pair / "video_cam1.avi", out) + ["--save-partial"]) == 0
    meta = json.loads((out / "rig.json").read_text())["meta"]
    assert meta["partial"] is True and meta["stopped"].startswith("stopped early")
    assert 35 <= meta["frames"]["cam1"] < 45  # the reading stopped at cam1's frame 40
    assert (out / "report.txt").read_text().startswith("PARTIAL")


def test_a_circular_fisheye_rig_video_keeps_each_cameras_image_circle(tmp_path, capsys):
    from tests.calib.rig.synthetic import check_circular_rig_output, circular_rig

    truth, frames = circular_rig()
    for k in (0, 1):  # each board pose held for 4 frames at 10 fps: the motion gate sees it rest
        w = cv2.VideoWriter(str(tmp_path / f"cam{k}.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (640, 480), False)
        for frame in frames:
            for _ in range(4):
                w.write(frame[k].image)
        w.release()
    out = tmp_path / "rig"
    assert main(["--rig", f"cam0={tmp_path / 'cam0.avi'}", f"cam1={tmp_path / 'cam1.avi'}", "--pattern", "9x6",
                 "--square", f"{truth.board.square_size}mm", "--out", str(out), "--quiet"]) == 0
    check_circular_rig_output(out, truth, capsys.readouterr().out)


def test_a_charuco_stereo_video_pair_calibrates_end_to_end(charuco_pair, tmp_path, capsys):
    from .boards import CHARUCO

    out = tmp_path / "rig"
    assert main(["--rig", f"cam0={charuco_pair}/video_cam0.avi", f"cam1={charuco_pair}/video_cam1.avi", "--board",
                 CHARUCO, "--out", str(out), "--quiet"]) == 0
    rig = json.loads((out / "rig.json").read_text())
    truth = json.loads((charuco_pair / "meta.json").read_text())["rig"]
    assert rig["quality"]["status"] == "ok" and rig["meta"]["board"] == CHARUCO
    assert abs(float(np.linalg.norm(np.asarray(rig["T"])[1])) / truth["baseline"] - 1) < 0.01
    assert rig["meta"]["kept_frames"]["cam0"] and rig["meta"]["kept_frames"]["cam1"]
    assert "cam0-cam1: 50 frame pairs" in capsys.readouterr().out
