"""The int8 model against float32: detections per named condition, in one process.

    python benchmarks/int8_detection.py [--images 30] [--int8 default_int8|PATH.tflite] [--base default]

``--int8`` may be given several times (other networks too, e.g. a float and an int8 export): each is
compared with ``--base`` on the same images, one table and one verdict each.

Prints, per condition, hits / wrong boards / images with any board / corners found and the median
corner error of hits for each model, then the int8 verdict (within one image per condition,
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
    ap.add_argument("--int8", action="append", default=None, metavar="MODEL",
                    help="the model compared with --base (repeatable; default: default_int8)")
    ap.add_argument("--base", default="default", help="the reference model (default: %(default)s)")
    a = ap.parse_args(argv)
    others = a.int8 or ["default_int8"]
    labels = {"int8": others[0]} if len(others) == 1 else {name: name for name in others}
    result = compare_models({"float32": a.base, **labels}, a.images)
    for label, name in labels.items():
        print(f"\n{name} against {a.base}:")
        print(f"| condition | {a.base} hits / wrong / found / corners, err px | {name} | ms {a.base} / {name} |")
        print("| --- | --- | --- | --- |")
        for cond, rec in result.items():
            cells = []
            for m in ("float32", label):
                r = rec[m]
                err = f"{np.median(r['errors']):.4f}" if r["errors"].size else "-"
                cells.append(f"{r['hits']} / {r['wrong']} / {r['found']} / {r['corners']}, {err}")
            print(f"| {cond} | {cells[0]} | {cells[1]} | {rec['float32']['ms']:.1f} / {rec[label]['ms']:.1f} |")
        print(verdict_line(result, "float32", label, a.images))
    return 0


if __name__ == "__main__":
    sys.exit(main())
