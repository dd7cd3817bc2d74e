"""A live ChArUco calibration in a real browser (headless Chromium): the fake camera plays a short
rendered video of a ChArUco board, and the page ends with a calibration file naming the board."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import pytest

from tests.live.test_live import CHROMIUM_FLAGS, ROOT, _chromium, _get, _route, _wait_for

BOARD = "charuco:6x5,square=40mm,marker=30mm,dict=DICT_4X4_50"


def test_browser_camera_page_calibrates_with_a_charuco_board(tmp_path):
    from data_gen.video import main as render

    browser = _chromium()
    if browser is None:
        if os.environ.get("CI"):
            pytest.fail("Chromium is not installed: .ci/run installs it (apt-get install chromium)")
        pytest.skip("no Chromium on this machine (apt-get install chromium)")
    video, out = tmp_path / "video", tmp_path / "calib"
    assert render(["--out", str(video), "--seconds", "3", "--fps", "8", "--size", "480x360", "--pace", "2",
                   "--board", BOARD, "--y4m", "--quiet", "--workers", "1"]) == 0
    server = subprocess.Popen([sys.executable, "-m", "aicalib_tf.live", "--board", BOARD, "--port", "0", "--out", str(out),
                               "--max-views", "4", "--model", "plumb_bob"], cwd=ROOT, stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    url = next((m.group(1) for line in server.stdout if (m := re.search(r"(http://\S+)", line))), None)
    assert url, f"the server did not start (exit {server.wait()})"
    chrome = subprocess.Popen([browser, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'profile'}",
                               f"--use-file-for-fake-video-capture={video / 'video.y4m'}", url + "&autostart=1&autosave=1"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        saved = _wait_for(out / "camera.json", 120, [server, chrome])
        state = _get(_route(url, "state"))
    finally:
        chrome.kill()
        server.kill()
    assert saved, f"no calibration saved; last state: {state}"
    cal = json.loads((out / "camera.json").read_text())
    truth = json.loads((video / "labels.jsonl").read_text().splitlines()[0])
    assert cal["meta"]["live"] is True and cal["meta"]["board"] == BOARD and state["views"] >= 3
    assert abs(cal["camera_matrix"][0][0] / truth["K"][0][0] - 1) < 0.1
    print(f"ChArUco in the browser: {state['frames']} frames, {state['views']} views, "
          f"fx {100 * (cal['camera_matrix'][0][0] / truth['K'][0][0] - 1):+.2f} %")
