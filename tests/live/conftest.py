"""The live-page test harness: the live server as a child process, its routes, and a headless Chromium whose
fake camera plays a rendered video until the page saves a calibration (``browser_calibration``)."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
LIVE = [sys.executable, "-m", "aicalib_tf.live"]
CHROMIUM_FLAGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--use-fake-ui-for-media-stream", "--use-fake-device-for-media-stream"]


def start_live(args: list[str]) -> tuple[subprocess.Popen, str]:
    """``python -m aicalib_tf.live ARGS`` from the repository root -> (the process, the page address it printed)."""
    proc = subprocess.Popen(LIVE + args, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=dict(os.environ, PYTHONPATH=str(ROOT)))
    for line in proc.stdout:
        m = re.search(r"(http://\S+)", line)
        if m:
            return proc, m.group(1)
    raise AssertionError(f"the server did not start (exit {proc.wait()})")


def route(url: str, path: str) -> str:
    """The printed page address (``http://localhost:PORT/?token=...``) -> one of its routes, with the token."""
    base, _, query = url.partition("?")
    assert query.startswith("token="), url
    return f"{base}{path}?{query}"


def get_json(url: str) -> dict:
    with urllib.request.urlopen(url, timeout=10) as r:
        return json.loads(r.read())


def wait_for(path: Path, seconds: float, procs) -> bool:
    """True once ``path`` exists; False after ``seconds`` or as soon as one of ``procs`` has ended."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if path.exists():
            return True
        if any(p.poll() is not None for p in procs):
            return False
        time.sleep(0.5)
    return False


@pytest.fixture
def browser_calibration(tmp_path):
    """A function ``(server_args, video_y4m, out, seconds) -> state``: starts the live server with
    ``server_args``, opens its page (autostart, autosave) in headless Chromium with ``video_y4m`` as the
    camera, waits up to ``seconds`` for ``out/camera.json``, stops both and returns the server's last
    ``/state`` (dict). Fails when nothing was saved. The test is skipped where Chromium is missing (failed
    under CI, which installs it)."""
    browser = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if browser is None:
        if os.environ.get("CI"):
            pytest.fail("Chromium is not installed: .ci/run installs it (apt-get install chromium)")
        pytest.skip("no Chromium on this machine (apt-get install chromium)")

    def run(server_args: list[str], video_y4m: Path, out: Path, seconds: float) -> dict:
        server, url = start_live(server_args)
        chrome = subprocess.Popen([browser, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'profile'}",
                                   f"--use-file-for-fake-video-capture={video_y4m}", url + "&autostart=1&autosave=1"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            saved = wait_for(out / "camera.json", seconds, [server, chrome])
            state = get_json(route(url, "state"))
        finally:
            chrome.kill()
            server.kill()
        assert saved, f"no calibration saved; last state: {state}"
        return state

    return run
