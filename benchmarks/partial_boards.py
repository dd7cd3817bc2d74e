"""Partial boards: how many visible corners come back, with which ids, on data_gen renders.

    python benchmarks/partial_boards.py [--images 30] [--presets occluded,partial,clutter] [--seed 21]
    python benchmarks/partial_boards.py --hash-out FILE      # full-board fingerprint of mixed images
    python benchmarks/partial_boards.py --hash-check FILE    # compare with a fingerprint made before
    python benchmarks/partial_boards.py --no-pattern [--presets ...]   # pattern_size=None: own-grid boards
    python benchmarks/partial_boards.py --speed [--repeats 3]           # ms per image, with and without the CNN

Accuracy: for each preset, --images 640×480 renders of 9×6 inner corners (seed --seed) go through
``detect_corners(image, (9, 6))`` and ``metrics.partial_board_stats``: each returned corner is
matched to the true corner its id names, after the one board symmetry (180°; 90° too for square
patterns) that gives the most matches; a corner within 2 px of a visible true corner is correct,
of a hidden one neither, any other is a wrong id. Recall = correct / visible corners.
A clutter image (no board) that gives any board is a false positive.

Without a pattern (--no-pattern), ``detect_corners(image, None)`` returns the largest complete grid
with its own ids. A returned grid is *right* when every corner lies within 2 px of a true corner
and its ids map onto those corners' true (col, row) by one rotation/reflection and shift; any
other grid is a wrong grid (on clutter: a false board).

Speed: 35 images (clean, noisy, blur, distorted, occluded, partial, clutter; 5 each, seed 11),
each timed --repeats times (the fastest counts, to see past other work on the machine), the whole
detection and the CNN alone (``inference.corner_points``); median and max per preset and overall.

Fingerprint: 40 mixed images (clean, distorted, noisy, blur, hard, occluded, partial, clutter;
seed 7), each detected with the pattern and without one; for each, the sha256 of the detection
(corners, ids, scores, complete) or "none". The check passes when every detection is
byte-identical. It also prints the median and max time per image with the pattern (the same
images, after a warm-up).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time

os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")

import numpy as np  # noqa: E402

from aicalib_tf.detect.pipeline import detect_corners  # noqa: E402
from aicalib_tf.bench.metrics import partial_board_stats  # noqa: E402
from aicalib_tf.cnn.model import load_model  # noqa: E402
from data_gen import make_sample  # noqa: E402

PATTERN = (9, 6)  # --pattern changes it
MAX_PX = 2.0
MIXED = ["clean", "distorted", "noisy", "blur", "hard", "occluded", "partial", "clutter"]


def partial_stats(corners, ids, truth, visible, pattern, max_px=MAX_PX) -> dict:
    """``metrics.partial_board_stats``; hidden corners found with the right id count as neither."""
    return partial_board_stats(corners, ids, truth, visible, pattern, max_px)


def _count_placements():
    """Wrap placement.place_cells to count grids whose ids the image left open (for the report only)."""
    from aicalib_tf.detect.chessboard import placement

    tally = {"tried": 0, "open": 0}
    place = placement.place_cells

    def counted(*args, **kwargs):
        ids = place(*args, **kwargs)
        tally["tried"] += 1
        tally["open"] += ids is None
        return ids

    placement.place_cells = counted
    return tally


def accuracy(model, presets, n, seed):
    tally = _count_placements()
    print("| preset | boards returned | complete | visible-corner recall | wrong ids | images with a wrong id | "
          "no board: ids left open / no grid | ms median |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for preset in presets:
        found = complete = vis = correct = wrong = bad_imgs = undecided = 0
        times, misses = [], []
        for i in range(n):
            s = make_sample(preset, seed, i, pattern=PATTERN, size=(640, 480))
            tally["open"] = 0
            t = time.perf_counter()
            det = detect_corners(s.image, PATTERN, model=model)
            times.append(1000 * (time.perf_counter() - t))
            found += det.found
            complete += det.complete
            undecided += (not det.found) and tally["open"] > 0
            if preset == "clutter":
                continue
            st = partial_stats(det.corners, det.ids, s.corners, s.visible, PATTERN)
            vis += st["visible"]
            correct += st["correct"]
            wrong += st["wrong_ids"]
            bad_imgs += st["wrong_ids"] > 0
            if st["recall"] < 0.9:
                misses.append((i, st["correct"], st["visible"], st["wrong_ids"]))
        if preset == "clutter":
            print(f"| {preset} | {found}/{n} (false positives) | {complete} | - | - | - | {undecided} / "
                  f"{n - found - undecided} | {np.median(times):.1f} |")
        else:
            print(f"| {preset} | {found}/{n} | {complete} | {correct}/{vis} = {correct / max(vis, 1):.3f} | {wrong} | "
                  f"{bad_imgs} | {undecided} / {n - found - undecided} | {np.median(times):.1f} |", flush=True)
            if misses:
                print("    recall < 0.9 (index, correct, visible, wrong):", misses, flush=True)


def _digest(det) -> str:
    if not det.found:
        return "none"
    raw = det.corners.tobytes() + det.ids.tobytes() + det.scores.tobytes() + bytes([det.complete])
    return hashlib.sha256(raw).hexdigest()


def fingerprint(model, n_per=5, seed=7) -> tuple[dict, list[float]]:
    out, times = {}, []
    samples = [(p, i, make_sample(p, seed, i, pattern=PATTERN, size=(640, 480))) for p in MIXED for i in range(n_per)]
    for _ in range(2):  # warm up: the size's own graph is traced on its second use
        detect_corners(samples[0][2].image, PATTERN, model=model)
    for p, i, s in samples:
        t = time.perf_counter()
        det = detect_corners(s.image, PATTERN, model=model)
        times.append(1000 * (time.perf_counter() - t))
        out[f"{p}/{i}"] = _digest(det)
        out[f"{p}/{i}/no-pattern"] = _digest(detect_corners(s.image, None, model=model))
    return out, times


def _own_grid_right(det, truth, max_px=MAX_PX) -> bool:
    """Whether a pattern-free detection is true corners whose ids are a rotation/reflection + shift of the true ids."""
    cols = PATTERN[0]
    d = np.linalg.norm(det.corners[:, None, :].astype(np.float64) - truth[None, :, :], axis=2)
    k = d.argmin(axis=1)
    if d[np.arange(len(k)), k].max() > max_px or len(set(k.tolist())) < len(k):
        return False
    cr = np.stack([k % cols, k // cols], 1)
    for m in ([[1, 0], [0, 1]], [[0, 1], [1, 0]]):
        for s in ([1, 1], [1, -1], [-1, 1], [-1, -1]):
            t = (cr @ np.array(m)) * np.array(s)
            if np.array_equal(t - t.min(0), det.ids - det.ids.min(0)):
                return True
    return False


def no_pattern(model, presets, n, seed):
    print("| preset | grids returned | corners returned / visible | mean grid size | wrong grids | ms median |")
    print("| --- | --- | --- | --- | --- | --- |")
    for preset in presets:
        found = corners = vis = wrong = 0
        times, sizes = [], []
        for i in range(n):
            s = make_sample(preset, seed, i, pattern=PATTERN, size=(640, 480))
            t = time.perf_counter()
            det = detect_corners(s.image, None, model=model)
            times.append(1000 * (time.perf_counter() - t))
            vis += int(np.sum(s.visible)) if preset != "clutter" else 0
            if not det.found:
                continue
            found += 1
            corners += len(det.corners)
            sizes.append(len(det.corners))
            wrong += preset == "clutter" or not _own_grid_right(det, np.asarray(s.corners, np.float64))
        label = "false boards" if preset == "clutter" else "wrong grids"
        print(f"| {preset} | {found}/{n} | {corners}/{vis} | {np.mean(sizes) if sizes else 0:.1f} | {wrong} {label} | "
              f"{np.median(times):.1f} |", flush=True)


SPEED = ["clean", "noisy", "blur", "distorted", "occluded", "partial", "clutter"]


def speed(model, repeats=3, n_per=5, seed=11):
    from aicalib_tf.cnn.inference import corner_points
    from aicalib_tf.io import load_image

    samples = [(p, make_sample(p, seed, i, pattern=PATTERN, size=(640, 480)).image) for p in SPEED for i in range(n_per)]
    for _ in range(2):  # warm up: the size's own graph is traced on its second use
        detect_corners(samples[0][1], PATTERN, model=model)
    total, cnn = [], []
    for _, image in samples:
        gray, t_all, t_cnn = load_image(image), [], []
        for _ in range(repeats):
            t = time.perf_counter()
            detect_corners(image, PATTERN, model=model)
            t_all.append(1000 * (time.perf_counter() - t))
            t = time.perf_counter()
            corner_points(model, gray)
            t_cnn.append(1000 * (time.perf_counter() - t))
        total.append(min(t_all))
        cnn.append(min(t_cnn))
    total, cnn = np.array(total), np.array(cnn)
    print("| images | ms median | ms max | max / median | CNN ms median | rest ms median | rest ms max |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for name, sel in [(p, slice(k * n_per, (k + 1) * n_per)) for k, p in enumerate(SPEED)] + [("all", slice(None))]:
        t, c = total[sel], cnn[sel]
        print(f"| {name} | {np.median(t):.1f} | {t.max():.1f} | {t.max() / np.median(t):.2f} | {np.median(c):.1f} | "
              f"{np.median(t - c):.1f} | {(t - c).max():.1f} |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--images", type=int, default=30)
    ap.add_argument("--presets", default="occluded,partial,clutter")
    ap.add_argument("--seed", type=int, default=21)
    ap.add_argument("--model", default="default")
    ap.add_argument("--pattern", default="9x6", help="inner corners COLSxROWS (default: %(default)s)")
    ap.add_argument("--hash-out")
    ap.add_argument("--hash-check")
    ap.add_argument("--no-pattern", action="store_true", help="detect with pattern_size=None (own-grid ids)")
    ap.add_argument("--speed", action="store_true", help="time 35 mixed images (whole detection and CNN alone)")
    ap.add_argument("--repeats", type=int, default=3, help="--speed: runs per image, the fastest counts")
    args = ap.parse_args(argv)
    global PATTERN
    PATTERN = tuple(int(v) for v in args.pattern.lower().split("x"))
    model = load_model(args.model)
    if args.hash_out or args.hash_check:
        fp, times = fingerprint(model)
        found = sum(v != "none" for k, v in fp.items() if not k.endswith("/no-pattern"))
        print(f"{len(times)} images, {found} with a board (pattern {PATTERN}); "
              f"ms median {np.median(times):.1f}, mean {np.mean(times):.1f}, max {max(times):.1f}")
        if args.hash_out:
            with open(args.hash_out, "w") as f:
                json.dump(fp, f, indent=1)
            return 0
        with open(args.hash_check) as f:
            ref = json.load(f)
        bad = [k for k, v in ref.items() if fp.get(k) != v]
        print(f"all {len(ref)} detections identical" if not bad else f"DIFFERENT: {bad}")
        return 1 if bad else 0
    if args.speed:
        speed(model, args.repeats)
        return 0
    if args.no_pattern:
        no_pattern(model, args.presets.split(","), args.images, args.seed)
    else:
        accuracy(model, args.presets.split(","), args.images, args.seed)
    return 0


if __name__ == "__main__":
    sys.exit(main())
