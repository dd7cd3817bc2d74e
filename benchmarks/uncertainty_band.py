"""Does the predicted halves difference hold the measured one? The formal covariance against the honest one.

    .venv/bin/python benchmarks/uncertainty_band.py [--sets opencv_left udacity_lane_cal ocam_fisheye]
        [--splits 40] [--synthetic 10] [--data /work/shared/data]

Each real set's photos go through the calibrate command's detector once (``real_split_noise.detections``)
and the lens model ``auto`` chooses on all of them is kept; then ``--splits`` random half-splits
(``real_split_noise.random_split``, seeds 0..N-1) are each calibrated (flat board, that model), their
projection difference measured (rotation fitted over the cells either half's boards cover, median over
them, as ``benchmarks/real_split_noise.py`` scores a split) and predicted by
:func:`aicalib_tf.calib.quality.predicted_half_difference` (its 10-90% band of one draw) from

- ``formal``: each half's ``cal.covariance`` (every corner an independent measurement);
- ``honest``: :func:`aicalib_tf.calib.quality.honest_covariance` (each half's covariance times its own
  view-cluster inflation κ, :mod:`aicalib_tf.calib.inflation`), what the calibrate command prints.

An honest band holds the measured difference on about 80% of the splits, with the misses on both
sides. ``--synthetic N``: N sets of 14 views (tests.calib.synthetic, 9x6 board, σ 0.3 px) of a plumb_bob
lens, 3 random splits each, with independent corner noise (the formal band is right there) and with
an error shared within each view (a random affine shift of its corners, about 1 px), where it is not.
Printed per set: each band's share of splits inside, below and above, and the mean predicted and
measured differences.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import real_repeatability as rr  # noqa: E402
import real_split_noise as rsn  # noqa: E402

from aicalib_tf.calib import quality as Q  # noqa: E402
from aicalib_tf.calib.diff import board_coverage, projection_diff  # noqa: E402
from aicalib_tf.calib.fit import View, calibrate_camera  # noqa: E402

BANDS = ("formal", "honest")
SYN_VIEWS, SYN_NOISE, SYN_SHARED = 14, 0.3, 1.0


def split_row(halves, pattern, square, size, model, circle=None) -> dict:
    """{"measured": px, band: {"p10", "p90", "mean"} px, "kappa": [κ_a, κ_b]} for one split (two View lists)."""
    cals = [calibrate_camera(h, pattern, square, size, model=model, image_circle=circle) for h in halves]
    covered = np.zeros(rr.GRID[0] * rr.GRID[1], bool)
    for c in cals:
        covered |= board_coverage(c.lens, c.pattern_size, c.square_size, c.rvecs, c.tvecs, rr.GRID)
    measured = projection_diff(cals[0].lens, cals[1].lens, grid=rr.GRID, covered=covered)["covered_stats"]["median"]
    honest = [Q.honest_covariance(c, h, covered, rr.GRID) for c, h in zip(cals, halves)]
    row = {"measured": float(measured), "kappa": [k for _, k in honest]}
    for band, covs in (("formal", [c.covariance for c in cals]), ("honest", [c for c, _ in honest])):
        p = Q.predicted_half_difference(cals[0], cals[1], covered, grid=rr.GRID, covariances=covs)
        row[band] = {"p10": p["p10_covered"], "p90": p["p90_covered"], "mean": p["median_covered"]}
    return row


def real_rows(name, folder, n_splits) -> list[dict]:
    pattern = tuple(rr.SETS[name][0])
    files, size, _ = rr.photos(folder)
    views, circle = rsn.detections(files, pattern)
    model = calibrate_camera([v for v in views if v is not None], pattern, 1.0, size, image_circle=circle).model
    rows = []
    for seed in range(n_splits):
        halves = [[views[i] for i in h if views[i] is not None] for h in rsn.random_split(len(views), seed)]
        rows.append(split_row(halves, pattern, 1.0, size, model, circle))
        print(f"{name} ({model}) split {seed}: measured {rows[-1]['measured']:.3f} px, κ "
              f"{rows[-1]['kappa'][0]:.2f}/{rows[-1]['kappa'][1]:.2f}", flush=True)
    return rows


def synthetic_rows(n_sets: int, shared: float) -> list[dict]:
    """Rows of ``n_sets`` synthetic sets (module docstring), ``shared`` px: the within-view error (0: none)."""
    from aicalib_tf.geometry.lens import Lens
    from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views

    size = (1280, 960)
    lens = Lens("plumb_bob", [[800, 0, 640], [0, 800, 480], [0, 0, 1]], [-0.2, 0.05, 0, 0, 0], size)
    rows = []
    for s in range(n_sets):
        rng = np.random.default_rng(s)
        views = synthetic_views(lens, n=SYN_VIEWS, noise=SYN_NOISE, seed=s)
        if shared:
            views = [View(v.name, v.corners + (v.corners - v.corners.mean(0)) @ (shared * rng.standard_normal((2, 2)) / 200).T
                          + shared * rng.standard_normal(2), v.ids) for v in views]
        for k in range(3):
            halves = [[views[i] for i in h] for h in rsn.random_split(len(views), 1000 * s + k)]
            rows.append(split_row(halves, PATTERN, SQUARE, size, "plumb_bob"))
    return rows


def summary(title: str, rows: list[dict]) -> list[str]:
    m = np.array([r["measured"] for r in rows])
    kappa = np.concatenate([r["kappa"] for r in rows])
    out = [f"{title} ({len(rows)} splits; measured mean {m.mean():.3g} px; κ median {np.median(kappa):.2f}, "
           f"10-90% {np.percentile(kappa, 10):.2f}-{np.percentile(kappa, 90):.2f}):"]
    for band in BANDS:
        lo, hi = np.array([r[band]["p10"] for r in rows]), np.array([r[band]["p90"] for r in rows])
        out.append(f"  {band:7s} inside {np.mean((m >= lo) & (m <= hi)):.0%} (below {np.mean(m < lo):.0%}, above "
                   f"{np.mean(m > hi):.0%}); predicted mean {np.mean([r[band]['mean'] for r in rows]):.3g} px")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sets", nargs="+", default=list(rr.SETS), choices=list(rr.SETS))
    ap.add_argument("--splits", type=int, default=40)
    ap.add_argument("--synthetic", type=int, default=10, help="synthetic sets per case (0: none)")
    ap.add_argument("--data", default=str(rr.SHARED))
    args = ap.parse_args(argv)
    lines, seen = [], set()
    for name, folder in rr.find_sets(args.sets, Path(args.data)):
        if name not in seen:
            seen.add(name)
            lines += summary(name, real_rows(name, folder, args.splits))
    if args.synthetic:
        lines += summary(f"synthetic, independent corner noise σ {SYN_NOISE} px", synthetic_rows(args.synthetic, 0.0))
        lines += summary(f"synthetic, plus an error shared within each view (~{SYN_SHARED} px)",
                         synthetic_rows(args.synthetic, SYN_SHARED))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
