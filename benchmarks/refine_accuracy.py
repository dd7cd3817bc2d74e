"""Subpixel refiners against data_gen's exact corners: our saddle fit versus OpenCV's cornerSubPix.

    python benchmarks/refine_accuracy.py [--images 20] [--start 0.7] [--shading]

Each refiner starts from the true corners moved by a random offset of up to --start px (what a
CNN peak gives) and the error after refinement is measured, per condition: clean (σ = 0.6 px
lens blur) and Gaussian noise σ = 10, 20 and 40 grey levels on top of it; with --shading also
evaluate's ``shading`` condition (illumination gradient and a hard shadow). "windowed" is the
detector's own refinement (:func:`aicalib_tf.detect.corners.refine.refine_windowed`: the window sized to the
squares, and the shadow-robust fit where the window is not point-symmetric); "windowed + polish" adds
the per-corner ramp fit (:func:`aicalib_tf.detect.corners.refine.polish`), which the detector does not
use (it polishes whole boards, :func:`aicalib_tf.detect.corners.refine.polish_board`, which needs a board's ids).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace

import numpy as np

from aicalib_tf.detect.corners.junctions import nearest_spacing
from aicalib_tf.bench.metrics import corner_error_stats
from aicalib_tf.detect.corners.refine import Smoothed, polish, refine_saddle, refine_subpix, refine_windowed
from data_gen import make_sample
from data_gen.presets import Rule, get_preset

REFINERS = {
    "saddle s1.0 r3": lambda g, p: refine_saddle(g, p, sigma=1.0, radius=3),
    "saddle s1.5 r4": lambda g, p: refine_saddle(g, p, sigma=1.5, radius=4),
    "saddle s2.0 r5": lambda g, p: refine_saddle(g, p, sigma=2.0, radius=5),
    "cornerSubPix hw3": lambda g, p: refine_subpix(g, p, half_window=3),
    "cornerSubPix hw5": lambda g, p: refine_subpix(g, p, half_window=5),
    "windowed": lambda g, p: refine_windowed(Smoothed(g), p, nearest_spacing(p)),
    "windowed + polish": lambda g, p: _polished(Smoothed(g), p),
}


def _polished(smoothed, p):
    """The detector's last step on a board's corners: :func:`refine_windowed`, then :func:`polish`."""
    out, ok = refine_windowed(smoothed, p, nearest_spacing(p))
    return polish(smoothed, out, nearest_spacing(p)), ok


def condition(noise: float):
    rules = (Rule.of("gaussian_blur", sigma=0.6),) + ((Rule.of("gaussian_noise", sigma=noise),) if noise else ())
    return replace(get_preset("clean", rules=rules), name=f"noise{noise:g}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--images", type=int, default=20)
    ap.add_argument("--start", type=float, default=0.7, help="px, the largest starting offset")
    ap.add_argument("--shading", action="store_true", help="also evaluate's shading condition")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    print("| condition | refiner | corners | ok % | median px | p95 px |\n|---|---|---|---|---|---|")
    presets = [condition(noise) for noise in (0, 10, 20, 40)]
    if args.shading:
        from aicalib_tf.bench.conditions import select_conditions

        presets.append(select_conditions("shading")[0].preset)
    for preset in presets:
        samples = [make_sample(preset, 0, i, pattern=(9, 6)) for i in range(args.images)]
        starts = []
        for s in samples:
            gt = s.corners[s.visible]
            ang = rng.uniform(0, 2 * np.pi, len(gt))
            rad = args.start * np.sqrt(rng.uniform(0, 1, len(gt)))
            starts.append(gt + np.stack([np.cos(ang), np.sin(ang)], 1) * rad[:, None])
        for name, fn in REFINERS.items():
            errs, oks = [], []
            for s, st in zip(samples, starts):
                out, ok = fn(s.image.astype(np.float32), st)
                errs.append(np.linalg.norm(out - s.corners[s.visible], axis=1))
                oks.append(ok)
            e, ok = np.concatenate(errs), np.concatenate(oks)
            st = corner_error_stats(e)
            print(f"| {preset.name} | {name} | {st['count']} | {100 * ok.mean():.1f} | {st['median']:.4f} | {st['p95']:.4f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
