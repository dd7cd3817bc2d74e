"""Which frames to calibrate with: the guided loop's selection against random frames and every 30th
frame, at equal view counts, over many noise draws of the same hand-held path.

The videos' exact corners (``labels.jsonl`` from ``python -m data_gen.video``) stand in for the
detector, with Gaussian noise of ``--noise`` px per axis drawn anew for every trial, so that one
path gives many independent trials in seconds and the comparison is about the selection alone
(``benchmarks/video_calibration.py`` runs the whole thing, detector included, once per video).
Frames count as detected when the whole board is in view and its fastest corner moved less than
``--max-motion`` px during the exposure (a sharp frame); the loop sees every ``--step``-th frame
(about what the motion gate passes). Per trial:

* ``guided``: the loop's final views (:meth:`GuidedCalibration.final_views`: the fewest views seen
  whose design reaches ``--target``); ``kept``: the views the loop kept, as kept;
* ``random``: as many views drawn at random among the detected frames of the video (a repeat of
  an earlier frame within 1 px, the board at rest, counted once as the calibration counts it);
  ``every30``: the first as many of frames 0, 30, 60, ... that were detected.

Every set is fitted with the lens's own model family (forced, so that the comparison is not about
the model choice) and scored by the rotation-fitted projection error against the truth over the
whole image (32×24 cells: what a user of the calibration gets) and over the cells the set's views
covered. Reported: the median over the trials and how often the guided set beat the other at
the same count (paired by trial).

One set's error swings 2-3× between noise draws, so with ``--redraws R`` each set is scored by
the mean error of R fits of its frames with fresh noise: its expected error, what the selection
itself is worth. ``--curve`` adds random frames at fixed counts and reads off how many random
frames reach the guided sets' errors.

    python benchmarks/guided_selection.py --paths mild:60:1280x720:1 fisheye150:60:1280x720:2 --trials 20
    python benchmarks/guided_selection.py --paths mild:60:1280x720:3 --trials 20 --redraws 6 --curve 6 9 13 18 26 36 52
    python benchmarks/guided_selection.py /tmp/vids/fish30 --trials 20   (a rendered video's labels.jsonl)
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aicalib_tf.calib import quality as Q  # noqa: E402
from aicalib_tf.calib.coverage import coverage_counts
from aicalib_tf.calib.fit import CalibrationError, View, fit_views  # noqa: E402
from aicalib_tf.calib.view_checks import duplicates  # noqa: E402
from aicalib_tf.geometry.lens import Lens  # noqa: E402
from aicalib_tf.guided.session import GuidedCalibration, GuidedConfig  # noqa: E402

FAMILY = {"equidistant": "equidistant", "plumb_bob": "plumb_bob", "rational_polynomial": "rational_polynomial"}


class _Truth:
    """Returns the frame's noisy corners (set in ``next``) for the next call."""

    relative = False

    def __init__(self):
        self.next = None

    def __call__(self, gray):
        return self.next


def _load(folder: Path) -> list[dict]:
    return [json.loads(line) for line in (folder / "labels.jsonl").open()]


def _path_labels(spec: str) -> tuple[str, list[dict]]:
    """``LENS:SECONDS:WxH:SEED`` -> (name, every frame's label) of the video ``python -m data_gen.video
    --lens LENS --seconds SECONDS --size WxH --seed SEED`` would render, without rendering it."""
    from data_gen.video import VideoConfig, frame_truth, make_scene

    lens, seconds, size, seed = spec.split(":")
    w, h = (int(v) for v in size.lower().split("x"))
    cfg = VideoConfig(out="", seconds=float(seconds), size=(w, h), lens=lens, seed=int(seed))
    scene = make_scene(cfg)
    return f"{lens}-{seconds}s-seed{seed}", [frame_truth(scene, i) for i in range(int(round(cfg.seconds * cfg.fps)))]


def _detected(labels, max_motion: float) -> dict[int, np.ndarray]:
    """{frame index: (N, 2) true corners} of the sharp frames showing the whole board."""
    out = {}
    for lab in labels:
        if lab["has_board"] and all(lab["visible"]) and lab["motion_px"] < max_motion:
            out[lab["index"]] = np.asarray(lab["corners"], np.float64)
    return out


def _score(lab: dict, views: list[View], model: str, redraw=None) -> tuple[float, float, int]:
    """(error over the image, over the covered cells, views used) px; NaN when the fit fails.

    redraw : None, or (exact corners {frame: (N, 2)}, rng, noise σ px, R): the set's frames fitted R
    times with fresh noise instead of the trial's own, and the mean of the R errors returned: the
    set's expected error, without the luck of one draw (errors of one set swing 2-3× between draws).
    """
    if redraw is not None:
        exact, rng, noise, reps = redraw
        frames = [int(v.name[len("frame"):]) for v in views]
        runs = [_score(lab, [replace(v, corners=exact[i] + rng.normal(0.0, noise, exact[i].shape))
                             for v, i in zip(views, frames)], model) for _ in range(reps)]
        return float(np.mean([r[0] for r in runs])), float(np.mean([r[1] for r in runs])), runs[0][2]
    size = tuple(lab["image_size"])
    try:
        cal = fit_views(views, tuple(lab["pattern_size"]), lab["square_size"], size, model, fix_k3=model != "equidistant")
    except (CalibrationError, np.linalg.LinAlgError):
        return float("nan"), float("nan"), 0
    true = Lens(lab["distortion_model"], lab["K"], lab["dist"], size)
    covered = coverage_counts(views, size, (32, 24)).ravel() > 0
    d, _ = Q.rotation_compensated_diff(true, Q.lens_of(cal), Q.grid_points(size), fit_mask=covered)
    return float(np.nanmean(d)), float(np.nanmean(d[covered])), len(cal.views)


def trial(labels, detected, ids, rng, args) -> dict:
    lab = labels[0]
    size = tuple(lab["image_size"])
    model = FAMILY[lab["distortion_model"]]
    noisy = {i: c + rng.normal(0.0, args.noise, c.shape) for i, c in detected.items()}
    views = {i: View(f"frame{i:06d}", c, ids) for i, c in noisy.items()}
    det = _Truth()
    cfg = GuidedConfig(tuple(lab["pattern_size"]), lab["square_size"], model=model, target_px=args.target, gate=False)
    session = GuidedCalibration(cfg, det)
    gray = np.zeros(size[::-1], np.uint8)
    for i in range(0, len(labels), args.step):
        det.next = (noisy[i], ids) if i in noisy else None
        if session.add((i, i / 30.0, gray)).done:
            break
    final, kept = session.final_views(), session.views
    every = [views[i] for i in range(0, len(labels), 30) if i in views]
    repeats = duplicates([views[i] for i in sorted(views)])  # a board at rest: the same view, counted once
    pool = [i for i in sorted(views) if views[i].name not in repeats]
    row = {"frames_read": session.frames_seen, "seen": len(session.ranked_views())}
    redraw = (detected, rng, args.noise, args.redraws) if args.redraws else None

    def random_views(k: int) -> list[View]:  # k distinct frames drawn from the deduplicated detections
        return [views[i] for i in sorted(rng.choice(pool, size=k, replace=False))]

    for name, got in (("guided", final), ("kept", kept)):
        k = len(got)
        row[name] = _score(lab, got, model, redraw)
        row[f"random@{name}"] = _score(lab, random_views(k), model, redraw)
        row[f"every30@{name}"] = _score(lab, every[:k], model, redraw)
    for k in args.curve:  # random frames at fixed counts: how many it takes for an error
        if k <= len(pool):
            row[f"curve{k}"] = _score(lab, random_views(k), model, redraw)
    return row


def views_for(curve: dict[int, float], error: float) -> float:
    """How many random views reach ``error`` px: the median-error curve {count: px}, interpolated in
    log(count) against log(error); inf beyond its largest count, and its smallest count or fewer
    when already below."""
    ks = sorted(k for k in curve if np.isfinite(curve[k]))
    if not ks or error <= 0:
        return float("nan")
    for a, b in zip(ks, ks[1:]):
        ea, eb = curve[a], curve[b]
        if ea >= error >= eb and ea > eb:
            t = (np.log(ea) - np.log(error)) / (np.log(ea) - np.log(eb))
            return float(np.exp(np.log(a) + t * (np.log(b) - np.log(a))))
    return float(ks[0]) if error >= curve[ks[0]] else float("inf")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("videos", nargs="*", type=Path, help="folders written by python -m data_gen.video")
    ap.add_argument("--paths", nargs="*", default=[], metavar="LENS:SECONDS:WxH:SEED",
                    help="hand-held paths of data_gen.video, their truth computed without rendering")
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--noise", type=float, default=0.15, help="corner noise σ per axis, px")
    ap.add_argument("--target", type=float, default=0.1, help="the loop's --target, px")
    ap.add_argument("--step", type=int, default=3, help="the loop sees every step-th frame")
    ap.add_argument("--redraws", type=int, default=0,
                    help="score each set by the mean error of this many fits with fresh noise (0: the trial's own)")
    ap.add_argument("--curve", type=int, nargs="*", default=[],
                    help="also random frames at these counts, and how many random views reach the guided errors")
    ap.add_argument("--max-motion", type=float, default=1.0, help="px: a frame moving more is blurred, not detected")
    args = ap.parse_args(argv)
    for name, labels in [*((f.name, _load(f)) for f in args.videos), *(_path_labels(p) for p in args.paths)]:
        detected = _detected(labels, args.max_motion)
        cols, rows = labels[0]["pattern_size"]
        ids = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), -1).reshape(-1, 2)
        t0 = time.perf_counter()
        rows_ = [trial(labels, detected, ids, np.random.default_rng([7, t]), args) for t in range(args.trials)]
        print(f"\n{name}: {labels[0]['distortion_model']} {labels[0]['image_size'][0]}x{labels[0]['image_size'][1]}, "
              f"{len(labels)} frames, {len(detected)} sharp full-board frames; noise σ {args.noise} px; "
              f"{args.trials} trials in {time.perf_counter() - t0:.0f} s")
        print(f"  views seen by the loop: median {np.median([r['seen'] for r in rows_]):.0f}; frames read before "
              f"the stop: median {np.median([r['frames_read'] for r in rows_]):.0f}")
        print(f"  {'set':<16} {'views':>5} {'image px':>9} {'covered px':>10} {'guided set better (image)':>26}")
        for base in ("guided", "kept"):
            ref = np.array([r[base] for r in rows_])
            for name in (base, f"random@{base}", f"every30@{base}"):
                a = np.array([r[name] for r in rows_])
                wins = "" if name == base else f"{np.mean(ref[:, 0] < a[:, 0]):.0%} of trials"
                print(f"  {name:<16} {np.median(a[:, 2]):5.0f} {np.nanmedian(a[:, 0]):9.4f} {np.nanmedian(a[:, 1]):10.4f} "
                      f"{wins:>26}")
        curve = {k: float(np.nanmedian([r[f"curve{k}"][0] for r in rows_])) for k in args.curve
                 if all(f"curve{k}" in r for r in rows_)}
        if curve:
            print("  random frames, median error over the image: "
                  + ", ".join(f"{k} views {e:.4f} px" for k, e in sorted(curve.items())))
            for base in ("guided", "kept"):
                a = np.array([r[base] for r in rows_])
                err, k = float(np.nanmedian(a[:, 0])), float(np.median(a[:, 2]))
                print(f"  random frames for {base}'s {err:.4f} px ({k:.0f} views): {views_for(curve, err):.1f} views")
    return 0


if __name__ == "__main__":
    sys.exit(main())
