"""The int8 model against float32: detections per named condition, in one process (issue 26).

    python benchmarks/int8_detection.py [--images 30] [--int8 default_int8|PATH.tflite]

Prints, per condition, hits / wrong boards / images with any board / corners found and the median
corner error of hits for each model, then issue 26's verdict (within one image per condition,
corner error within 5%; :func:`aicalib_tf.bench.model_detections.int8_verdict`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aicalib_tf.bench.model_detections import compare_models, verdict_line  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--images", type=int, default=30, help="images per named condition")
    ap.add_argument("--int8", default="default_int8")
    a = ap.parse_args(argv)
    result = compare_models({"float32": "default", "int8": a.int8}, a.images)
    print("| condition | float32 hits / wrong / found / corners, err px | int8 | ms float32 / int8 |")
    print("| --- | --- | --- | --- |")
    for cond, rec in result.items():
        cells = []
        for m in ("float32", "int8"):
            r = rec[m]
            err = f"{np.median(r['errors']):.4f}" if r["errors"].size else "-"
            cells.append(f"{r['hits']} / {r['wrong']} / {r['found']} / {r['corners']}, {err}")
        print(f"| {cond} | {cells[0]} | {cells[1]} | {rec['float32']['ms']:.1f} / {rec['int8']['ms']:.1f} |")
    print(verdict_line(result, "float32", "int8", a.images))
    return 0


if __name__ == "__main__":
    sys.exit(main())
