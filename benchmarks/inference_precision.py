"""The corner-map model's validation figures and speed in float32 and in bfloat16 (the model card's table).

    python benchmarks/inference_precision.py [--model default] [--images 64] [--repeats 3]

Scores ``corner_points(model, image, 0.5, precision=P)`` on the fixed validation images of
``python -m aicalib_tf.train`` (preset ``train``, seed 900001; a match is within 1 px) for
P = float32 and bfloat16, and times network and decoding per image (median over images of the
fastest of ``--repeats`` calls). bfloat16 is only fast on a CPU with native bfloat16 arithmetic
(see :mod:`aicalib_tf.cnn.inference`); elsewhere its row shows the emulation's cost.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")

import numpy as np  # noqa: E402

from aicalib_tf.cnn.inference import corner_points, native_bfloat16  # noqa: E402
from aicalib_tf.cnn.point_metrics import point_detection_stats  # noqa: E402
from aicalib_tf.cnn.model import load_model  # noqa: E402
from aicalib_tf.cnn.train import validation_set  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", default="default", help="shipped name or .keras path (default: %(default)s)")
    ap.add_argument("--images", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    if args.images < 1 or args.repeats < 1:
        ap.error(f"--images and --repeats must be >= 1, got {args.images} and {args.repeats}")
    model = load_model(args.model)
    images, corners = validation_set("train", args.images, progress=False)
    print(f"model {args.model}; native bfloat16: {native_bfloat16()}\n")
    print("| precision | precision (metric) | recall | localisation median px | p95 px | ms per image (network and decoding) |")
    print("| --- | --- | --- | --- | --- | --- |")
    for precision in ("float32", "bfloat16"):
        corner_points(model, images[0], 0.5, precision=precision)  # trace
        pairs, times = [], []
        for img, gt in zip(images, corners):
            best = np.inf
            for _ in range(args.repeats):
                t = time.perf_counter()
                pts, _ = corner_points(model, img, 0.5, precision=precision)
                best = min(best, time.perf_counter() - t)
            times.append(best)
            pairs.append((pts, gt))
        st = point_detection_stats(pairs, 1.0)
        print(f"| {precision} | {st['precision']:.4f} | {st['recall']:.4f} | {st['loc_median_px']:.3f} | "
              f"{st['loc_p95_px']:.3f} | {1000 * np.median(times):.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
