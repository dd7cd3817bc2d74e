"""Detector speed beside OpenCV's classic detector, in one run: 640×480 conditions, 1920×1080, tracked video.

    python benchmarks/detector_speed.py [--repeat 2] [--limit N] [--threads 1] [--frames 60] [--hd 2]
        [--no-before] [--model default_int8] [--also default --also PATH.tflite]

Three parts, every figure beside ``cv2.findChessboardCorners`` + ``cornerSubPix``
(:func:`aicalib_tf.detect.opencv.opencv_classic`) timed on the same image in the same process,
so that the ratios hold on a shared machine whose absolute times drift:

* the images of ``evaluate --quick`` at 640×480 (its named conditions and sweep levels, rendered
  once, fixed seeds) and its 1920×1080 images: ``detect_corners`` as it is ("cnn") and, unless
  ``--no-before``, without the quick pass ("cnn-before": :func:`aicalib_tf.detect.pyramid.quick_scales`
  switched off, the search of the previous release); each image is timed ``--repeat`` times, round
  robin over the detectors, and keeps its least time. Reported: the median over conditions of
  each condition's median ms (and its ratio to OpenCV's), the mean over images, and clean images;
* a 1280×720 video (``--frames`` frames of a data_gen ``clean`` scene whose board moves on a
  smooth path, up to about 10 px a frame), each frame through :class:`aicalib_tf.detect.track.Tracker`,
  ``detect_corners`` and OpenCV's detector: mean and median ms after the first frame, and how the
  tracker found each board.

``--also MODEL`` (repeatable) times ``detect_corners`` with another network too ("cnn:MODEL"), in
the same round robin, for a before/after comparison of two networks in one run.

``--threads 1`` runs OpenCV (``cv2.setNumThreads(1)``) and the network's interpreter
(``AICALIB_THREADS=1``) on one thread each. Also reports the hits (a full board within 2 px of the
truth) of each detector, a check that a faster path lost nothing on these images.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aicalib_tf.bench.conditions import PATTERN, condition_samples, select_conditions  # noqa: E402
from aicalib_tf.bench.metrics import WRONG_PX, board_detection_outcome  # noqa: E402
from aicalib_tf.bench.runner import QUICK_COUNTS  # noqa: E402


def quick_images(limit: int | None, hd: int = QUICK_COUNTS["hd"]) -> list[tuple[str, np.ndarray, np.ndarray | None]]:
    """(condition, uint8 image, true corners or None) of evaluate --quick's conditions, with ``hd``
    images at 1920×1080."""
    out = []
    for cond in select_conditions(None):
        n = QUICK_COUNTS["sweep"] if cond.sweep else hd if cond.size[0] > 1000 else QUICK_COUNTS["named"]
        n = min(n, limit) if limit else n
        for _, s in condition_samples(cond, n):
            truth = np.asarray(s.label["corners"], np.float64) if s.label["has_board"] else None
            out.append((cond.name, s.image, truth))
    return out


def video_frames(count: int, size=(1280, 720), seed: int = 3) -> list[np.ndarray]:
    """``count`` frames (H, W) uint8 of one data_gen ``clean`` scene, its board moving on a smooth path:
    up to about 60 px either way across the image and 40 px up and down, turning a little."""
    from data_gen.sample import draw_scene

    scene = draw_scene("clean", seed, 0, size=size, pattern=PATTERN)
    while not scene.has_board or scene.framing == "partial":
        seed += 1
        scene = draw_scene("clean", seed, 0, size=size, pattern=PATTERN)
    z, fx = float(scene.tvec[2]), float(scene.camera.K[0, 0])
    frames = []
    for k in range(count):
        t = 2 * np.pi * k / 40.0
        tvec = scene.tvec + np.array([60 * np.sin(t), 40 * np.sin(0.5 * t), 0.0]) * z / fx
        rvec = scene.rvec + np.array([0.0, 0.0, 0.05 * np.sin(0.5 * t)])
        frames.append(scene.render(rvec, tvec))
    return frames


def _timed(fn, img):
    """(fn(img), wall ms, CPU ms of this process: every thread's, so above the wall time where two run)."""
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn(img)
    return out, 1e3 * (time.perf_counter() - t0), 1e3 * (time.process_time() - c0)


def _hit(corners: np.ndarray | None, truth: np.ndarray | None) -> bool:
    if corners is None or truth is None or len(corners) != len(truth):
        return False
    return board_detection_outcome(np.asarray(corners, np.float64), truth, PATTERN, WRONG_PX)[0] == "hit"


def time_images(images, detectors: dict, repeat: int) -> dict:
    """{detector: {"ms": [...], "cpu": [...], "cond": [...], "size": [...], "hit": [...]}} over ``images``,
    each image's least wall and CPU time of ``repeat`` runs."""
    rec = {name: defaultdict(list) for name in detectors}
    for cond, img, truth in images:
        best = {name: np.inf for name in detectors}
        cpu = dict(best)
        corners = {}
        for _ in range(repeat):
            for name, fn in detectors.items():
                got, ms, c = _timed(fn, img)
                best[name], cpu[name] = min(best[name], ms), min(cpu[name], c)
                corners[name] = got
        for name in detectors:
            r = rec[name]
            r["ms"].append(best[name])
            r["cpu"].append(cpu[name])
            r["cond"].append(cond)
            r["size"].append(img.shape[::-1])
            r["hit"].append(_hit(corners[name], truth))
    return rec


def summarise(rec: dict, key: str = "ms", ref: str = "opencv") -> list[str]:
    """Markdown rows: per detector and image group, median over conditions, mean, clean, hits; ratio to ``ref``.

    key : "ms" (wall time) or "cpu" (CPU time)."""
    lines = [f"| detector, {'wall' if key == 'ms' else 'CPU'} | 640×480 median over conditions ms | ratio | mean ms "
             "| ratio | clean median ms | ratio | 1920×1080 median ms | ratio | hits |", "| --- |" + " ---: |" * 9]
    stats = {}
    for name, r in rec.items():
        ms, cond, size = np.array(r[key]), np.array(r["cond"]), r["size"]
        vga = np.array([s == (640, 480) for s in size])
        hd = np.array([s == (1920, 1080) for s in size])
        per_cond = [np.median(ms[vga & (cond == c)]) for c in dict.fromkeys(cond[vga])]
        clean = ms[vga & (cond == "clean")]
        stats[name] = (np.median(per_cond), ms[vga].mean(), np.median(clean) if len(clean) else np.nan,
                       np.median(ms[hd]) if hd.any() else np.nan, int(np.sum(r["hit"])))
    for name, (c, m, cl, hd, hits) in stats.items():
        o = stats[ref]
        lines.append(f"| {name} | {c:.2f} | {c / o[0]:.2f}× | {m:.2f} | {m / o[1]:.2f}× "
                     f"| {cl:.2f} | {cl / o[2]:.2f}× "
                     f"| {hd:.2f} | {hd / o[3]:.2f}× | {hits} |")
    return lines


def time_video(frames, model) -> list[str]:
    """Markdown rows: the tracker, detect_corners and OpenCV per 1280×720 frame (the first frame left out)."""
    from aicalib_tf.detect.opencv import opencv_classic
    from aicalib_tf.detect.pipeline import detect_corners
    from aicalib_tf.detect.track import Tracker

    tracker = Tracker(PATTERN, model=model)
    ms, cpu = defaultdict(list), defaultdict(list)
    how, found = defaultdict(int), defaultdict(int)
    for k, img in enumerate(frames):
        runs = {"tracker": tracker, "detect_corners": lambda i: detect_corners(i, PATTERN, model=model),
                "opencv": lambda i: opencv_classic(i, PATTERN)}
        for name, fn in runs.items():
            got, t, c = _timed(fn, img)
            if k:
                ms[name].append(t)
                cpu[name].append(c)
                ok = got[0] if name == "opencv" else got.complete
                found[name] += bool(ok)
        if k:
            how[tracker.how or "none"] += 1
    o, oc = np.mean(ms["opencv"]), np.mean(cpu["opencv"])
    lines = ["| 1280×720 video, per frame | mean ms | ratio | median ms | max ms | CPU mean ms | ratio "
             "| full boards |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for name, v in ms.items():
        c = np.mean(cpu[name])
        lines.append(f"| {name} | {np.mean(v):.2f} | {np.mean(v) / o:.2f}× | {np.median(v):.2f} | {np.max(v):.2f} "
                     f"| {c:.2f} | {c / oc:.2f}× | {found[name]} of {len(v)} |")
    lines.append("tracker: " + ", ".join(f"{k} {v}" for k, v in sorted(how.items())))
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--limit", type=int, default=None, help="images per condition at most")
    ap.add_argument("--threads", type=int, default=None, help="OpenCV's and the interpreter's threads")
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--hd", type=int, default=QUICK_COUNTS["hd"], help="1920x1080 images (evaluate --quick's 2)")
    ap.add_argument("--no-before", action="store_true", help="leave out the search without the quick pass")
    ap.add_argument("--model", default="default", help="default, default_int8, quick, quick_int8 or a .tflite path")
    ap.add_argument("--also", action="append", default=[], metavar="MODEL",
                    help="another network timed beside --model in the same run (repeatable)")
    a = ap.parse_args(argv)
    import cv2

    if a.threads:
        os.environ["AICALIB_THREADS"] = str(a.threads)
        cv2.setNumThreads(a.threads)
    from aicalib_tf.cnn.model import load_model
    from aicalib_tf.detect import pipeline
    from aicalib_tf.detect.opencv import opencv_classic
    from aicalib_tf.detect.warm import warm

    model = load_model(a.model)
    others = {name: load_model(name) for name in a.also}
    for m in (model, *others.values()):
        for size in ((640, 480), (1920, 1080), (1280, 720)):
            warm(m, size)

    def cnn(img):
        d = pipeline.detect_corners(img, PATTERN, model=model)
        return d.corners if d.complete else None

    def before(img):
        quick, pipeline.quick_scales = pipeline.quick_scales, lambda w, h: []
        try:
            return cnn(img)
        finally:
            pipeline.quick_scales = quick

    def cv(img):
        ok, c = opencv_classic(img, PATTERN)
        return np.asarray(c).reshape(-1, 2) if ok else None

    detectors = {"cnn": cnn, "opencv": cv} if a.no_before else {"cnn": cnn, "cnn-before": before, "opencv": cv}

    def with_model(m):
        def fn(img):
            d = pipeline.detect_corners(img, PATTERN, model=m)
            return d.corners if d.complete else None
        return fn

    detectors.update({f"cnn:{name}": with_model(m) for name, m in others.items()})
    t0 = time.time()
    images = quick_images(a.limit, a.hd)
    frames = video_frames(a.frames)
    print(f"{len(images)} images, {len(frames)} frames rendered in {time.time() - t0:.0f} s; "
          f"model {a.model}{''.join(f', also {n}' for n in a.also)}; threads: {a.threads or 'default'}; load average {os.getloadavg()[0]:.1f}", flush=True)
    rec = time_images(images, detectors, a.repeat)
    print("\n".join(summarise(rec) + [""] + summarise(rec, "cpu")), flush=True)
    print("\n".join(time_video(frames, model)))
    print(f"load average at the end {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
