"""How many frames per second the live page handles from a browser camera.

    python benchmarks/live_fps.py [--video DIR_WITH_video.y4m] [--seconds 30] [--size 640x480] [--fps 30]

Renders a hand-held video (``data_gen.video``, y4m) unless one is given, starts
``python -m aicalib_tf.live`` on a free port, and opens the page in headless Chromium whose fake
camera plays the video (at the y4m's frame rate, looping). The page sends one frame, waits for
its update, sends the next: the rate it reaches is the rate the page shows detections at. Reads
the server's ``/state`` every second and prints the frames handled, the rate over the last 30
frames and the mean over the run, and the per-frame time of the loop. Needs Chromium
(``apt-get install chromium``).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FLAGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--use-fake-ui-for-media-stream", "--use-fake-device-for-media-stream"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--video", default=None, help="a folder holding video.y4m (default: render one)")
    ap.add_argument("--seconds", type=float, default=30.0, help="how long the page runs (default: %(default)s)")
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--fps", default="30")
    a = ap.parse_args()
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        print("error: no Chromium (apt-get install chromium)", file=sys.stderr)
        return 2
    tmp = Path(tempfile.mkdtemp(prefix="live_fps_"))
    video = Path(a.video) if a.video else tmp / "video"
    if not a.video:
        subprocess.run([sys.executable, "-m", "data_gen.video", "--out", str(video), "--seconds", "10", "--fps", a.fps,
                        "--size", a.size, "--y4m", "--quiet"], check=True, cwd=ROOT)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    server = subprocess.Popen([sys.executable, "-m", "aicalib_tf.live", "--pattern", "9x6", "--square", "25mm", "--port", "0",
                               "--out", str(tmp / "calib"), "--max-views", "1000", "--target", "0.0001px"],
                              cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    url = next(m.group(1) for line in server.stdout if (m := re.search(r"(http://\S+)", line)))
    chrome = subprocess.Popen([browser, *FLAGS, f"--user-data-dir={tmp / 'profile'}",
                               f"--use-file-for-fake-video-capture={video / 'video.y4m'}", url + "?autostart=1"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        first = None
        end = time.monotonic() + a.seconds
        while time.monotonic() < end:
            time.sleep(1.0)
            with urllib.request.urlopen(url + "state", timeout=10) as r:
                state = json.loads(r.read())
            if state and first is None:
                first = (time.monotonic(), state["frames"])
            if state:
                print(f"{state['frames']:5d} frames  {state.get('fps')} fps (last 30)  loop {state.get('ms')} ms  "
                      f"{state['views']} views", flush=True)
        if first and state:
            mean = (state["frames"] - first[1]) / (time.monotonic() - first[0])
            print(f"mean over the run: {mean:.1f} frames/s handled ({a.size} at {a.fps} fps from the fake camera)")
    finally:
        chrome.kill()
        server.kill()
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
