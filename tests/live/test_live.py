"""The live page: a real browser (headless Chromium) with a fake camera playing a rendered video ends
with a calibration file; the server-side source; bad input."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM_FLAGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--use-fake-ui-for-media-stream", "--use-fake-device-for-media-stream"]
LIVE = [sys.executable, "-m", "aicalib_tf.live", "--pattern", "9x6", "--square", "25mm", "--port", "0",
        "--max-views", "5", "--model", "plumb_bob"]


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    """A 6 s, 10 fps, 640x480 hand-held video of a 9x6 board (AVI and the y4m Chromium's fake camera plays)."""
    from data_gen.video import main as render

    out = tmp_path_factory.mktemp("video")
    assert render(["--out", str(out), "--seconds", "6", "--fps", "10", "--size", "640x480", "--y4m", "--quiet",
                   "--workers", "1"]) == 0
    return out


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")


def _start(args, tmp_path) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen(LIVE + args, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=dict(os.environ, PYTHONPATH=str(ROOT)))
    for line in proc.stdout:
        m = re.search(r"(http://\S+)", line)
        if m:
            return proc, m.group(1)
    raise AssertionError(f"the server did not start (exit {proc.wait()})")


def _route(url: str, path: str) -> str:
    """The printed page address (``http://localhost:PORT/?token=...``) -> one of its routes, with the token."""
    base, _, query = url.partition("?")
    assert query.startswith("token="), url
    return f"{base}{path}?{query}"


def _get(url: str) -> dict:
    with urllib.request.urlopen(url, timeout=10) as r:
        return json.loads(r.read())


def _wait_for(path: Path, seconds: float, procs) -> bool:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if path.exists():
            return True
        if any(p.poll() is not None for p in procs):
            return False
        time.sleep(0.5)
    return False


def test_browser_camera_page_ends_with_a_calibration_file(video, tmp_path):
    browser = _chromium()
    if browser is None:
        if os.environ.get("CI"):
            pytest.fail("Chromium is not installed: .ci/run installs it (apt-get install chromium)")
        pytest.skip("no Chromium on this machine (apt-get install chromium)")
    out = tmp_path / "calib"
    server, url = _start(["--out", str(out)], tmp_path)
    chrome = subprocess.Popen([browser, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'profile'}",
                               f"--use-file-for-fake-video-capture={video / 'video.y4m'}", url + "&autostart=1&autosave=1"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        saved = _wait_for(out / "camera.json", 240, [server, chrome])
        state = _get(_route(url, "state"))
    finally:
        chrome.kill()
        server.kill()
    assert saved, f"no calibration saved; last state: {state}"
    cal = json.loads((out / "camera.json").read_text())
    assert cal["meta"]["live"] is True and cal["meta"]["source"] == "browser camera"
    assert 400 < cal["camera_matrix"][0][0] < 700 and state["views"] >= 3
    print(f"browser camera: {state['frames']} frames, {state['fps']} frames/s handled, {state['views']} views")


def test_server_side_video_source_and_save(video, tmp_path):
    out = tmp_path / "calib"
    server, url = _start(["--out", str(out), "--source", str(video / "video.avi")], tmp_path)
    try:
        ws_free_state = {}
        end = time.monotonic() + 120
        while time.monotonic() < end:
            ws_free_state = _get(_route(url, "state"))
            if ws_free_state.get("views", 0) >= 3 and (ws_free_state.get("done") or ws_free_state.get("frames", 0) > 40):
                break
            time.sleep(1)
        with pytest.raises(urllib.error.HTTPError, match="403"):  # the token is required
            urllib.request.urlopen(urllib.request.Request(url.partition("?")[0] + "save", method="POST"), timeout=10)
        req = urllib.request.Request(_route(url, "save"), method="POST")
        with urllib.request.urlopen(req, timeout=120) as r:
            reply = json.loads(r.read())
    finally:
        server.kill()
    assert reply["ok"], reply
    assert (out / "camera.yaml").exists() and json.loads((out / "camera.json").read_text())["meta"]["live"]


def test_a_missing_source_is_one_error_line_and_exit_2(tmp_path):
    proc = subprocess.run(LIVE + ["--source", str(tmp_path / "none.mp4")], cwd=ROOT, capture_output=True, text=True,
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
