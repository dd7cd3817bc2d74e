"""Full-board detection: the CNN pipeline against OpenCV's two detectors on data_gen renders.

    python benchmarks/detect_compare.py [--images 30] [--conditions clean,noisy,blur,distorted]

For each condition, renders --images 640×480 boards of 9×6 inner corners (seed 21) and runs every
detector on the same images. A hit is a full board whose corners are all within 2 px of the truth
after the board's symmetries (DESIGN.md); a full board with any corner further off is a wrong
detection. Errors are over the corners of hits. Times are per image, in this one process.
A precursor of ``python -m aicalib_tf.evaluate`` (issue 6).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")

import numpy as np  # noqa: E402

from aicalib_tf.baselines import opencv_classic, opencv_sb  # noqa: E402
from aicalib_tf.detect import find_chessboard_corners  # noqa: E402
from aicalib_tf.metrics import align_to_truth, corner_error_stats  # noqa: E402
from aicalib_tf.model import load_model  # noqa: E402
from data_gen import make_sample  # noqa: E402

PATTERN = (9, 6)
WRONG_PX = 2.0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--images", type=int, default=30)
    ap.add_argument("--conditions", default="clean,noisy,blur,distorted,occluded")
    ap.add_argument("--model", default="default")
    args = ap.parse_args(argv)
    model = load_model(args.model)
    detectors = {
        "cnn": lambda img: find_chessboard_corners(img, PATTERN, model=model),
        "opencv": lambda img: opencv_classic(img, PATTERN),
        "opencv-sb": lambda img: opencv_sb(img, PATTERN),
    }
    detectors["cnn"](make_sample("clean", 0, 0, pattern=PATTERN).image)  # warm up
    print("| condition | detector | full boards | wrong | corner median px | p95 px | ms median | ms max |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for cond in args.conditions.split(","):
        samples = [make_sample(cond, 21, i, pattern=PATTERN, size=(640, 480)) for i in range(args.images)]
        for name, fn in detectors.items():
            hits = wrong = 0
            errs, times = [], []
            for s in samples:
                t = time.perf_counter()
                ok, corners = fn(s.image)
                times.append(1000 * (time.perf_counter() - t))
                if not ok:
                    continue
                e = np.linalg.norm(align_to_truth(np.asarray(corners).reshape(-1, 2), s.corners, PATTERN) - s.corners, axis=1)
                if e.max() > WRONG_PX:
                    wrong += 1
                else:
                    hits += 1
                    errs.append(e)
            st = corner_error_stats(np.concatenate(errs) if errs else np.zeros(0))
            print(f"| {cond} | {name} | {hits}/{len(samples)} | {wrong} | {st['median']:.4f} | {st['p95']:.4f} | "
                  f"{np.median(times):.1f} | {max(times):.1f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
