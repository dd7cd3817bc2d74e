"""Faint corners of full boards on the close-up families: each corner's contrast over the noise against its error.

    python benchmarks/faint_corners.py [--split tune|held-out|both] [--count 12] [--seed 301] [--families NAME,...]
                                       [--model PATH] [--floors 0.5,1,1.5,2,2.5] [--show]

Each full board the detector finds on ``closeup_families.py``'s renders (its families, lens splits and seeds) is
aligned to the truth as evaluate scores it (a hit: every corner within 2 px; wrong: one further off), and every corner
gets its contrast over the noise about it (``cnr``, :func:`aicalib_tf.detect.corners.contrast.corner_contrast`) and its
error. Prints per split: the corners per cnr band (their errors' median, 90th percentile, largest, RMS per axis, and
the median localisation bound), then per floor the full boards that refusing the corners under it would turn into
partial boards (hits and wrong boards), the least ``z`` of a hit's corner and of each wrong board's (a corner under
−``REVERSED_Z`` is refused: :func:`aicalib_tf.detect.corners.contrast.without_reversed`), and the CPU time of the
measure per board. ``--show`` lists each wrong
board's worst corner and each refused hit's faintest.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from aicalib_tf.bench.conditions import PATTERN  # noqa: E402

BANDS = (-np.inf, 1.0, 2.0, 3.0, 5.0, 10.0, np.inf)


def board_rows(split: str, names: list[str], seed: int, count: int, model):
    """Yield (family, index, errors (N,), cnr (N,), bound (N,), CPU s of the measure, z (N,)) for each full board found."""
    import closeup_families as cf
    from aicalib_tf import detect_corners
    from aicalib_tf.bench.metrics import align_to_truth
    from aicalib_tf.detect.corners.contrast import corner_contrast
    from aicalib_tf.io import as_gray_float

    cols, rows = PATTERN
    ids = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), axis=-1).reshape(-1, 2)  # the truth's order
    for name in names:
        cond = cf.family_condition(name, split, seed)
        for index, s in cf.samples(cond, count, bool(cf.families()[name].get("rim"))):
            det = detect_corners(s.image, PATTERN, model=model)
            if not det.complete:
                continue
            truth = np.asarray(s.corners, np.float64)
            aligned = align_to_truth(det.corners, truth, PATTERN)
            gray = s.image if s.image.ndim == 2 and s.image.dtype == np.uint8 else as_gray_float(s.image)
            t0 = time.process_time()
            m = corner_contrast(gray, aligned, ids)
            cpu = time.process_time() - t0
            yield name, index, np.linalg.norm(aligned - truth, axis=1), m["cnr"], m["bound"], cpu, m["z"]


def report(split: str, boards: list, floors: list[float], show: bool) -> None:
    """Print the bands, the floors' refusals and the measure's CPU time for one split's boards."""
    err = np.concatenate([b[2] for b in boards])
    cnr = np.concatenate([b[3] for b in boards])
    bound = np.concatenate([b[4] for b in boards])
    wrong = [b for b in boards if b[2].max() > 2.0]
    print(f"\n{split}: {len(boards)} full boards ({len(wrong)} wrong), {len(err)} corners ({int(np.isnan(cnr).sum())} unmeasured)")
    print("| cnr | corners | error median | p90 | largest | RMS per axis | bound median |\n|---|---|---|---|---|---|---|")
    for lo, hi in zip(BANDS[:-1], BANDS[1:]):
        m = (cnr >= lo) & (cnr < hi)
        if m.any():
            print(f"| {lo:g}–{hi:g} | {int(m.sum())} | {np.median(err[m]):.3f} | {np.percentile(err[m], 90):.3f} | "
                  f"{err[m].max():.3f} | {np.sqrt(np.mean(err[m] ** 2) / 2):.3f} | {np.nanmedian(bound[m]):.3f} |")
    print("| floor (cnr) | hits refused | wrong refused |\n|---|---|---|")
    for f in floors:
        low = [b for b in boards if np.nanmin(np.append(b[3], np.inf)) < f]
        print(f"| {f:g} | {sum(b[2].max() <= 2.0 for b in low)} | {sum(b[2].max() > 2.0 for b in low)} |")
    least = [np.nanmin(np.append(b[6], np.inf)) for b in boards]
    hits = [z for z, b in zip(least, boards) if b[2].max() <= 2.0]
    print(f"least z of a corner: hits {min(hits, default=np.inf):.2f}; wrong boards "
          + ", ".join(f"{z:.2f}" for z, b in zip(least, boards) if b[2].max() > 2.0))
    cpu = np.array([b[5] for b in boards])
    print(f"measure CPU per board: median {1e6 * np.median(cpu):.0f} us, largest {1e6 * cpu.max():.0f} us")
    if show:
        for b in wrong:
            k = int(np.argmax(b[2]))
            print(f"  wrong {b[0]} #{b[1]}: corner {k} {b[2][k]:.2f} px off, cnr {b[3][k]:.2f}")
        for b in boards:
            k = int(np.nanargmin(np.where(np.isnan(b[3]), np.inf, b[3]))) if np.isfinite(b[3]).any() else 0
            if b[2].max() <= 2.0 and b[3][k] < max(floors):
                print(f"  hit {b[0]} #{b[1]}: faintest corner {k} cnr {b[3][k]:.2f}, {b[2][k]:.2f} px off (board's largest {b[2].max():.2f})")


def _floors(text: str) -> list[float]:
    """The comma-separated cnr floors of ``text``; [] where one is not a number."""
    try:
        return [float(v) for v in text.split(",")]
    except ValueError:
        return []


def main(argv=None) -> int:
    import closeup_families as cf
    from stage_misses import family_parser, family_setup

    ap = family_parser(__doc__, ("--floors", {"default": "0.5,1,1.5,2,2.5",
                                              "help": "comma-separated cnr floors to count refusals for"}),
                       show="each wrong board's worst corner, each refused hit's faintest")
    got = family_setup("faint_corners", ap, argv, cf.families(),
                       check=lambda a: None if _floors(a.floors) else f"--floors must be numbers, got {a.floors!r}")
    if got is None:
        return 2
    args, names, splits, model = got
    for split in splits:
        report(split, list(board_rows(split, names, args.seed, args.count, model)), _floors(args.floors), args.show)
    return 0


if __name__ == "__main__":
    sys.exit(main())
