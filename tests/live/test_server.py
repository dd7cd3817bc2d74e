"""The live server in process (aiohttp's test client): who may reach it (Host, Origin, token), bad
frames on the websocket, the stall explanation in the state, and Save beside the user's files."""

from __future__ import annotations

import asyncio
import json
import zlib
import struct

import cv2
import numpy as np
import pytest

from aicalib_tf.live.server import MAX_FRAME_BYTES, LiveConfig, LiveState, make_app
from aicalib_tf.live.stall import STALL_S
from aicalib_tf.outfolder import OutputFolder

TOKEN = "test-token-0123456789"
K = np.array([[600.0, 0, 319.5], [0, 600.0, 239.5], [0, 0, 1]])
IDS = np.stack(np.meshgrid(np.arange(9), np.arange(6)), -1).reshape(-1, 2)


def _project(rvec_deg, tvec, rng) -> np.ndarray:
    board = np.concatenate([IDS * 25.0 - [100.0, 62.5], np.zeros((54, 1))], axis=1)
    px = cv2.projectPoints(board, np.radians(rvec_deg), np.asarray(tvec, float), K, None)[0].reshape(-1, 2)
    return px + rng.normal(0.0, 0.1, px.shape)  # a detector's noise


def _poses(n: int) -> list[np.ndarray]:
    """Corners (54, 2) px of a 9x6 board (25 mm squares) in ``n`` distinct poses seen by a 640x480 camera."""
    rng = np.random.default_rng(4)
    out = []
    while len(out) < n:
        px = _project(rng.uniform([-35, -35, -20], [35, 35, 20]),
                      [rng.uniform(-90, 90), rng.uniform(-60, 60), rng.uniform(450, 650)], rng)
        if px.min() > 8 and px[:, 0].max() < 632 and px[:, 1].max() < 472:
            out.append(px)
    return out


def _corner_poses() -> list[np.ndarray]:
    """Small boards in the image's four corners (new image cells for any path of :func:`_poses`)."""
    rng = np.random.default_rng(5)
    return [_project([sy * 25, -sx * 25, 0], [sx * 330, sy * 230, 1100], rng) for sx in (-1, 1) for sy in (-1, 1)]


class _Looped:
    """A detector that sees the board of ``poses`` in turn, then again from the start: a looped video's path."""

    relative = False
    info: dict = {}

    def __init__(self, poses):
        self.poses, self.k = poses, 0

    def __call__(self, gray):
        px = self.poses[self.k % len(self.poses)]
        self.k += 1
        return px, IDS


class _Clock:
    def __init__(self, step):
        self.t, self.step = 0.0, step

    def __call__(self):
        self.t += self.step
        return self.t


def _state(tmp_path, detector=None, clock=None, **cfg) -> LiveState:
    det = detector or _Looped(_poses(10))
    return LiveState(LiveConfig((9, 6), square=25.0, square_unit="mm", out=str(tmp_path / "calib"),
                                model="plumb_bob", **cfg), det, **({"clock": clock} if clock else {}))


def _serve(state, body):
    """Run ``body(client, port)`` against the app of ``state`` bound to 127.0.0.1."""
    from aiohttp.test_utils import TestClient, TestServer

    async def main():
        async with TestClient(TestServer(make_app(state, token=TOKEN), host="127.0.0.1")) as client:
            return await body(client, client.server.port)

    return asyncio.run(main())


def test_requests_must_name_this_server_come_from_its_page_and_carry_the_token(tmp_path):
    state = _state(tmp_path)

    async def body(c, port):
        async def status(method, path, **headers):
            async with c.request(method, path, headers=headers) as r:
                return r.status

        here = f"127.0.0.1:{port}"
        got = {
            "page": await status("GET", "/"),
            "page via localhost": await status("GET", "/", Host=f"localhost:{port}"),
            "page via [::1]": await status("GET", "/", Host=f"[::1]:{port}"),
            "rebound page": await status("GET", "/", Host=f"evil.example:{port}"),
            "rebound state": await status("GET", f"/state?token={TOKEN}", Host=f"evil.example:{port}"),
            "other port": await status("GET", "/", Host="127.0.0.1:1"),
            "no port": await status("GET", "/", Host="localhost"),
            "state": await status("GET", f"/state?token={TOKEN}"),
            "state by header": await status("GET", "/state", **{"X-Aicalib-Token": TOKEN}),
            "state without token": await status("GET", "/state"),
            "state, wrong token": await status("GET", "/state?token=guess"),
            "config without token": await status("GET", "/config"),
            "save without token": await status("POST", "/save", Origin=f"http://{here}"),
            "save from evil": await status("POST", f"/save?token={TOKEN}", Origin="http://evil.example"),
            "save from null": await status("POST", f"/save?token={TOKEN}", Origin="null"),
            "save from https page": await status("POST", f"/save?token={TOKEN}", Origin=f"https://{here}"),
            "save from the page": await status("POST", f"/save?token={TOKEN}", Origin=f"http://localhost:{port}"),
        }
        return got

    got = _serve(state, body)
    ok = {"page", "page via localhost", "page via [::1]", "state", "state by header", "save from the page"}
    assert {k for k, v in got.items() if v == 200} == ok, got
    assert all(v == 403 for k, v in got.items() if k not in ok), got
    assert not (tmp_path / "calib").exists()  # the refused saves wrote nothing (the allowed one: too few views)


def test_a_websocket_from_another_site_or_without_the_token_is_refused(tmp_path):
    from aiohttp import WSServerHandshakeError

    state = _state(tmp_path)
    jpeg = cv2.imencode(".jpg", np.zeros((480, 640), np.uint8))[1].tobytes()

    async def body(c, port):
        refused = []
        for path, origin in ((f"/ws?token={TOKEN}", "http://evil.example"), ("/ws", f"http://127.0.0.1:{port}"),
                             (f"/ws?token={TOKEN}", f"http://127.0.0.1:{port + 1}")):
            with pytest.raises(WSServerHandshakeError) as exc:
                await c.ws_connect(path, headers={"Origin": origin})
            refused.append(exc.value.status)
        async with c.ws_connect(f"/ws?token={TOKEN}", headers={"Origin": f"http://localhost:{port}"}) as ws:
            await ws.send_bytes(jpeg)
            update = json.loads(await ws.receive_str(timeout=30))
        return refused, update

    refused, update = _serve(state, body)
    assert refused == [403, 403, 403] and update["frames"] == 1 and state.session.frames_seen == 1


def _png_bomb(side: int = 10000) -> bytes:
    """A valid PNG of side x side black grey pixels, about 100 kB: a decompression bomb."""
    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    z, row = zlib.compressobj(9), b"\0" * (side + 1)
    idat = b"".join(z.compress(row) for _ in range(side)) + z.flush()
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", side, side, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", idat) + chunk(b"IEND", b""))


def test_bad_frames_are_answered_counted_and_keep_the_connection(tmp_path, capfd):
    state = _state(tmp_path)
    good = cv2.imencode(".jpg", np.zeros((480, 640), np.uint8))[1].tobytes()
    small = cv2.imencode(".png", np.zeros((100, 80), np.uint8))[1].tobytes()
    bad = [b"", _png_bomb(), b"\xff\xd8\xff" + b"junk" * 10, b"\x89PNG\r\n\x1a\n" + b"\0" * 50, small,
           b"\0" * (MAX_FRAME_BYTES + 1), cv2.imencode(".png", np.zeros((1, 1), np.uint8))[1].tobytes()]

    async def body(c, port):
        replies = []
        async with c.ws_connect(f"/ws?token={TOKEN}") as ws:
            for data in [good, *bad, good]:
                await ws.send_bytes(data)
                replies.append(json.loads(await ws.receive_str(timeout=30)))
        async with c.get(f"/state?token={TOKEN}") as r:
            return replies, await r.json()

    replies, last = _serve(state, body)
    errors = [r.get("error") for r in replies]
    assert errors[0] is None and errors[-1] is None and all(errors[1:-1]), errors
    assert "empty" in errors[1] and "10000x10000" in errors[2] and "640x480" in errors[5], errors
    assert "larger than" in errors[6] and "1x1 px is too small" in errors[7], errors
    assert [r["bad_frames"] for r in replies[1:-1]] == [1, 2, 3, 4, 5, 6, 7] and last["bad_frames"] == 7
    assert last["frames"] == 3  # the frame of another size was seen, then refused
    err = capfd.readouterr().err
    assert "Traceback" not in err and "ERROR" not in err, err


def test_a_looped_path_stalls_and_the_state_says_why_what_helps_and_the_verdict(tmp_path):
    poses = _poses(10)
    state = _state(tmp_path, _Looped(poses), _Clock(1.0), target_px=1e-4)  # a target the path cannot reach
    gray = np.zeros((480, 640), np.uint8)
    for _ in range(len(poses)):
        state.add_gray(gray)
    assert state.last["stall"] is None and state.last["views"] >= 5 and state.last["estimate"]
    stalls = [state.add_gray(gray)["stall"] for _ in range(int(STALL_S) + 5)]  # the same path again
    first = next(k for k, s in enumerate(stalls) if s is not None)
    assert stalls[first]["seconds"] == STALL_S and all(stalls[first:])  # 30 s after the last kept view, and on
    stall = stalls[-1]
    assert stall["reason"] == "near-duplicate" and stall["why"].startswith("no new poses for 3")
    assert "the path repeats" in stall["why"] and stall["help"].startswith("try: hold the board at the ")
    assert stall["verdict"].startswith("uncertainty ") and "Save keeps this calibration" in stall["verdict"]
    assert stall["can_save"] is True

    async def body(c, port):
        async with c.get(f"/state?token={TOKEN}") as r:
            return await r.json()

    assert _serve(state, body)["stall"] == stall  # what the page reads
    state.detector.poses = _corner_poses()  # new poses: a view is kept, the stall ends
    updates = [state.add_gray(gray) for _ in range(6)]
    kept = next(k for k, u in enumerate(updates) if u["kept"])
    assert all(u["stall"] is None for u in updates[kept:])


def test_stall_reasons_other_than_a_repeated_path():
    from types import SimpleNamespace

    from aicalib_tf.live.stall import StallWatch

    def run(reason, n=40):
        watch = StallWatch(0.1)
        out = None
        for t in range(n):
            out = watch.note(SimpleNamespace(kept=False, done=False, reason=reason, estimate=None, missing=(),
                                             guidance=None), 2, float(t))
        return out

    assert run("no board")["why"] == "no board seen for 39 s" and "into view" in run("no board")["help"]
    assert run("blurred (edges 4.0 px wide, typical 1.3 px)")["help"] == "move the board more slowly, or add light"
    assert run("no board")["can_save"] is False and run("no board")["verdict"] == "no fit yet (2 views kept)"
    assert run("no board", n=20) is None  # not yet 30 s
    watch = StallWatch(0.1)
    unknown = SimpleNamespace(kept=False, done=False, reason="adds little (predicted uncertainty -0.0%)", missing=(),
                              estimate=SimpleNamespace(sigma_px=float("inf")), guidance=None)
    out = [watch.note(unknown, 6, float(t)) for t in range(40)][-1]
    assert out["verdict"].startswith("uncertainty not known yet") and out["help"] == "show the board in other places and tilts"


def test_save_keeps_the_users_files_in_the_out_folder(tmp_path):
    poses = _poses(10)
    state = _state(tmp_path, _Looped(poses))
    for _ in range(len(poses)):
        state.add_gray(np.zeros((480, 640), np.uint8))
    out = tmp_path / "calib"
    with OutputFolder(out, "calibration") as folder:  # as an earlier Save left it
        (folder.path / "camera.json").write_text("{}")
    (out / "notes.txt").write_text("tripod at 1.2 m")
    assert state.save()[0] == str(out)
    assert (out / "notes.txt").read_text() == "tripod at 1.2 m"
    assert json.loads((out / "camera.json").read_text())["meta"]["source"] == "browser camera"


@pytest.mark.parametrize("bind, host, local, ok", [
    ("127.0.0.1", "127.0.0.1:8765", ("127.0.0.1", 8765), True),
    ("127.0.0.1", "LOCALHOST:8765", ("127.0.0.1", 8765), True),
    ("::1", "[::1]:8765", ("::1", 8765, 0, 0), True),
    ("0.0.0.0", "192.168.1.20:8765", ("192.168.1.20", 8765), True),  # a phone on the network
    ("0.0.0.0", "192.168.1.21:8765", ("192.168.1.20", 8765), False),
    ("cam-pc.local", "cam-pc.local:8765", ("192.168.1.20", 8765), True),
    ("127.0.0.1", "attacker.example:8765", ("127.0.0.1", 8765), False),
    ("127.0.0.1", "127.0.0.1.attacker.example:8765", ("127.0.0.1", 8765), False),
    ("127.0.0.1", "127.0.0.1:8765@evil", ("127.0.0.1", 8765), False),
    ("127.0.0.1", "[::1", ("127.0.0.1", 8765), False),
    ("127.0.0.1", "", ("127.0.0.1", 8765), False),
])
def test_the_host_rule(bind, host, local, ok):
    from aicalib_tf.live.guard import refusal

    why = refusal("/", {"Host": host}, {}, token=TOKEN, bind_host=bind, local=local)
    assert (why is None) == ok, why


CHARUCO = "charuco:6x5,square=30mm,marker=20mm,dict=DICT_4X4_50"


def _charuco_frame(cut: int) -> tuple[np.ndarray, dict]:
    """A 640x480 frame of the board of :data:`CHARUCO` (54 px squares, at (60, 60)) with its ``cut`` left
    px hidden, and {OpenCV corner id: (x, y) px} of the inner corners left in view."""
    from aicalib_tf.geometry.charuco import layout_image, parse_board

    board, p, at = parse_board(CHARUCO), 54, 60
    frame = np.full((480, 640), 140, np.uint8)
    img = layout_image(board, p, margin_px=p // 2)
    frame[at - p // 2: at - p // 2 + img.shape[0], at - p // 2: at - p // 2 + img.shape[1]] = img
    frame[:, :cut] = 140
    frame = cv2.GaussianBlur(frame, (0, 0), 0.8)
    cols, rows = board.pattern_size
    truth = {r * cols + c: (at + (c + 1) * p - 0.5, at + (r + 1) * p - 0.5) for r in range(rows) for c in range(cols)}
    return frame, {k: xy for k, xy in truth.items() if xy[0] > cut}


def test_a_charuco_board_runs_the_loop_and_the_page_gets_corner_ids(tmp_path):
    from aicalib_tf.calib.workflow import make_detector
    from aicalib_tf.geometry.charuco import parse_board

    board = parse_board(CHARUCO)
    state = LiveState(LiveConfig(board.pattern_size, 30.0, "mm", out=str(tmp_path / "calib"), model="plumb_bob",
                                 board=CHARUCO), make_detector("cnn", board))
    for cut in (0, 140):  # the whole board, then a board cut by the frame's left edge: its ids name the corners
        frame, truth = _charuco_frame(cut)
        update = state.add_gray(frame)
        assert update["examined"] and len(update["ids"]) == len(update["corners"]) == len(truth), (cut, update)
        got = dict(zip(update["ids"], update["corners"]))
        assert set(got) == set(truth)
        assert max(np.hypot(*(np.subtract(got[k], truth[k]))) for k in truth) < 0.5
    assert state.session.views and json.loads(json.dumps(state.last))["ids"]

    async def body(c, _port):
        async with c.get(f"/config?token={TOKEN}") as r:
            return await r.json()

    assert _serve(state, body)["board"] == CHARUCO
    chess = _state(tmp_path)  # a chessboard's ids are relative to the visible grid: not sent
    assert "ids" not in chess.add_gray(np.zeros((480, 640), np.uint8))


def test_the_live_command_takes_a_board_or_a_pattern(tmp_path, capsys):
    from aicalib_tf.live.__main__ import _config, _parse_args, main

    cfg = _config(_parse_args(["--board", CHARUCO, "--out", str(tmp_path / "o")]))
    assert cfg.board == CHARUCO and cfg.pattern == (5, 4) and cfg.square == 30.0 and cfg.square_unit == "mm"
    for args, why in ((["--board", CHARUCO, "--pattern", "9x6"], "not both"), ([], "give --pattern"),
                      (["--board", "charuco:6x5,square=30mm,marker=20mm,dict=DICT_NOPE"], "DICT_NOPE")):
        assert main(args + ["--out", str(tmp_path / "o"), "--port", "0"]) == 2
        err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
        assert len(err) == 1 and why in err[0], err


def test_the_tracking_detector_hands_each_corners_sigma_to_the_guided_loop():
    """The live page's calibrations weigh corners as every other fit does: the detector keeps their σ."""
    from aicalib_tf.calib.workflow import DETECTOR_NETWORK, make_detector
    from aicalib_tf.detect.warm import synthetic_board
    from aicalib_tf.live.server import tracking_detector

    detect = tracking_detector((9, 6), DETECTOR_NETWORK, make_detector("cnn", (9, 6)))
    assert detect.sigmas is None
    corners, _ = detect(synthetic_board((9, 6), square=30))
    assert detect.sigmas is not None and len(detect.sigmas) == len(corners) and np.all(detect.sigmas > 0)
    assert detect(np.full((480, 640), 128, np.uint8)) is None and detect.sigmas is None
