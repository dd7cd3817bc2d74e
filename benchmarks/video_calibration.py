"""Guided frame selection on synthetic hand-held videos against every 30th frame and random frames.

Videos come from ``python -m data_gen.video`` (60 s, 30 fps, 1280×720 by default: one mild lens,
one 150° fisheye), rendered here with ``--render`` or given as folders with ``--videos``. Per video:

* ``guided``: the loop of :mod:`aicalib_tf.guided` (motion gate, blur, duplicates, the keep rule,
  refits, the stop rule at ``--target``), then the full ``auto`` model choice over its final views
  (the design over the views seen: as many as were kept, more if the target is not reached); wall time includes decoding
  every frame and detecting the examined ones; ``kept`` is the same with the views the loop kept,
  as it kept them;
* ``design``: the first k of the loop's ranked views (:meth:`GuidedCalibration.ranked_views`, the
  backward-elimination design over the views it saw), for k in ``--views``;
* ``every30``: the detections of frames 0, 30, 60, ..., calibrated with the first k of them;
* ``random``: k frames drawn at random from the whole video (``--draws`` draws, the median error
  reported); ``random-seen``: k drawn among the views the guided loop saw (the same candidates the
  design chose from).

The error is the rotation-fitted projection error against the truth (unproject a 32×24 pixel grid
with the true lens, project with the estimate after the best rotation of the camera frame,
:func:`aicalib_tf.calib.quality.rotation_compensated_diff`), mean over the cells the video's
boards cover (any detected view of any method: the same region for every method, "err px"), and
over the image ("image px"). ``cli s`` is the wall time of the whole
``python -m aicalib_tf.calibrate video.avi`` command (report, half-vs-half check and files too);
``cpu s`` / ``cli cpu`` the CPU seconds (user + system, all threads) of the same, which a busy
shared machine does not inflate.

    python benchmarks/video_calibration.py --render /tmp/videos [--seconds 60] [--size 1280x720]
    python benchmarks/video_calibration.py --videos /tmp/videos/mild /tmp/videos/fisheye150 [--out video.csv]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aicalib_tf.calib import quality as Q  # noqa: E402
from aicalib_tf.calib.coverage import coverage_counts
from aicalib_tf.calib.fit import CalibrationError, View, calibrate_camera  # noqa: E402
from aicalib_tf.calib.workflow import make_detector  # noqa: E402
from aicalib_tf.geometry.lens import Lens  # noqa: E402
from aicalib_tf.guided.session import GuidedCalibration, GuidedConfig  # noqa: E402
from aicalib_tf.sources import VideoFile  # noqa: E402

PATTERN, SQUARE = (9, 6), 25.0


REGION: dict = {}  # video name -> (M,) bool: the cells any detected view of the video covers


def _error(lab: dict, cal, views, region=None) -> tuple[float, float]:
    """(mean over ``region``, mean over the image) of the rotation-fitted error, px. region : (M,)
    bool over the 32×24 cells, the same for every method of a video (default: the cells ``views``
    cover)."""
    size = tuple(lab["image_size"])
    true = Lens(lab["distortion_model"], lab["K"], lab["dist"], size)
    pts = Q.grid_points(size)
    if region is None:
        region = coverage_counts([v for v in views if v.name in set(cal.views)], size, (32, 24)).ravel() > 0
    d, _ = Q.rotation_compensated_diff(true, cal.lens, pts, fit_mask=region)
    return float(np.nanmean(d[region])), float(np.nanmean(d))


def guided(path: Path, target: float) -> dict:
    t0, c0 = time.perf_counter(), time.process_time()
    session = GuidedCalibration(GuidedConfig(PATTERN, SQUARE, target_px=target), make_detector("cnn", PATTERN))
    with VideoFile(path) as src:
        for frame in src:
            if session.add(frame).done:
                break
    t_loop = time.perf_counter() - t0
    final = session.final_views()
    cal = session.result(views=final)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    est = session._s.estimate
    return {"cal": cal, "views": final, "kept": session.views, "ranked": session.ranked_views(), "wall_s": wall,
            "cpu_s": cpu, "loop_s": t_loop, "frames": session.frames_seen, "examined": session.examined,
            "sigma_px": est.sigma_px if est else float("nan")}


def detect_frames(path: Path, indices) -> dict[int, View]:
    """{frame index: View} for the frames in ``indices`` where a board was found."""
    want, out = set(int(i) for i in indices), {}
    detect = make_detector("cnn", PATTERN)
    with VideoFile(path) as src:
        for frame in src:
            if frame.index in want:
                hit = detect(frame.gray)
                if hit is not None and len(hit[1]) >= 12:
                    out[frame.index] = View(f"frame{frame.index:06d}", hit[0], hit[1], relative=detect.relative)
    return out


def fixed(lab: dict, views: list[View], region=None) -> tuple[float, float, int, float]:
    """(err over ``region``, err image, views used, seconds) of calibrating ``views`` with model auto."""
    t0 = time.perf_counter()
    try:
        cal = calibrate_camera(views, PATTERN, SQUARE, tuple(lab["image_size"]))
    except CalibrationError:
        return float("nan"), float("nan"), 0, float("nan")
    return (*_error(lab, cal, views, region), len(cal.views), time.perf_counter() - t0)


def cli_seconds(path: Path, target: float) -> tuple[float, float]:
    """(wall s, CPU s: user + system of the child) of the whole command."""
    import resource

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run([sys.executable, "-m", "aicalib_tf.calibrate", str(path), "--pattern", "9x6", "--square", "25mm",
                        "--out", str(Path(tmp) / "c"), "--target", f"{target}px", "--quiet"], check=True,
                       capture_output=True, cwd=Path(__file__).resolve().parents[1])
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        return time.perf_counter() - t0, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)


def _random_rows(lab, name, method, pool: list[View], k: int, draws: int, rng, note: str) -> dict:
    res = np.array([fixed(lab, [pool[i] for i in sorted(rng.choice(len(pool), size=min(k, len(pool)), replace=False))],
                          REGION.get(name)) for _ in range(draws)])
    return dict(video=name, method=method, views=int(np.median(res[:, 2])), err_px=float(np.nanmedian(res[:, 0])),
                image_px=float(np.nanmedian(res[:, 1])), wall_s=float(np.nanmedian(res[:, 3])),
                note=f"median of {draws} draws of {k} {note}")


def bench(folder: Path, target: float, draws: int, rng, sizes) -> list[dict]:
    video = next(folder.glob("video.*"))
    lab = json.loads((folder / "labels.jsonl").read_text().splitlines()[0])
    n = sum(1 for _ in (folder / "labels.jsonl").open())
    g = guided(video, target)
    every = detect_frames(video, range(0, n, 30))
    found = detect_frames(video, rng.choice(n, size=min(n, 150), replace=False))
    everything = [*every.values(), *found.values(), *g["ranked"], *g["kept"]]
    region = REGION[folder.name] = coverage_counts(everything, tuple(lab["image_size"]), (32, 24)).ravel() > 0
    err, err_img = _error(lab, g["cal"], g["views"], region)
    rows = [dict(video=folder.name, method="guided", views=len(g["cal"].views), err_px=err, image_px=err_img,
                 wall_s=g["wall_s"], cpu_s=g["cpu_s"],
                 note=f"{g['examined']} of {g['frames']} frames examined; loop {g['loop_s']:.1f} s; "
                      f"predicted σ90 {g['sigma_px']:.3f} px; {len(g['ranked'])} views seen; model {g['cal'].model}")]
    rows[0]["cli_s"], rows[0]["cli_cpu_s"] = cli_seconds(video, target)
    e, ei, used, s = fixed(lab, g["kept"], region)
    rows.append(dict(video=folder.name, method="kept", views=used, err_px=e, image_px=ei, wall_s=s,
                     note="the loop's kept views, as kept"))
    ranked = g["ranked"]
    for k in sorted({len(g["cal"].views), len(g["kept"]), *sizes}):
        if k > len(ranked):
            continue
        e, ei, used, s = fixed(lab, ranked[:k], region)
        rows.append(dict(video=folder.name, method="design", views=used, err_px=e, image_px=ei, wall_s=s,
                         note=f"first {k} ranked"))
        rows.append(_random_rows(lab, folder.name, "random-seen", ranked, k, draws, rng, "of the views seen"))
        rows.append(_random_rows(lab, folder.name, "random", [found[i] for i in sorted(found)], k, draws, rng,
                                 "of the whole video"))
        e, ei, used, s = fixed(lab, [every[i] for i in sorted(every)][:k], region)
        rows.append(dict(video=folder.name, method="every30", views=used, err_px=e, image_px=ei, wall_s=s,
                         note=f"first {k}"))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--videos", nargs="*", type=Path, default=[])
    ap.add_argument("--render", type=Path, help="render the mild and fisheye150 videos into this folder first")
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--target", type=float, default=0.1)
    ap.add_argument("--draws", type=int, default=5)
    ap.add_argument("--views", type=int, nargs="*", default=[6, 8, 11, 15, 20, 25], help="the view counts compared")
    ap.add_argument("--out", type=Path, default=None, help="CSV of the rows")
    args = ap.parse_args(argv)
    videos = list(args.videos)
    if args.render:
        from data_gen.video import main as render

        for lens, seed in (("mild", 1), ("fisheye150", 2)):
            out = args.render / lens
            t0 = time.perf_counter()
            render(["--out", str(out), "--seconds", str(args.seconds), "--size", args.size, "--lens", lens,
                    "--seed", str(seed), "--workers", str(args.workers), "--quiet"])
            print(f"rendered {out} in {time.perf_counter() - t0:.0f} s")
            videos.append(out)
    rows = []
    for v in videos:
        rows += bench(v, args.target, args.draws, np.random.default_rng(0), args.views)
    nan = float("nan")
    print(f"{'video':<12} {'method':<8} {'views':>5} {'err px':>7} {'image px':>8} {'wall s':>7} {'cpu s':>6} "
          f"{'cli s':>6} {'cli cpu':>7}  note")
    for r in rows:
        print(f"{r['video']:<12} {r['method']:<8} {r['views']:>5} {r['err_px']:7.3f} {r['image_px']:8.3f} "
              f"{r['wall_s']:7.1f} {r.get('cpu_s', nan):6.1f} {r.get('cli_s', nan):6.1f} {r.get('cli_cpu_s', nan):7.1f}  "
              f"{r['note']}")
    if args.out:
        import csv

        with open(args.out, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=["video", "method", "views", "err_px", "image_px", "wall_s", "cpu_s", "cli_s",
                                                   "cli_cpu_s", "note"])
            w.writeheader()
            w.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
