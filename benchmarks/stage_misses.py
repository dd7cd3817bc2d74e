"""Which stage of the detector loses each board it misses, judged against the truth.

    python benchmarks/stage_misses.py --conditions generalize --count 40 [--seed S] [--model PATH] [--show]

For each image of the named evaluate conditions (``aicalib_tf.bench.conditions``: the same renders,
``generalize`` for the close-up and steep-tilt conditions the detector was not tuned on), the shipped
pipeline (:func:`aicalib_tf.detect_corners` with the 9×6 pattern) is scored as evaluate scores it
(hit, wrong, miss). Each board not hit is then followed through the stages at full size, as
:mod:`aicalib_tf.detect.pipeline` runs them, with the true corners as the yardstick:

- **map**: the share of true corners with a network point (strong or weak) within 3 px;
- **candidates**: the share with a refined candidate within 1.5 px;
- **grid**: the most true corners one assembled grid holds (straight seeds, then bent ones), a
  grid point counting when it is within 2 px of a true corner;
- **rim**: whether a grid within the rim completion's reach (the pattern's extent, every point
  on a true corner, up to ``rim.MAX_MISSING`` corners missing, all on the outer ring) is made a
  full board by :func:`aicalib_tf.detect.chessboard.rim.rim_board` (placement and occlusion test);
- **order**: whether the board order accepts a grid that holds every true corner;
- **shading**: where the shading look (:func:`aicalib_tf.detect.chessboard.shading.flattened_look`), asked as
  the pipeline asks it with the largest grid, ends (``shading.LOOK_ENDS``: no region, not darkened, nothing
  new, no full board, unmarked corner, sigma, flat saddle, found), and where it searched, the map,
  candidates and grid stages again on its flattened region (``flat``);
- **unshear**: whether the un-shear look (:mod:`aicalib_tf.detect.chessboard.unshear`), asked with the
  full-size search's partial board, finds a complete board, and whether its corners are on the truth.

The stage blamed is the first that falls short: map (under 80% of the corners), candidates (under
80%, or a fifth fewer than the map had), grid (no grid with every corner, nor one within the rim
completion's reach), rim (such a grid, not completed), order (a grid with every corner refused),
else ``pipeline`` (the full-size stages find it: a scale, the quick pass or the zoom loses it).
The two looks are the recoveries from those stages' shortfalls, so they are traced beside the blame.
Prints one line per miss with these figures, the counts per condition and stage, and the counts of
the looks' ends over the misses.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from dataclasses import replace

import numpy as np

from aicalib_tf.bench.conditions import PATTERN, condition_samples, select_conditions
from aicalib_tf.bench.metrics import board_detection_outcome
from aicalib_tf.detect.chessboard.rim import MAX_MISSING, rim_board
from aicalib_tf.detect.chessboard.shading import flatten, flattened_look, local_mean, shading_box

STAGES = ("map", "candidates", "grid", "rim", "order", "pipeline")


def _recall(truth: np.ndarray, pts: np.ndarray, tol: float) -> np.ndarray:
    """(N,) bool: true corners (N, 2) with a point of (M, 2) within ``tol`` px."""
    if len(pts) == 0:
        return np.zeros(len(truth), bool)
    d = np.linalg.norm(truth[:, None, :] - np.asarray(pts, np.float64)[None, :, :], axis=2)
    return d.min(axis=1) <= tol


def trace(gray: np.ndarray, truth: np.ndarray, model, pattern=PATTERN, threshold: float = 0.5, looks: bool = True) -> dict:
    """The full-size stages on ``gray`` (H, W) float32 against ``truth`` (cols·rows, 2) px.

    Returns {"map", "candidates"}: shares of true corners found; "grid": most true corners in one
    grid; "grid_shape"; "rim_reach": a grid within the rim completion's reach; "rim": the rim
    completion makes a full board; "accepted": a grid with every corner passes the board order; "stage";
    with ``looks``, "shading" and "flat" (:func:`trace_shading`) and "unshear" (:func:`trace_unshear`).
    """
    from aicalib_tf.cnn.inference import weak_corner_points
    from aicalib_tf.detect import pipeline as pl

    n = len(truth)
    strong, _, lower = weak_corner_points(model, gray, threshold, pl.WEAK * threshold)
    weaker = lower()  # the points under the threshold, or nothing when the map has none
    net = np.concatenate([strong.reshape(-1, 2)] + ([np.asarray(weaker[0]).reshape(-1, 2)] if len(weaker) else []))
    smoothed = pl.Smoothed(gray, None)
    refined, scores, weak = pl.refined_points(model, gray, threshold, smoothed=smoothed, min_points=pl.MIN_CORNERS,
                                              weak=pl.WEAK)
    out = {"map": float(_recall(truth, net, 3.0).mean()), "candidates": float(_recall(truth, refined, 1.5).mean()),
           "grid": 0, "grid_shape": None, "rim_reach": False, "rim": False, "accepted": False}
    grids = []
    if len(refined) >= pl.MIN_CORNERS:
        smooth = smoothed.sigma(pl.RING_SIGMA)
        ref_amp = pl.typical_amplitude(smooth, refined, pl.MIN_CORNERS)
        propose = pl.proposer(smoothed, smooth, ref_amp, weak=weak)
        limit = max(pattern) + 1
        grids = pl.assemble_grids(refined, scores, gray=smooth, propose=propose, limit=limit)
        grids += pl.assemble_grids(refined, scores, gray=smooth, propose=propose.bent, limit=limit, bend=True)
        for g in grids:
            held = int(_recall(truth, g.points, 2.0).sum())
            on = _recall(g.points, truth, 2.0).all()
            if held > out["grid"] or (held == out["grid"] == n and on):
                out["grid"], out["grid_shape"] = held, list(g.shape)
            if held == n and len(g) == n and pl.full_board(g, scores, pattern, smooth) is not None:
                out["accepted"] = True
            out["rim_reach"] |= on and _in_rim_reach(g, pattern)
        out["rim"] = rim_board(grids, scores, pattern, smoothed, smooth, ref_amp) is not None
    out["stage"] = _blame(out, n)
    if looks:
        out["shading"], out["flat"] = trace_shading(gray, truth, model, grids, refined, pattern, threshold)
        out["unshear"] = trace_unshear(gray, truth, model, pattern, threshold)
    return out


def trace_shading(gray: np.ndarray, truth: np.ndarray, model, grids: list, refined: np.ndarray, pattern,
                  threshold: float) -> tuple[str, dict | None]:
    """Where the shading look ends for ``gray`` (H, W) float32 (one of ``shading.LOOK_ENDS``; "no grid" without
    one), asked with the largest of ``grids`` and the candidates ``refined`` (N, 2) px as the pipeline asks it;
    and, when it got as far as its flattened region, :func:`trace` (without the looks) on that region
    against ``truth`` (N, 2) px, else None."""
    from functools import partial as bind

    from aicalib_tf.cnn.inference import weak_corner_points
    from aicalib_tf.detect import pipeline as pl

    if not grids:
        return "no grid", None
    largest = max(grids, key=len)
    search = bind(pl._detect_at, pattern_size=pattern, model=model, threshold=threshold, partial_above=sum(pattern) ** 2)
    marks = bind(weak_corner_points, model, threshold=threshold, weak=pl.WEAK * threshold)
    why: list = []
    flattened_look(gray, pattern, largest, refined, search, marks, why=why)
    end = why[0] if why else "found"
    if end in ("no region", "not darkened"):
        return end, None
    x0, y0, x1, y1 = shading_box(largest.ij, largest.points, pattern, gray.shape[::-1])
    flat = flatten(gray[y0:y1, x0:x1], local_mean(gray[y0:y1, x0:x1]))
    return end, trace(flat, truth - np.array([x0, y0], np.float64), model, pattern, threshold, looks=False)


def trace_unshear(gray: np.ndarray, truth: np.ndarray, model, pattern, threshold: float) -> str:
    """The un-shear look on ``gray`` (H, W) float32, asked with the full-size search's partial board as the
    pipeline asks it: "none" (no complete board), "hit" or "wrong" (its corners against ``truth``)."""
    from aicalib_tf.detect import pipeline as pl

    seen = pl._detect_at(gray, pattern, model, threshold)
    got = pl._unsheared(gray, pattern, model, threshold, seen)
    if got is seen or not got.complete:
        return "none"
    return board_detection_outcome(np.asarray(got.corners, np.float64), truth, pattern)[0]


def _in_rim_reach(grid, pattern) -> bool:
    """Whether ``grid`` has the pattern's extent (either way round) and misses 1 to ``MAX_MISSING``
    positions, all on its outer ring: a grid the rim completion is asked to complete."""
    a, b = grid.shape
    if sorted((a, b)) != sorted(pattern) or not 0 < a * b - len(grid) <= MAX_MISSING:
        return False
    have = {(int(i), int(j)) for i, j in grid.ij}
    return all(i in (0, a - 1) or j in (0, b - 1) for i in range(a) for j in range(b) if (i, j) not in have)


def _blame(t: dict, n: int) -> str:
    if t["map"] < 0.8:
        return "map"
    if t["candidates"] < 0.8 or t["candidates"] < t["map"] - 0.2:
        return "candidates"
    if t["grid"] < n and not t["rim"]:
        return "rim" if t["rim_reach"] else "grid"
    if t["grid"] == n and not t["accepted"]:
        return "order"
    return "pipeline"


def stage_figures(t: dict, n: int) -> str:
    """One line of a miss's trace ``t`` (:func:`trace`) for a board of ``n`` corners: its blamed stage, the map's and
    the candidates' recall, the grid's corners and shape, and the rim completion's reach."""
    return (f"{t['stage']}: map {t['map']:.2f} cand {t['candidates']:.2f} grid {t['grid']}/{n} {t['grid_shape']} "
            f"rim {t['rim_reach']}/{t['rim']}")


def traced_misses(samples, model, counts: Counter, looks: bool = True, pattern=PATTERN):
    """Detect each (index, Sample) of ``samples`` (boards of ``pattern`` (cols, rows)); add its outcome ("hit" /
    "wrong" / "miss") and its detection time ("seconds") to ``counts``, and each miss's blamed stage; yield
    (index, sample, Detection, outcome, :func:`trace` of it) for every board not hit (``looks``: trace the second
    looks too)."""
    from aicalib_tf import detect_corners
    from aicalib_tf.io import as_gray_float

    for index, s in samples:
        t0 = time.perf_counter()
        det = detect_corners(s.image, pattern, model=model)
        counts["seconds"] += time.perf_counter() - t0
        outcome, _ = board_detection_outcome(det.corners if det.complete else None, s.corners, pattern)
        counts[outcome] += 1
        if outcome == "hit":
            continue
        t = trace(as_gray_float(s.image), s.corners, model, pattern, looks=looks)  # the pipeline's grey in [0, 1]
        counts[t["stage"]] += 1
        yield index, s, det, outcome, t


def run_condition(cond, count: int, model, show: bool) -> Counter:
    """Counts of outcomes, blamed stages and the looks' ends (keys "shading: END", "unshear: END") over ``count``
    images of ``cond``; prints each miss."""
    counts: Counter = Counter()
    for index, s, det, outcome, t in traced_misses(condition_samples(cond, count), model, counts):
        counts[f"shading: {t['shading']}"] += 1
        counts[f"unshear: {t['unshear']}"] += 1
        lab = s.label
        if show:
            f = t["flat"]
            flat = "" if f is None else f" (flat: map {f['map']:.2f} cand {f['candidates']:.2f} grid {f['grid']}/{len(s.corners)})"
            print(f"  {cond.name} #{index}: {outcome}, {stage_figures(t, len(s.corners))} accepted {t['accepted']} "
                  f"| shading {t['shading']}{flat} | unshear {t['unshear']} | "
                  f"{lab['distortion_model']} {2 * (lab['max_theta_deg'] or 0):.0f}° reason {det.reason!r}", flush=True)
    return counts


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--conditions", default="generalize", help="evaluate condition names, or 'generalize'")
    ap.add_argument("--count", type=int, default=40, help="images per condition")
    ap.add_argument("--model", default=None, help="corner model (default: the shipped one)")
    ap.add_argument("--show", action="store_true", help="one line per miss")
    ap.add_argument("--seed", type=int, default=None, help="data_gen seed in place of the conditions' (other scenes)")
    args = ap.parse_args(argv)
    from aicalib_tf.cnn.model import load_model
    from aicalib_tf.cnn.spec import DETECTOR_NETWORK

    model = load_model(args.model or DETECTOR_NETWORK)
    print(f"| condition | hit | wrong | miss | {' | '.join(STAGES)} |\n|---|---|---|---|{'---|' * len(STAGES)}")
    rows = []
    for cond in select_conditions(args.conditions):
        cond = cond if args.seed is None else replace(cond, seed=args.seed)
        c = run_condition(cond, args.count, model, args.show)
        rows.append(f"| {cond.name} | {c['hit']} | {c['wrong']} | {c['miss']} | "
                    + " | ".join(str(c[s]) for s in STAGES) + " |")
        print(rows[-1], flush=True)
        looks = sorted(k for k in c if k.startswith(("shading: ", "unshear: ")))
        print(f"|   looks over its misses: {', '.join(f'{k} {c[k]}' for k in looks) or 'none'} |", flush=True)
    return 0



def family_parser(doc: str, *more: tuple[str, dict], show: str = "one line per miss") -> argparse.ArgumentParser:
    """The family benchmarks' options (--split, --count, --seed, --families, --model), then each (flag, keywords)
    of ``more``, then --show with the help ``show``; the description is ``doc``'s first line."""
    ap = argparse.ArgumentParser(description=doc.split("\n")[0])
    ap.add_argument("--split", choices=("tune", "held-out", "both"), default="both")
    ap.add_argument("--count", type=int, default=12, help="images per family")
    ap.add_argument("--seed", type=int, default=301, help="data_gen seed of the families' renders")
    ap.add_argument("--families", default=None, help="comma-separated family names (default: all)")
    ap.add_argument("--model", default=None, help="corner model (default: the shipped one)")
    for flag, keywords in more:
        ap.add_argument(flag, **keywords)
    ap.add_argument("--show", action="store_true", help=show)
    return ap


def family_setup(prog: str, ap: argparse.ArgumentParser, argv, known: dict, check=None):
    """Parse ``argv`` with ``ap`` (:func:`family_parser`): (args, family names, splits, the corner model), or None
    after one line "``prog``: why" on stderr for a family not in ``known``, --count under 1 or ``check(args)``'s
    message (None where the arguments are right)."""
    args = ap.parse_args(argv)
    names = list(known) if args.families is None else args.families.split(",")
    unknown = [n for n in names if n not in known]
    why = (f"unknown families {unknown} (known: {', '.join(known)})" if unknown else
           f"--count must be >= 1, got {args.count}" if args.count < 1 else check(args) if check else None)
    if why:
        print(f"{prog}: {why}", file=sys.stderr)
        return None
    from aicalib_tf.cnn.model import load_model
    from aicalib_tf.cnn.spec import DETECTOR_NETWORK

    splits = ("tune", "held-out") if args.split == "both" else (args.split,)
    return args, names, splits, load_model(args.model or DETECTOR_NETWORK)


def print_family_tables(names: list[str], splits, run, extra: tuple[tuple[str, str], ...] = ()) -> None:
    """One table row per family of ``names`` and split of ``splits`` (``run(name, split)``: its Counter of hit /
    wrong / miss, blamed stages and "seconds") and each split's total: the outcomes, the stages, a column per
    (header, Counter key) of ``extra``, and ms per image."""
    heads = list(STAGES) + [head for head, _ in extra]
    print(f"| family | split | hit | wrong | miss | {' | '.join(heads)} | ms/image |\n"
          f"|---|---|---|---|---|{'---|' * len(heads)}---|")

    def row(c: Counter, first: str) -> str:
        n = c["hit"] + c["wrong"] + c["miss"]
        cells = [str(c[s]) for s in STAGES] + [str(c[key]) for _, key in extra] + [f"{1000 * c['seconds'] / n:.0f}"]
        return f"| {first} | {c['wrong']} | {c['miss']} | " + " | ".join(cells) + " |"

    for split in splits:
        total: Counter = Counter()
        for name in names:
            c = run(name, split)
            total.update(c)
            print(row(c, f"{name} | {split} | {c['hit']}"), flush=True)
        n = total["hit"] + total["wrong"] + total["miss"]
        print(row(total, f"**all** | {split} | {total['hit']}/{n} ({100 * total['hit'] / n:.1f}%)"), flush=True)


def families_main(prog: str, doc: str, known: dict, run_family, argv=None, extra: tuple[tuple[str, str], ...] = ()) -> int:
    """A family benchmark's main: :func:`family_parser` options, then :func:`print_family_tables` of
    ``run_family(name, split, seed, count, model, show)`` over the chosen families of ``known``; 2 on bad arguments."""
    got = family_setup(prog, family_parser(doc), argv, known)
    if got is None:
        return 2
    args, names, splits, model = got
    print_family_tables(names, splits, lambda name, split: run_family(name, split, args.seed, args.count, model, args.show),
                        extra)
    return 0


if __name__ == "__main__":
    sys.exit(main())
