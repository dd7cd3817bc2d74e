"""How thin each board's squares are in the image, against which detectors found the board.

    python benchmarks/board_thickness.py --results reports/DATE/results.csv [--condition barrel] [--show 25]

For each image of an evaluate condition (``aicalib_tf.bench.conditions``: the same renders), every
square of the true corner grid is measured as the quadrilateral of its four corners: its area over
its longest side, i.e. its thickness in px across the longest side (a square seen face-on: its
side; squeezed by a wide-angle lens or a steep tilt: much less). The board's thinnest square and
its 10th percentile are printed beside each detector's outcome in the results.csv, thinnest
boards first, then the thinnest board each detector found.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
import pandas as pd

from aicalib_tf.bench.conditions import PATTERN, condition_samples, select_conditions


def square_thickness(corners: np.ndarray, pattern=PATTERN) -> np.ndarray:
    """((rows-1)·(cols-1),) px: each square's area over its longest side; corners (cols·rows, 2) OpenCV order."""
    cols, rows = pattern
    c = np.asarray(corners, np.float64).reshape(rows, cols, 2)
    p00, p01, p10, p11 = c[:-1, :-1], c[:-1, 1:], c[1:, :-1], c[1:, 1:]
    d1, d2 = p11 - p00, p10 - p01
    area = 0.5 * np.abs(d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0])
    sides = np.stack([np.linalg.norm(a - b, axis=-1) for a, b in ((p01, p00), (p11, p10), (p10, p00), (p11, p01))])
    return (area / sides.max(axis=0)).ravel()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--results", required=True, help="an evaluate results.csv")
    ap.add_argument("--condition", default="barrel")
    ap.add_argument("--show", type=int, default=25, help="thinnest boards to list")
    args = ap.parse_args(argv)
    res = pd.read_csv(args.results)
    res = res[res.condition == args.condition]
    if res.empty:
        raise SystemExit(f"{args.results}: no rows for condition {args.condition!r}")
    cond = select_conditions(args.condition)[0]
    rows = {}
    for i, s in condition_samples(cond, int(res["index"].max()) + 1):
        if s.label["has_board"]:
            t = square_thickness(s.corners)
            rows[i] = {"thinnest_px": t.min(), "p10_px": np.percentile(t, 10), "median_px": np.median(t)}
    df = pd.DataFrame.from_dict(rows, orient="index")
    for det, g in res.groupby("detector"):
        df[det] = g.set_index("index").outcome
    df = df.sort_values("thinnest_px")
    pd.set_option("display.width", 200)
    print(df.head(args.show).round(2).to_string())
    print()
    for det in res.detector.unique():
        hit = df[df[det] == "hit"]
        print(f"{det}: {len(hit)}/{len(df)} hits; thinnest board found {hit.thinnest_px.min():.2f} px; "
              f"boards missed with thinnest square ≥ that: {int(((df[det] != 'hit') & (df.thinnest_px >= hit.thinnest_px.min())).sum())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
