"""The live page: a real browser (headless Chromium) with a fake camera playing a rendered video ends
with a calibration file; the server-side source; bad input."""

from __future__ import annotations

import json
import os
import subprocess
import time
import urllib.error
import urllib.request

import pytest

from tests.live.conftest import LIVE, ROOT, get_json, route, start_live

CHESSBOARD = ["--pattern", "9x6", "--square", "25mm", "--port", "0", "--max-views", "5", "--model", "plumb_bob"]


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    """A 6 s, 10 fps, 640x480 hand-held video of a 9x6 board (AVI and the y4m Chromium's fake camera plays)."""
    from data_gen.video import main as render

    out = tmp_path_factory.mktemp("video")
    assert render(["--out", str(out), "--seconds", "6", "--fps", "10", "--size", "640x480", "--y4m", "--quiet",
                   "--workers", "1"]) == 0
    return out


def test_browser_camera_page_ends_with_a_calibration_file(video, tmp_path, browser_calibration):
    out = tmp_path / "calib"
    state = browser_calibration(CHESSBOARD + ["--out", str(out)], video / "video.y4m", out, 240)
    cal = json.loads((out / "camera.json").read_text())
    assert cal["meta"]["live"] is True and cal["meta"]["source"] == "browser camera"
    assert 400 < cal["camera_matrix"][0][0] < 700 and state["views"] >= 3
    print(f"browser camera: {state['frames']} frames, {state['fps']} frames/s handled, {state['views']} views")


def test_server_side_video_source_and_save(video, tmp_path):
    out = tmp_path / "calib"
    server, url = start_live(CHESSBOARD + ["--out", str(out), "--source", str(video / "video.avi")])
    try:
        ws_free_state = {}
        end = time.monotonic() + 120
        while time.monotonic() < end:
            ws_free_state = get_json(route(url, "state"))
            if ws_free_state.get("views", 0) >= 3 and (ws_free_state.get("done") or ws_free_state.get("frames", 0) > 40):
                break
            time.sleep(1)
        with pytest.raises(urllib.error.HTTPError, match="403"):  # the token is required
            urllib.request.urlopen(urllib.request.Request(url.partition("?")[0] + "save", method="POST"), timeout=10)
        req = urllib.request.Request(route(url, "save"), method="POST")
        with urllib.request.urlopen(req, timeout=120) as r:
            reply = json.loads(r.read())
    finally:
        server.kill()
    assert reply["ok"], reply
    assert (out / "camera.yaml").exists() and json.loads((out / "camera.json").read_text())["meta"]["live"]


def test_a_missing_source_is_one_error_line_and_exit_2(tmp_path):
    proc = subprocess.run(LIVE + CHESSBOARD + ["--source", str(tmp_path / "none.mp4")], cwd=ROOT, capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)), timeout=120)
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("error:")]
    assert proc.returncode == 2 and len(lines) == 1 and "none.mp4" in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr


def test_page_frames_decode_to_the_same_gray_jpeg_or_png():
    import cv2
    import numpy as np

    from aicalib_tf.live.server import LiveConfig, LiveState

    seen = []

    def detector(gray):
        seen.append(gray.copy())
        return None

    detector.info, detector.relative = {}, False
    state = LiveState(LiveConfig((9, 6)), detector)
    rng = np.random.default_rng(1)
    bgr = cv2.GaussianBlur(rng.integers(0, 256, (120, 160, 3), dtype=np.uint8), (7, 7), 2)
    jpeg = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, 92])[1].tobytes()
    png = cv2.imencode(".png", cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR))[1].tobytes()
    assert state.add_jpeg(jpeg)["examined"] and state.add_jpeg(png)["examined"]
    assert seen[0].dtype == np.uint8 and seen[0].shape == (120, 160)
    assert np.abs(seen[0].astype(int) - seen[1]).max() <= 1  # the luma of the JPEG, and the PNG's grey
    with pytest.raises(ValueError, match="not a JPEG or PNG"):
        state.add_jpeg(b"\xff\xd8\xff" + b"junk" * 10)
