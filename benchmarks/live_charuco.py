"""A live ChArUco calibration in headless Chromium: the browser's fake camera plays a rendered video.

    python benchmarks/live_charuco.py [--out /tmp/live_charuco] [--seconds 8] [--fps 10] [--size 640x480]
        [--board charuco:6x5,square=40mm,marker=30mm,dict=DICT_4X4_50] [--seed 0] [--wait 300]

Renders a hand-held video of the ChArUco board (``python -m data_gen.video --board ... --y4m``),
starts ``python -m aicalib_tf.live --board ...`` on a free port and opens the page in headless
Chromium with ``autostart=1&autosave=1``: the page sends the fake camera's frames (the y4m, looped)
until the loop's stop rule holds, then saves. Prints whether a calibration file came out, the
seconds it took, the frames the page sent and the views kept, the rate the page reached, and the
saved calibration's fx error (%) and principal point error (px) against the render's truth.
``--board aprilgrid:...`` runs the same with a Kalibr AprilGrid. Needs Chromium (``apt-get install chromium``).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FLAGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--use-fake-ui-for-media-stream", "--use-fake-device-for-media-stream"]
BOARD = "charuco:6x5,square=40mm,marker=30mm,dict=DICT_4X4_50"


def _state(url: str) -> dict:
    base, _, query = url.partition("?")
    with urllib.request.urlopen(f"{base}state?{query}", timeout=10) as r:
        return json.loads(r.read())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="/tmp/live_charuco")
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--fps", default="10")
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--board", default=BOARD)
    ap.add_argument("--seed", default="0")
    ap.add_argument("--wait", type=float, default=300.0, help="seconds to wait for the saved file")
    a = ap.parse_args(argv)
    browser = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if browser is None:
        print("no Chromium (apt-get install chromium)", file=sys.stderr)
        return 2
    out = Path(a.out)
    video, calib = out / "video", out / "calib"
    if not (video / "video.y4m").is_file():
        subprocess.run([sys.executable, "-m", "data_gen.video", "--out", str(video), "--seconds", str(a.seconds),
                        "--fps", a.fps, "--size", a.size, "--seed", a.seed, "--board", a.board, "--y4m", "--quiet"],
                       cwd=ROOT, check=True)
    shutil.rmtree(calib, ignore_errors=True)
    server = subprocess.Popen([sys.executable, "-m", "aicalib_tf.live", "--board", a.board, "--port", "0",
                               "--out", str(calib), "--max-views", "8"], cwd=ROOT, stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    url = next((m.group(1) for line in server.stdout if (m := re.search(r"(http://\S+)", line))), None)
    if url is None:
        print(f"the server did not start (exit {server.wait()})", file=sys.stderr)
        return 1
    t0 = time.monotonic()
    chrome = subprocess.Popen([browser, *FLAGS, f"--user-data-dir={out / 'profile'}",
                               f"--use-file-for-fake-video-capture={video / 'video.y4m'}",
                               url + "&autostart=1&autosave=1"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    state = {}
    try:
        while time.monotonic() - t0 < a.wait and not (calib / "camera.json").is_file():
            time.sleep(1.0)
            state = _state(url)
        took = time.monotonic() - t0
        state = _state(url)
    finally:
        chrome.kill()
        server.kill()
    if not (calib / "camera.json").is_file():
        print(f"no calibration saved in {a.wait:.0f} s; last state: {state}")
        return 1
    cam = json.loads((calib / "camera.json").read_text())
    truth = json.loads((video / "labels.jsonl").read_text().splitlines()[0])
    K, Kt = cam["camera_matrix"], truth["K"]
    pp = ((K[0][2] - Kt[0][2]) ** 2 + (K[1][2] - Kt[1][2]) ** 2) ** 0.5
    from aicalib_tf.geometry.aprilgrid import corner_count

    whole = corner_count(a.board) or truth["pattern_size"][0] * truth["pattern_size"][1]  # an AprilGrid's: its tag corners
    partial = sum(1 for v in cam["views"] if v["corners"] < whole)
    print(f"saved {calib / 'camera.json'} after {took:.0f} s: {state.get('frames')} frames from the page, "
          f"{state.get('views')} views kept, {state.get('fps')} frames/s handled; {len(cam['views'])} views used "
          f"({partial} partial), fx error {100 * (K[0][0] / Kt[0][0] - 1):+.3f} %, principal point error {pp:.2f} px, "
          f"model {cam['model']}, board {cam['meta'].get('board')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
