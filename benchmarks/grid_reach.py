"""How far grid growth reaches on close-up fisheye boards whose squares shrink 3× or more across the board.

    python benchmarks/grid_reach.py [--conditions closeup-eq,closeup-unified] [--seed S ...] [--count 60]
        [--min-ratio 3] [--candidates] [--detect] [--show]

For each image of the named evaluate conditions (``aicalib_tf.bench.conditions``) rendered with each seed
(default: 41, 97, 123), the board's step ratio is the longest over the shortest distance between neighbouring
visible true corners; images under ``--min-ratio`` are skipped. On the others:

- **truth**: the visible true corners, jittered by σ 0.25 px and shuffled, are assembled as the detector
  assembles them (straight seeds, then bent ones; no ``propose``). Reach: the corners of the best grid
  on their true lattice position over the visible corners; wrong: grid cells off that lattice.
- **candidates** (``--candidates``): the detector's own candidates and ``propose`` (the full-size stage of
  :mod:`aicalib_tf.detect.pipeline`, as ``benchmarks/stage_misses.py`` traces it); reach over the visible
  corners with a candidate or a grid point within 1.5 px, and over all visible corners.
- **detect** (``--detect``): :func:`aicalib_tf.detect_corners` with the 9×6 pattern, scored as evaluate
  scores it (hit / wrong / miss).

Prints one line per image with ``--show``, and per condition the images kept, their median ratio and the
sums of the figures above.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from dataclasses import replace

import cv2
import numpy as np

from aicalib_tf.bench.conditions import PATTERN, condition_samples, select_conditions
from aicalib_tf.detect.chessboard.grid import assemble_grids
from aicalib_tf.io import as_gray_float

JITTER = 0.25  # px: σ of the noise on the true corners of the truth mode
MATCH = 2.0  # px: a grid point within this of a true corner is that corner
SEEDS = (41, 97, 123)  # the default scenes: the close-up conditions' own (41) and two more


def step_ratio(corners: np.ndarray, visible: np.ndarray, pattern=PATTERN) -> float:
    """Longest over shortest step between neighbouring visible corners; corners (cols·rows, 2) px."""
    cols, rows = pattern
    c, v = corners.reshape(rows, cols, 2), visible.reshape(rows, cols)
    s = np.concatenate([np.linalg.norm(c[:, 1:] - c[:, :-1], axis=2)[v[:, 1:] & v[:, :-1]],
                        np.linalg.norm(c[1:] - c[:-1], axis=2)[v[1:] & v[:-1]]])
    return float(s.max() / s.min()) if len(s) else float("nan")


def grid_on_truth(g, truth: np.ndarray, pattern=PATTERN) -> tuple[int, int]:
    """(cells on their true lattice position, cells off it) of grid ``g`` against truth (cols·rows, 2) px.

    Each grid point is named the true corner within ``MATCH`` px; the lattice map (one of the 8
    flips/turns and a shift) that most cells agree with is the grid's; the others are off it.
    """
    cols = pattern[0]
    d = np.linalg.norm(g.points[:, None, :] - truth[None], axis=2)
    k = np.argmin(d, axis=1)
    named = d[np.arange(len(k)), k] <= MATCH
    cr = np.stack([k % cols, k // cols], 1)
    best = 0
    for m in (np.eye(2, dtype=int), np.array([[0, 1], [1, 0]])):
        for s in (np.array([1, 1]), np.array([1, -1]), np.array([-1, 1]), np.array([-1, -1])):
            mapped = (g.ij @ m) * s
            shift = cr[named] - mapped[named]
            if len(shift) == 0:
                continue
            vals, counts = np.unique(shift, axis=0, return_counts=True)
            best = max(best, int(counts.max()))
    return best, len(g) - best


def truth_reach(sample, rng) -> tuple[int, int]:
    """(most cells on the truth in one grid, cells off the truth in that grid) from jittered true corners."""
    vis = np.asarray(sample.label["visible"], bool)
    pts = sample.corners[vis] + rng.normal(0, JITTER, (int(vis.sum()), 2))
    order = rng.permutation(len(pts))
    pts = pts[order]
    gray = cv2.GaussianBlur(as_gray_float(sample.image), (0, 0), 1.0)
    limit = max(PATTERN) + 1
    grids = assemble_grids(pts, gray=gray, limit=limit) + assemble_grids(pts, gray=gray, limit=limit, bend=True)
    return _best(grids, sample.corners)


def _best(grids, truth) -> tuple[int, int]:
    best = (0, 0)
    for g in grids:
        on, off = grid_on_truth(g, truth)
        if (on, -off) > (best[0], -best[1]):
            best = (on, off)
    return best


def candidate_reach(sample, model) -> tuple[int, int, int]:
    """(cells on the truth, cells off it, visible corners within 1.5 px of a candidate or grid point)."""
    from aicalib_tf.detect import pipeline as pl

    gray = as_gray_float(sample.image)
    smoothed = pl.Smoothed(gray, None)
    refined, scores, weak = pl.refined_points(model, gray, 0.5, smoothed=smoothed, min_points=pl.MIN_CORNERS, weak=pl.WEAK)
    vis = np.asarray(sample.label["visible"], bool)
    truth = sample.corners
    if len(refined) < pl.MIN_CORNERS:
        return 0, 0, 0
    smooth = smoothed.sigma(pl.RING_SIGMA)
    propose = pl.proposer(smoothed, smooth, pl.typical_amplitude(smooth, refined, pl.MIN_CORNERS), weak=weak)
    limit = max(PATTERN) + 1
    grids = pl.assemble_grids(refined, scores, gray=smooth, propose=propose, limit=limit)
    grids += pl.assemble_grids(refined, scores, gray=smooth, propose=propose.bent, limit=limit, bend=True)
    on, off = _best(grids, truth)
    pts = np.concatenate([refined] + [g.points for g in grids])
    seen = np.linalg.norm(truth[vis][:, None] - pts[None], axis=2).min(axis=1) <= 1.5
    return on, off, int(seen.sum())


def run_condition(cond, count: int, min_ratio: float, model, detect: bool, show: bool) -> Counter:
    from aicalib_tf import detect_corners
    from aicalib_tf.bench.metrics import board_detection_outcome

    c: Counter = Counter()
    ratios = []
    rng = np.random.default_rng(cond.seed)
    for index, s in condition_samples(cond, count):
        vis = np.asarray(s.label["visible"], bool)
        ratio = step_ratio(s.corners, vis)
        if not ratio >= min_ratio or vis.sum() < 9:
            continue
        ratios.append(ratio)
        c["images"] += 1
        c["visible"] += int(vis.sum())
        on, off = truth_reach(s, rng)
        c["truth_on"] += on
        c["truth_off"] += off
        c["truth_full"] += on == vis.sum() and off == 0
        line = f"  {cond.name} #{index}: ratio {ratio:.1f}, visible {vis.sum()}, truth grid {on}/{off}"
        if model is not None:
            con, coff, seen = candidate_reach(s, model)
            c["cand_on"] += con
            c["cand_off"] += coff
            c["cand_seen"] += seen
            line += f", candidates grid {con}/{coff} of {seen}"
        if detect:
            det = detect_corners(s.image, PATTERN, model=model)
            outcome, _ = board_detection_outcome(det.corners if det.complete else None, s.corners, PATTERN)
            c[outcome] += 1
            line += f", {outcome}"
        if show:
            print(line, flush=True)
    c["median_ratio_x10"] = int(round(10 * float(np.median(ratios)))) if ratios else 0
    return c


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--conditions", default="closeup-eq,closeup-unified", help="evaluate condition names")
    ap.add_argument("--seed", type=int, action="append", default=None,
                    help="data_gen seed (repeatable) in place of the conditions' (default: 41, 97 and 123)")
    ap.add_argument("--count", type=int, default=60, help="images rendered per condition and seed")
    ap.add_argument("--min-ratio", type=float, default=3.0, help="the smallest step ratio of an image kept")
    ap.add_argument("--candidates", action="store_true", help="also the detector's candidates (loads the corner model)")
    ap.add_argument("--detect", action="store_true", help="also the whole detector's hit / wrong / miss")
    ap.add_argument("--show", action="store_true", help="one line per image")
    args = ap.parse_args(argv)
    model = None
    if args.candidates or args.detect:
        from aicalib_tf.cnn.model import load_model
        from aicalib_tf.cnn.spec import DETECTOR_NETWORK

        model = load_model(DETECTOR_NETWORK)
    print("| condition | seed | images | median ratio | truth reach | truth off | truth full | candidates reach | "
          "candidates off | hit | wrong | miss |\n|---|---|---|---|---|---|---|---|---|---|---|---|")
    for cond in select_conditions(args.conditions):
        for seed in args.seed or list(SEEDS):
            cs = replace(cond, seed=seed)
            c = run_condition(cs, args.count, args.min_ratio, model if args.candidates else None, args.detect, args.show)
            cand = f"{c['cand_on']}/{c['cand_seen']} ({c['cand_on']}/{c['visible']})" if args.candidates else "-"
            det = (f"{c['hit']} | {c['wrong']} | {c['miss']}" if args.detect else "- | - | -")
            print(f"| {cond.name} | {seed} | {c['images']} | {c['median_ratio_x10'] / 10:.1f} | {c['truth_on']}/{c['visible']} | "
                  f"{c['truth_off']} | {c['truth_full']} | {cand} | {c['cand_off'] if args.candidates else '-'} | {det} |",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
