"""A live ChArUco calibration in a real browser (headless Chromium): the fake camera plays a short
rendered video of a ChArUco board, and the page ends with a calibration file naming the board."""

from __future__ import annotations

import json

BOARD = "charuco:6x5,square=40mm,marker=30mm,dict=DICT_4X4_50"


def test_browser_camera_page_calibrates_with_a_charuco_board(tmp_path, browser_calibration):
    from data_gen.video import main as render

    video, out = tmp_path / "video", tmp_path / "calib"
    assert render(["--out", str(video), "--seconds", "3", "--fps", "8", "--size", "480x360", "--pace", "2",
                   "--board", BOARD, "--y4m", "--quiet", "--workers", "1"]) == 0
    state = browser_calibration(["--board", BOARD, "--port", "0", "--out", str(out), "--max-views", "4",
                                 "--model", "plumb_bob"], video / "video.y4m", out, 120)
    cal = json.loads((out / "camera.json").read_text())
    truth = json.loads((video / "labels.jsonl").read_text().splitlines()[0])
    assert cal["meta"]["live"] is True and cal["meta"]["board"] == BOARD and state["views"] >= 3
    assert abs(cal["camera_matrix"][0][0] / truth["K"][0][0] - 1) < 0.1
    print(f"ChArUco in the browser: {state['frames']} frames, {state['views']} views, "
          f"fx {100 * (cal['camera_matrix'][0][0] / truth['K'][0][0] - 1):+.2f} %")
