"""One frame iterator for every source: a video file, an image sequence, a camera or a stream.

:func:`open_source` turns what the user typed into a :class:`FrameSource`; iterating it yields
:class:`Frame` (index, timestamp_s, grey uint8 (H, W)):

* a video file (anything ``cv2.VideoCapture`` decodes): every frame in order, the timestamp from
  the container (or index / fps);
* an image sequence (a folder, a glob, or a list of files; read through
  :func:`aicalib_tf.io.load_image`): one frame per file, timestamp index / ``fps``; an unreadable
  file is skipped and counted (``skipped``), never silently;
* a camera (``0``, ``1``, ...) or a stream URL (``rtsp://``, ``http://``, ...): a live source. A
  reader thread keeps only the newest frame, so a slow consumer drops frames instead of falling
  behind; ``dropped`` counts them. A camera that cannot be opened, or a stream that stops giving
  frames, is an :class:`OSError` naming the source. A URL's password is never printed:
  ``name`` (and every message) shows ``rtsp://user:***@host/`` (:func:`source_name`).

A frame rate outside :data:`FPS_RANGE` (a container claiming 0.001 fps) is taken as unknown
(``fps`` None): frames are then timed by their index and never paced by that rate.

:func:`pair_frames` pairs two cameras' frames (by index, or by timestamp within a tolerance) for
a rig, reports the unpaired ones, and refuses streams that drift out of sync. Errors name the
source, for :func:`aicalib_tf.cli.run_main`'s one line.
"""

from __future__ import annotations

import errno
import os
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

import cv2
import numpy as np

from aicalib_tf.io import IMAGE_SUFFIXES, redact_credentials

__all__ = ["Frame", "FrameSource", "VideoFile", "ImageSequence", "LiveSource", "open_source", "is_video",
           "pair_frames", "Pairing", "is_stream", "source_name", "plausible_fps", "VIDEO_EXTENSIONS", "IMAGE_EXTENSIONS",
           "FPS_RANGE"]

VIDEO_EXTENSIONS = (".mp4", ".avi", ".mov", ".mkv", ".m4v", ".webm", ".y4m", ".mpg", ".mpeg", ".wmv", ".mjpeg",
                    ".mjpg", ".ts", ".flv", ".3gp")
IMAGE_EXTENSIONS = IMAGE_SUFFIXES  # the image gate's: a file of these is never taken for a video
_STREAM_PREFIXES = ("rtsp://", "rtmp://", "http://", "https://", "udp://", "tcp://", "srt://")
FPS_RANGE = (1.0, 240.0)  # a frame rate a source claims outside this is taken as unknown


def plausible_fps(fps) -> float | None:
    """A frame rate a container or device reports, or None when it is outside :data:`FPS_RANGE` (or
    not a number): a video that claims 0.001 fps would otherwise be paced at 1000 s a frame."""
    try:
        value = float(fps or 0.0)
    except (TypeError, ValueError):
        return None
    return value if FPS_RANGE[0] <= value <= FPS_RANGE[1] else None


def source_name(spec) -> str:
    """What the user typed, as it may be printed or written: a camera index as ``camera N``, a URL
    without its password (``rtsp://user:***@host/``)."""
    return f"camera {spec}" if isinstance(spec, int) else redact_credentials(str(spec))


@dataclass(frozen=True)
class Frame:
    """index : frame number in the source (live sources skip the numbers they dropped).
    time_s : seconds from the source's start. gray : (H, W) uint8."""

    index: int
    time_s: float
    gray: np.ndarray


def _quiet_capture(open_capture: Callable):
    """Open a capture with OpenCV's and FFmpeg's own log lines silenced (errors reach the user as ours)."""
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")  # read when FFmpeg is first used
    log = getattr(getattr(cv2, "utils", None), "logging", None)
    level = log.getLogLevel() if log else None
    if log:
        log.setLogLevel(log.LOG_LEVEL_SILENT)
    try:
        return open_capture()
    finally:
        if log:
            log.setLogLevel(level)


def _gray(img: np.ndarray) -> np.ndarray:
    """A decoded frame (H, W) or (H, W, 3|4) uint8/uint16 -> (H, W) uint8 grey."""
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    if img.dtype == np.uint16:
        img = (img >> 8).astype(np.uint8)
    return np.ascontiguousarray(img, dtype=np.uint8)


class FrameSource:
    """What every source has: ``name`` (for messages), ``live``, ``fps`` (None when unknown),
    ``count`` (frames, None when unknown), ``dropped`` and ``skipped`` counters; iterate for
    :class:`Frame`; :meth:`close` (also a context manager)."""

    name: str = ""
    live: bool = False
    fps: float | None = None
    count: int | None = None
    dropped: int = 0
    skipped: int = 0

    def __iter__(self) -> Iterator[Frame]:
        raise NotImplementedError

    def close(self) -> None:
        """Release the device or file."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class VideoFile(FrameSource):
    """Every frame of a video file in order (``cv2.VideoCapture``).

    Raises FileNotFoundError for a missing file and ValueError for one OpenCV cannot decode,
    both naming it.
    """

    def __init__(self, path):
        self.name = str(path)
        if not Path(path).is_file():
            raise FileNotFoundError(errno.ENOENT, "no such video file", self.name)
        self._cap = _quiet_capture(lambda: cv2.VideoCapture(self.name))
        ok = self._cap.isOpened()
        first = self._cap.read() if ok else (False, None)
        if not first[0]:
            self._cap.release()
            raise ValueError(f"{self.name}: not a readable video (OpenCV cannot decode it)")
        self._first = first[1]
        self.fps = plausible_fps(self._cap.get(cv2.CAP_PROP_FPS))
        n = int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        self.count = n if n > 0 else None
        self.size = (self._first.shape[1], self._first.shape[0])

    def __iter__(self) -> Iterator[Frame]:
        k, img = 0, self._first
        while img is not None:
            yield Frame(k, k / self.fps if self.fps else float(k), _gray(img))
            ok, img = self._cap.read()
            img = img if ok else None
            k += 1
        self.count = k

    def close(self) -> None:
        self._cap.release()


class ImageSequence(FrameSource):
    """Files (paths, globs, or a folder's images, sorted) as frames at ``fps`` (default 1: time = index).

    Raises ValueError when nothing matches. Unreadable files are skipped and counted in
    ``skipped`` ({name: why} in ``why``).
    """

    def __init__(self, patterns, fps: float | None = None):
        from aicalib_tf.io import expand_images

        items = [patterns] if isinstance(patterns, (str, os.PathLike)) else list(patterns)
        self.files = expand_images(items)  # a folder stands for its images
        self.name = " ".join(str(p) for p in items)
        if not self.files:
            raise ValueError(f"{self.name}: no images found")
        self.fps, self.count, self.why = fps, len(self.files), {}

    def __iter__(self) -> Iterator[Frame]:
        from aicalib_tf.io import ImageError, load_image, quantize

        for k, f in enumerate(self.files):
            try:
                gray = quantize(load_image(f))
            except ImageError as exc:
                self.skipped += 1
                self.why[f] = str(exc)
                continue
            yield Frame(k, k / self.fps if self.fps else float(k), gray)


class LiveSource(FrameSource):
    """A camera or stream read by a thread that keeps only the newest frame (module docstring).

    open_capture : () -> an object with ``isOpened()``, ``read()`` and ``release()`` (default
    ``cv2.VideoCapture(device)``; tests pass a fake). timeout_s : how long to wait for a frame before
    the stream counts as stopped. Raises OSError naming the source when it cannot be opened; the
    iteration raises OSError when the stream stops without :meth:`close`.
    """

    def __init__(self, device, open_capture: Callable | None = None, timeout_s: float = 5.0):
        self.name = source_name(device)
        self.live, self.timeout_s = True, float(timeout_s)
        self._cap = _quiet_capture(open_capture or (lambda: cv2.VideoCapture(device)))
        if not self._cap.isOpened():
            self._cap.release()
            raise OSError(f"{self.name}: cannot open it (no such device, or it is busy)" if isinstance(device, int)
                          else f"{self.name}: cannot open the stream (unreachable, or not a video stream)")
        self.fps = plausible_fps(getattr(self._cap, "get", lambda _: 0.0)(cv2.CAP_PROP_FPS))
        self.read_count = 0
        self._slot, self._ended, self._stop = None, False, False
        self._cond = threading.Condition()
        self._t0 = time.monotonic()
        self._thread = threading.Thread(target=self._reader, name=f"reader {self.name}", daemon=True)
        self._thread.start()

    def _reader(self) -> None:
        while not self._stop:
            ok, img = self._cap.read()
            with self._cond:
                if not ok or img is None:
                    self._ended = True
                    self._cond.notify_all()
                    return
                if self._slot is not None:
                    self.dropped += 1  # the consumer never took the previous frame
                self._slot = Frame(self.read_count, time.monotonic() - self._t0, _gray(img))
                self.read_count += 1
                self._cond.notify_all()

    def __iter__(self) -> Iterator[Frame]:
        while True:
            with self._cond:
                if not self._cond.wait_for(lambda: self._slot is not None or self._ended or self._stop,
                                           timeout=self.timeout_s):
                    raise OSError(f"{self.name}: no frame for {self.timeout_s:g} s (the stream stopped)")
                frame, self._slot = self._slot, None
                if frame is None:
                    if self._stop:
                        return
                    raise OSError(f"{self.name}: the stream stopped after {self.read_count} frames")
            yield frame

    def close(self) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        self._thread.join(timeout=2.0)
        self._cap.release()


def is_video(path) -> bool:
    """Whether ``path`` names a video file: a video extension, or an existing non-image file that
    ``cv2.VideoCapture`` opens and reads a frame from."""
    p = Path(str(path))
    ext = p.suffix.lower()
    if ext in VIDEO_EXTENSIONS:
        return True
    if ext in IMAGE_EXTENSIONS or any(ch in str(path) for ch in "*?[") or not p.is_file():
        return False
    cap = _quiet_capture(lambda: cv2.VideoCapture(str(p)))
    try:
        return bool(cap.isOpened() and cap.read()[0])
    finally:
        cap.release()


def is_stream(spec) -> bool:
    """Whether ``spec`` is a stream URL (rtsp://, http://, ...)."""
    return isinstance(spec, str) and spec.lower().startswith(_STREAM_PREFIXES)


def open_source(spec, *, fps: float | None = None) -> FrameSource:
    """A :class:`FrameSource` for ``spec``: an int or digit string (a camera), a stream URL, a video
    file, or image paths/globs/a folder (a sequence at ``fps``). Errors name ``spec``."""
    if isinstance(spec, int) or (isinstance(spec, str) and spec.isdigit()):
        return LiveSource(int(spec))
    if is_stream(spec):
        return LiveSource(spec)
    if isinstance(spec, (str, os.PathLike)) and is_video(spec):
        return VideoFile(spec)
    return ImageSequence(spec, fps=fps)


@dataclass(frozen=True)
class Pairing:
    """pairs : [(index into a, index into b)]; unpaired_a, unpaired_b : indices left out;
    offset_s : median time of b minus time of a over the pairs (0 when paired by index)."""

    pairs: list
    unpaired_a: list
    unpaired_b: list
    offset_s: float


def pair_frames(times_a, times_b, *, by: str = "time", tolerance_s: float = 0.010, names=("cam0", "cam1"),
                window: int = 30) -> Pairing:
    """Pair two cameras' frames.

    times_a, times_b : (Na,), (Nb,) frame timestamps, s (by="index": only their lengths matter,
    frame k pairs with frame k). by="time": each frame of a pairs with the nearest frame of b when
    they are at most ``tolerance_s`` apart (each b frame used once). Raises ValueError naming both
    cameras and the measured offset when, over any ``window`` consecutive frames of a, the median
    distance to b's nearest frame exceeds the tolerance (out of sync, or drifting apart).
    """
    a, b = np.asarray(times_a, np.float64).ravel(), np.asarray(times_b, np.float64).ravel()
    if by == "index":
        n = min(len(a), len(b))
        return Pairing([(k, k) for k in range(n)], list(range(n, len(a))), list(range(n, len(b))), 0.0)
    if by != "time":
        raise ValueError(f"pairing must be by 'time' or 'index', got {by!r}")
    if not len(a) or not len(b):
        raise ValueError(f"{names[0]} and {names[1]}: one of them has no frames to pair")
    order = np.argsort(b)
    j = np.clip(np.searchsorted(b[order], a), 1, len(b) - 1) if len(b) > 1 else np.zeros(len(a), int)
    left, right = order[np.maximum(j - 1, 0)], order[j]
    near = np.where(np.abs(b[left] - a) <= np.abs(b[right] - a), left, right)
    dt = b[near] - a
    for s in range(0, max(len(a) - window, 0) + 1, max(window // 2, 1)):
        med = float(np.median(np.abs(dt[s:s + window])))
        if med > tolerance_s:
            raise ValueError(f"{names[0]} and {names[1]} are out of sync: from frame {s} of {names[0]} their frames "
                             f"are {float(np.median(dt[s:s + window])):+.3f} s apart (median), more than the "
                             f"{tolerance_s:.3f} s tolerance")
    pairs, used = [], set()
    for i in np.argsort(np.abs(dt)):
        if abs(dt[i]) <= tolerance_s and int(near[i]) not in used:
            used.add(int(near[i]))
            pairs.append((int(i), int(near[i])))
    pairs.sort()
    paired_a = {p[0] for p in pairs}
    offset = float(np.median([b[q] - a[p] for p, q in pairs])) if pairs else float("nan")
    return Pairing(pairs, [k for k in range(len(a)) if k not in paired_a],
                   [k for k in range(len(b)) if k not in used], offset)
