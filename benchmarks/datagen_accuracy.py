"""How well do OpenCV's corners agree with data_gen's ground truth on clean renders?

    python benchmarks/datagen_accuracy.py [--images 40] [--pattern 9x6] [--window 5]

Renders `clean` boards, runs cv2.findChessboardCorners + cv2.cornerSubPix (each half-window
of --windows, px) and prints the per-corner error distribution against the stored truth. This is the
external check that the renderer and the labels share OpenCV's pixel-centre convention.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from aicalib_tf.detect.opencv import opencv_classic
from aicalib_tf.bench.metrics import align_to_truth, corner_error_stats
from data_gen import make_sample
from aicalib_tf.geometry.pattern import parse_pattern


WRONG_PX = 2.0  # DESIGN.md: a board with a matched corner off by more than this is a wrong detection


def opencv_errors(n_images: int, pattern: tuple[int, int], window: int, seed: int = 0, preset: str = "clean"):
    """Per-corner px errors of findChessboardCorners + cornerSubPix on correct boards.

    Returns (errors (M,) px, boards found, wrong boards). Wrong boards (a corner off by more than
    ``WRONG_PX``: OpenCV's own mistakes) are counted, not mixed into the error distribution.
    """
    errs, found, wrong = [], 0, 0
    for i in range(n_images):
        s = make_sample(preset, seed, i, pattern=pattern)
        ok, c = opencv_classic(s.image, pattern, half_window=window)
        if not ok:
            continue
        found += 1
        e = np.linalg.norm(align_to_truth(c, s.corners, pattern) - s.corners, axis=1)
        if e.max() > WRONG_PX:
            wrong += 1
            continue
        errs.append(e)
    return (np.concatenate(errs) if errs else np.zeros(0)), found, wrong


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--images", type=int, default=40)
    ap.add_argument("--pattern", default="9x6")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--windows", default="3,4,5", help="cornerSubPix half-windows to try")
    a = ap.parse_args(argv)
    pattern = parse_pattern(a.pattern)
    print(f"clean preset, {a.images} images, pattern {a.pattern}, seed {a.seed}")
    print("half-window  found  wrong  corners  median_px  p95_px  p99_px  max_px")
    for w in (int(v) for v in a.windows.split(",")):
        e, found, wrong = opencv_errors(a.images, pattern, w, a.seed)
        st = corner_error_stats(e)
        print(
            f"{w:11d}  {found:5d}  {wrong:5d}  {st['count']:7d}  {st['median']:9.4f}  {st['p95']:6.4f}"
            f"  {st['p99']:6.4f}  {st['max']:6.4f}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
