"""The live calibration page's server: frames in, the guided loop, updates out, a save on request.

Two ways frames arrive, one loop (:class:`~aicalib_tf.guided.session.GuidedCalibration`) for both:

* **the browser's camera** (``getUserMedia``): the page sends one JPEG frame over the websocket
  and sends the next only when the update for it has come back, taking whatever frame its camera
  shows then. Detection keeps up by skipping frames, never by queueing them;
* **a server-side source** (a video file, a camera index, a stream URL; :mod:`aicalib_tf.sources`):
  a reader thread keeps only the newest frame (a video file plays at its own frame rate), the loop
  takes the newest when it is free, and the page receives each examined frame (JPEG) and its update.

Routes: ``GET /`` the page, ``GET /config`` its settings (JSON), ``GET /ws`` the websocket,
``GET /state`` the last update (JSON), ``POST /save`` the calibration so far into ``--out``
(the files of ``python -m aicalib_tf.calibrate``; JSON ``{"ok", "out", "report"}`` or
``{"ok": false, "error"}``). Every request must name the served address, come from the page
itself, and (all but ``/``) carry the run's token (:mod:`aicalib_tf.live.guard`). The server is
aiohttp; detection and fitting run in one worker thread so that the page stays responsive.

A frame the page sends that cannot be used (empty, not a JPEG or PNG, over
:data:`MAX_FRAME_PIXELS` such as a decompression bomb, under :data:`MIN_FRAME_SIDE`, or of
another size than the first) is answered on the socket with ``{"error", "bad_frames"}`` and
counted; the connection stays open.
When views stop coming the update carries ``stall``, the explanation of
:mod:`aicalib_tf.live.stall` (why, what would help, the verdict Save would keep).
"""

from __future__ import annotations

import asyncio
import functools
import sys
import threading
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from aicalib_tf.calib.coverage import coverage_counts
from aicalib_tf.cnn.spec import DETECTOR_NETWORK

__all__ = ["LiveConfig", "LiveState", "make_app", "token_of", "update_json", "tracking_detector", "COVERAGE_CELLS"]

COVERAGE_CELLS = (8, 6)  # the coverage map the page draws (cols, rows)
PAGE = Path(__file__).with_name("page.html")
MAX_FRAME_BYTES = 8 << 20  # a websocket frame larger than this is refused (answered, counted)
MAX_MESSAGE_BYTES = 4 * MAX_FRAME_BYTES  # a websocket message larger than this closes the connection (code 1009)
MAX_FRAME_PIXELS = 7680 * 4320  # a frame larger than 8K UHD is refused before it is decoded
MIN_FRAME_SIDE = 32  # a frame narrower or lower than this (px) cannot show a board: refused
MAX_PACE_S = 1.0  # the longest wait for a file's next frame (a frame rate is at least 1 fps)
JPEG_QUALITY = 80  # frames sent to the page
FPS_WINDOW = 30  # frames over which the handled frame rate is measured


@dataclass(frozen=True)
class LiveConfig:
    """The page's settings. source : None (the browser's camera) or a video path, camera index or URL."""

    pattern: tuple[int, int]
    square: float = 1.0
    square_unit: str = ""
    out: str = "calib"
    source: str | None = None
    detector: str = "cnn"
    network: str = DETECTOR_NETWORK
    model: str = "auto"
    target_px: float = 0.1
    max_views: int = 40
    board: str | None = None  # a ChArUco board or an AprilGrid (pattern and square follow from it); None: a chessboard


def _finite(x):
    """A float for JSON, None when not finite (strict JSON has no NaN)."""
    x = float(x)
    return x if np.isfinite(x) else None


def corner_labels(cfg: LiveConfig):
    """What the page writes beside a marker board's corners: ``(N, 2) ids -> [int] * N``, a ChArUco
    corner's id (row·cols + col, OpenCV's) or the id of the AprilGrid tag the corner belongs to (the page
    writes it once, at the tag's corners' centre); None for a chessboard (its ids are relative)."""
    if not cfg.board:
        return None
    from aicalib_tf.geometry.aprilgrid import AprilGrid, is_aprilgrid, load_board

    if is_aprilgrid(cfg.board):
        grid = load_board(cfg.board)
        return (lambda ids: [int(k) for k in grid.tag_of(ids)]) if isinstance(grid, AprilGrid) else None
    cols = int(cfg.pattern[0])
    return lambda ids: [int(c + r * cols) for c, r in np.asarray(ids, np.int64).reshape(-1, 2)]


def update_json(update, session, *, labels=None) -> dict:
    """One update as the page reads it (strict JSON; no NaN); ``labels``: :func:`corner_labels`' function,
    which adds the marker board's ``ids``, one a corner."""
    est = update.estimate
    size = session.image_size or (1, 1)
    cover = coverage_counts(session.views, size, COVERAGE_CELLS) if session.views else np.zeros(COVERAGE_CELLS[::-1])
    return {
        "index": int(update.index), "examined": bool(update.examined), "kept": bool(update.kept),
        "reason": update.reason, "done": bool(update.done), "image_size": list(size),
        "corners": [] if update.corners is None else np.round(np.asarray(update.corners), 2).tolist(),
        "guidance": update.guidance.text if update.guidance is not None else None,
        "missing": list(update.missing),
        "estimate": None if est is None else {
            "model": est.model, "fx": _finite(est.K[0, 0]), "fy": _finite(est.K[1, 1]), "cx": _finite(est.K[0, 2]),
            "cy": _finite(est.K[1, 2]), "rms": _finite(est.rms), "views": int(est.views),
            "sigma_px": _finite(est.sigma_px), "covered": _finite(est.covered)},
        "coverage": cover.astype(int).tolist(),
        "frames": int(session.frames_seen), "examined_frames": int(session.examined), "views": len(session.views),
        "target_px": _finite(session.cfg.target_px),
        **({"ids": labels(update.ids)} if labels is not None and update.ids is not None else {}),
    }


def tracking_detector(pattern: tuple[int, int], network: str, base):
    """The guided loop's detector for a stream: a :class:`~aicalib_tf.detect.track.Tracker`, which
    refines the last board's corners where they moved to before it runs the network, and searches
    near the last board before the whole frame. ``base`` (:func:`aicalib_tf.calib.workflow.make_detector`'s
    CNN detector) gives the model's ``info``. Same interface: (H, W) uint8 -> (corners, ids) or None."""
    from aicalib_tf.cnn.model import load_model
    from aicalib_tf.detect.track import Tracker

    tracker = Tracker(tuple(pattern), model=load_model(network))

    def detect(gray):
        det = tracker(gray)
        detect.why, detect.relative, detect.sigmas = det.reason, det.relative, det.sigmas  # σ weigh the live fits
        return (det.corners, det.ids) if len(det.corners) else None

    detect.info, detect.why, detect.relative, detect.sigmas = base.info, "", False, None
    return detect


class LiveState:
    """The loop and what the page needs of it; one per server. ``detector`` as for the guided loop."""

    def __init__(self, cfg: LiveConfig, detector, clock=time.monotonic):
        from aicalib_tf.guided.session import GuidedCalibration, GuidedConfig
        from aicalib_tf.live.stall import StallWatch

        self.cfg, self.clock = cfg, clock  # clock: () -> s, for the stall rule
        self.detector = detector
        self.labels = corner_labels(cfg)
        self.session = GuidedCalibration(GuidedConfig(cfg.pattern, cfg.square, cfg.square_unit, cfg.model,
                                                      cfg.target_px, cfg.max_views, gate=False), detector)
        self.watch = StallWatch(cfg.target_px)
        self.last: dict = {}
        self.index, self.bad_frames = 0, 0
        self.times: deque = deque(maxlen=FPS_WINDOW)  # when the last frames were handled (monotonic s)
        self.lock = threading.Lock()  # the session is used from the worker thread only; saves take it too

    def add_gray(self, gray: np.ndarray) -> dict:
        """Run one (H, W) uint8 frame through the loop; returns its update as JSON-able dict."""
        with self.lock:
            t = time.monotonic()
            update = self.session.add((self.index, t, gray))
            self.index += 1
            self.last = update_json(update, self.session, labels=self.labels)
            self.last["stall"] = self.watch.note(update, len(self.session.views), self.clock())
            self.last["bad_frames"] = self.bad_frames
            now = time.monotonic()
            self.times.append(now)
            span = now - self.times[0]
            self.last["ms"] = round((now - t) * 1000, 1)
            self.last["fps"] = round((len(self.times) - 1) / span, 1) if span > 0 else None
        return self.last

    def add_jpeg(self, data: bytes) -> dict:
        """Decode one frame the page sent (JPEG or PNG bytes) and run it; ValueError when it cannot be used
        (module docstring), counted in ``bad_frames``."""
        try:
            gray = _decode_frame(data)
        except (ValueError, cv2.error) as exc:
            self.bad_frames += 1
            raise ValueError(str(exc) if isinstance(exc, ValueError) else "the frame could not be decoded") from None
        try:
            return self.add_gray(gray)
        except Exception:  # a frame of another size than the first, or a fault: counted, then reported
            self.bad_frames += 1
            raise

    def save(self) -> tuple[str, str]:
        """Calibrate the kept views and write the files into ``cfg.out``; returns (out, report)."""
        from aicalib_tf.guided.save import save_session
        from aicalib_tf.sources import source_name

        meta = {"source": source_name(self.cfg.source or "browser camera"), "detector": self.cfg.detector,
                "model": self.detector.info.get("model"), "model_sha256": self.detector.info.get("sha256"),
                "lens_model": self.cfg.model, "frames": self.session.frames_seen, "examined": self.session.examined,
                "kept_frames": self.session.kept_frames, "target_px": self.cfg.target_px, "live": True,
                **({"board": self.cfg.board} if self.cfg.board else {})}
        with self.lock:
            report = save_session(self.session, self.cfg.out, meta, head=[f"live page: {meta['source']}"])
        return self.cfg.out, report


def _decode_frame(data: bytes) -> np.ndarray:
    """A frame the page sent (JPEG or PNG bytes) -> (H, W) uint8 grey; ValueError (or cv2.error) when it cannot be used."""
    from aicalib_tf.io import image_size_from_header, quantize, to_gray_float

    if not data:
        raise ValueError("the page sent an empty frame")
    if len(data) > MAX_FRAME_BYTES:
        raise ValueError(f"frame of {len(data)} bytes is larger than {MAX_FRAME_BYTES}")
    size = image_size_from_header(data)
    if size is not None and size[0] * size[1] > MAX_FRAME_PIXELS:
        raise ValueError(f"frame of {size[0]}x{size[1]} px is larger than {MAX_FRAME_PIXELS / 1e6:.0f} MP")
    buf = np.frombuffer(data, np.uint8)
    if data[:3] == b"\xff\xd8\xff":  # JPEG (8-bit): decoding its luma alone is about 4x faster at 720p
        gray = _quiet(cv2.imdecode, buf, cv2.IMREAD_GRAYSCALE)
        if gray is not None:
            return _big_enough(gray)
    img = _quiet(cv2.imdecode, buf, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError("the page sent a frame that is not a JPEG or PNG image")
    return _big_enough(quantize(to_gray_float(img, "frame")))


def _big_enough(gray: np.ndarray) -> np.ndarray:
    if min(gray.shape[:2]) < MIN_FRAME_SIDE:
        raise ValueError(f"frame of {gray.shape[1]}x{gray.shape[0]} px is too small for a board "
                         f"(at least {MIN_FRAME_SIDE} px each way)")
    return gray


def _quiet(fn, *args):
    """``fn(*args)`` with OpenCV's own log lines off (a broken frame is reported once, on the page)."""
    from aicalib_tf.sources import _quiet_capture

    return _quiet_capture(lambda: fn(*args))


def _paced(source, stop: threading.Event):
    """Frames of ``source`` as a camera would give them: a file plays at its frame rate, and a frame
    whose time has passed while the loop was busy is dropped (counted), so the loop never lags."""
    start = time.monotonic()
    for frame in source:
        if stop.is_set():
            return
        if source.live or not source.fps:
            yield frame
            continue
        ahead = frame.time_s - (time.monotonic() - start)
        if ahead < -1.0 / source.fps:
            source.dropped += 1
            continue
        if ahead > 0:
            time.sleep(min(ahead, MAX_PACE_S))
        yield frame


def _source_thread(state: LiveState, loop: asyncio.AbstractEventLoop, queue: asyncio.Queue, stop: threading.Event):
    """Read the server-side source; run its newest frame whenever the loop is free; push (jpeg, update)."""
    from aicalib_tf.sources import open_source

    try:
        with open_source(state.cfg.source) as source:
            for frame in _paced(source, stop):
                update = dict(state.add_gray(frame.gray), dropped=int(source.dropped))
                ok, jpg = cv2.imencode(".jpg", frame.gray, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
                loop.call_soon_threadsafe(_offer, queue, (jpg.tobytes() if ok else b"", update))
        loop.call_soon_threadsafe(_offer, queue, (b"", dict(state.last, ended=True)))
    except Exception as exc:  # noqa: BLE001 - reported on the page and the console, one line
        from aicalib_tf.cli import describe_error
        from aicalib_tf.sources import source_name

        why = describe_error(exc)
        name = source_name(state.cfg.source)
        loop.call_soon_threadsafe(_offer, queue, (b"", {"error": why if why.startswith(name) else f"{name}: {why}"}))


def _offer(queue: asyncio.Queue, item) -> None:
    """Put ``item``, dropping the oldest when the page is behind (never a growing queue)."""
    while queue.full():
        queue.get_nowait()
    queue.put_nowait(item)


class _Routes:
    """The page's request handlers over one :class:`LiveState` (one worker thread runs the loop)."""

    def __init__(self, state: LiveState):
        self.state = state
        self.executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="aicalib-live")
        self.stop = threading.Event()
        self.listeners: set = set()

    async def _in_worker(self, fn, *args):
        return await asyncio.get_running_loop().run_in_executor(self.executor, fn, *args)

    async def page(self, _request):
        from aiohttp import web

        return web.FileResponse(PAGE)

    async def config(self, _request):
        from aiohttp import web

        cfg = self.state.cfg
        return web.json_response({"mode": "server" if cfg.source else "browser", "pattern": list(cfg.pattern),
                                  "board": cfg.board, "target_px": cfg.target_px, "max_views": cfg.max_views, "out": cfg.out})

    async def last(self, _request):
        from aiohttp import web

        return web.json_response(self.state.last, dumps=_strict_dumps)

    async def save(self, _request):
        from aiohttp import web

        from aicalib_tf.cli import describe_error

        try:
            out, report = await self._in_worker(self.state.save)
        except Exception as exc:  # noqa: BLE001 - the page and the console show the reason
            print(f"not saved: {describe_error(exc)}", file=sys.stderr, flush=True)
            return web.json_response({"ok": False, "error": describe_error(exc)})
        print(f"saved the calibration into {out}", flush=True)
        return web.json_response({"ok": True, "out": out, "report": report})

    async def socket(self, request):
        """The browser's frames in (binary JPEG), one update out per frame (JSON)."""
        from aiohttp import WSMsgType, web

        ws = web.WebSocketResponse(max_msg_size=MAX_MESSAGE_BYTES)
        await ws.prepare(request)
        self.listeners.add(ws)
        try:
            async for msg in ws:
                if msg.type != WSMsgType.BINARY or self.state.cfg.source:
                    continue
                try:
                    update = await self._in_worker(self.state.add_jpeg, msg.data)
                except Exception as exc:  # noqa: BLE001 - a bad frame never ends the connection
                    update = {"error": _frame_error(exc), "bad_frames": self.state.bad_frames}
                await ws.send_str(_strict_dumps(update))
        finally:
            self.listeners.discard(ws)
        return ws

    async def start_source(self, app) -> None:
        """With a server-side source: its reader thread, and a task forwarding frames and updates to the pages."""
        if not self.state.cfg.source:
            return
        queue: asyncio.Queue = asyncio.Queue(maxsize=2)
        threading.Thread(target=_source_thread, args=(self.state, asyncio.get_running_loop(), queue, self.stop),
                         daemon=True).start()

        async def forward():
            while True:
                jpg, update = await queue.get()
                for ws in list(self.listeners):
                    if jpg:
                        await ws.send_bytes(jpg)
                    await ws.send_str(_strict_dumps(update))
        app["pump"] = asyncio.get_running_loop().create_task(forward())

    async def cleanup(self, app) -> None:
        self.stop.set()
        if "pump" in app:
            app["pump"].cancel()
        self.executor.shutdown(wait=False, cancel_futures=True)


def _frame_error(exc: BaseException) -> str:
    """The page's line for a frame that failed: the reason of an expected error, else one console line too."""
    from aicalib_tf.cli import describe_error

    if isinstance(exc, ValueError):
        return describe_error(exc)
    line = f"frame not used: unexpected {type(exc).__name__}: {describe_error(exc)}"
    print(line, file=sys.stderr, flush=True)
    return line


def _strict_dumps(obj) -> str:
    from aicalib_tf.jsonio import dumps

    return dumps(obj, indent=None)


@functools.cache
def _token_key():
    from aiohttp import web

    return web.AppKey("token", str)


def token_of(app) -> str:
    """The token the application of :func:`make_app` requires."""
    return app[_token_key()]


def make_app(state: LiveState, *, token: str | None = None, host: str = "127.0.0.1"):
    """The aiohttp application serving the page for ``state`` (routes in the module docstring), to be
    bound to ``host``, that requires the run's token (``token``, or a new random one; :func:`token_of`)
    in the page's address (:mod:`aicalib_tf.live.guard`)."""
    from aiohttp import web

    from aicalib_tf.live.guard import guard_middleware, new_token

    token = token or new_token()
    routes = _Routes(state)
    app = web.Application(client_max_size=MAX_FRAME_BYTES, middlewares=[guard_middleware(token, host)])
    app[_token_key()] = token
    app.router.add_get("/", routes.page)
    app.router.add_get("/config", routes.config)
    app.router.add_get("/state", routes.last)
    app.router.add_post("/save", routes.save)
    app.router.add_get("/ws", routes.socket)
    app.on_startup.append(routes.start_source)
    app.on_cleanup.append(routes.cleanup)
    return app
