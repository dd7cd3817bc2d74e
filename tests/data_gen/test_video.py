"""Rendered videos: frames read back, strict per-frame truth, motion blur from the motion, y4m."""

import json

import cv2
import numpy as np
import pytest

from aicalib_tf.guided.selection import blur_px
from data_gen.video import VideoConfig, main, make_scene, render_frame


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    out = tmp_path_factory.mktemp("video")
    assert main(["--out", str(out), "--seconds", "1", "--size", "320x240", "--pace", "3", "--seed", "5",
                 "--rolling-shutter", "0.01", "--y4m", "--quiet"]) == 0
    return out


def test_frames_and_labels_round_trip(video):
    labels = [json.loads(line) for line in (video / "labels.jsonl").read_text().splitlines()]
    cap = cv2.VideoCapture(str(video / "video.avi"))
    frames = []
    while True:
        ok, img = cap.read()
        if not ok:
            break
        frames.append(img)
    assert len(frames) == len(labels) == 30 and frames[0].shape[:2] == (240, 320)
    assert [lab["index"] for lab in labels] == list(range(30))
    lab = labels[0]
    assert {"K", "dist", "distortion_model", "rvec", "tvec", "corners", "visible", "time_s", "motion_px"} <= set(lab)
    assert len(lab["corners"]) == 54 and len(lab["visible"]) == 54
    assert json.loads((video / "meta.json").read_text())["frames"] == 30


def test_y4m_has_a_header_and_every_frame(video):
    data = (video / "video.y4m").read_bytes()
    head, _, rest = data.partition(b"\n")
    assert head.startswith(b"YUV4MPEG2 W320 H240 F30:1") and b"C420jpeg" in head
    assert len(rest) == 30 * (len(b"FRAME\n") + 320 * 240 * 3 // 2)


def test_motion_blur_follows_the_motion():
    scene = make_scene(VideoConfig(out="", seconds=3, size=(640, 480), seed=2, noise=0.0))
    arrive, leave = scene.path.times[0]
    middle = 0.5 * (leave + scene.path.times[1, 0])  # the fastest moment of the first move
    widths, motions = [], []
    for i in (int(arrive * 30) + 1, int(middle * 30)):
        gray, lab = render_frame(scene, i)
        vis = np.array(lab["visible"])
        ids = np.stack(np.meshgrid(np.arange(9), np.arange(6)), -1).reshape(-1, 2)[vis]
        widths.append(blur_px(gray, np.array(lab["corners"], dtype=float)[vis], ids))
        motions.append(lab["motion_px"])
    assert motions[0] < 0.5 < 4.0 < motions[1] and widths[1] > 1.4 * widths[0], (motions, widths)


def test_bad_arguments_are_one_line(capsys, tmp_path):
    assert main(["--out", str(tmp_path / "x"), "--size", "641x480"]) == 2
    assert main(["--out", str(tmp_path / "x"), "--shutter", "0.5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(e.startswith("error: ") for e in err)
