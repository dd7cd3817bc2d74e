"""Corner-point precision and recall of the shipped CNNs, per data_gen condition.

    python benchmarks/model_compare.py [--images 30] [--models default,report,mine=runs/x/model.keras] [--thresholds 0.5,0.4] [--conditions noisy,blur]

Each model scores whole 640×480 images (the default model decodes its corner map; the report's
patch classifier scores saddle-point candidates). A detection matches a visible true corner
within 1 px. This measures the networks alone, before refinement and grid assembly. It also
times the network step per image.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")

import numpy as np  # noqa: E402

from aicalib_tf.inference import corner_points  # noqa: E402
from aicalib_tf.metrics import point_detection_stats  # noqa: E402
from aicalib_tf.model import load_model  # noqa: E402
from data_gen import make_sample  # noqa: E402

CONDITIONS = ("clean", "noisy", "blur", "distorted", "occluded", "hard")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--images", type=int, default=30)
    ap.add_argument("--models", default="default,report",
                    help="comma list of shipped names (default, report), .keras paths or LABEL=PATH (default: %(default)s)")
    ap.add_argument("--seed", type=int, default=77)
    ap.add_argument("--thresholds", default="0.5", help="comma list of corner-weight thresholds (default: %(default)s)")
    ap.add_argument("--conditions", default=",".join(CONDITIONS))
    args = ap.parse_args(argv)
    thresholds = [float(t) for t in args.thresholds.split(",")]
    models = {}
    for spec in args.models.split(","):  # a shipped name, a .keras path, or LABEL=PATH
        label, _, path = spec.rpartition("=")
        models[label or spec] = load_model(path)
    print("| condition | model | threshold | precision | recall | F1 | loc median px | network ms/image |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for cond in args.conditions.split(","):
        samples = [make_sample(cond, args.seed, i, size=(640, 480)) for i in range(args.images)]
        for name, model in models.items():
            corner_points(model, samples[0].image)  # warm up the traced function
            for thr in thresholds:
                pairs, times = [], []
                for s in samples:
                    t = time.perf_counter()
                    pts, _ = corner_points(model, s.image, thr)
                    times.append(time.perf_counter() - t)
                    pairs.append((pts, s.corners[s.visible] if s.label["has_board"] else np.zeros((0, 2))))
                st = point_detection_stats(pairs, 1.0)
                print(f"| {cond} | {name} | {thr:g} | {st['precision']:.3f} | {st['recall']:.3f} | {st['f1']:.3f} | "
                      f"{st['loc_median_px']:.3f} | {1000 * np.median(times):.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
