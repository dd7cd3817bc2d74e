"""Are two evaluate runs' detections the same? (a speed change must not change results)

    python benchmarks/compare_results.py BEFORE/results.csv AFTER/results.csv [--detector cnn]

Rows are matched by (condition, index, detector). Same means, per row: the outcome (hit, wrong,
partial, miss, false board), the corners found, correct and wrong ids; and over all hits the
median and RMS corner error within ``--tolerance`` (default 2%) of before. Prints the rows that
differ and the summary; exit status 1 when anything differs beyond that.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys

KEY = ("condition", "index", "detector")
EXACT = ("outcome", "complete", "n_corners", "correct", "wrong_ids")


def read_rows(path: str, detector: str) -> dict:
    """{(condition, index, detector): row} of one results.csv, for one detector."""
    with open(path, newline="", encoding="utf-8") as fh:
        return {tuple(r[k] for k in KEY): r for r in csv.DictReader(fh) if r["detector"] == detector}


def _floats(rows, name: str) -> list[float]:
    vals = (float(r[name]) for r in rows if r["outcome"] == "hit" and r[name] not in ("", "nan"))
    return [v for v in vals if math.isfinite(v)]


def compare(before: dict, after: dict, tolerance: float) -> tuple[list[str], dict]:
    """Differences (lines of text) and a summary: rows, exact differences, corner-error change."""
    lines = []
    if set(before) != set(after):
        lines.append(f"rows differ: {len(set(before) ^ set(after))} keys in one run only")
    common = sorted(set(before) & set(after))
    for k in common:
        diff = [f"{f} {before[k][f]} -> {after[k][f]}" for f in EXACT if before[k][f] != after[k][f]]
        if diff:
            lines.append(f"{'/'.join(k)}: " + ", ".join(diff))
    summary = {"rows": len(common), "differing_rows": len(lines)}
    for name in ("err_median", "err_max"):
        b, a = _floats([before[k] for k in common], name), _floats([after[k] for k in common], name)
        mb, ma = (sorted(b)[len(b) // 2] if b else math.nan), (sorted(a)[len(a) // 2] if a else math.nan)
        rel = (ma - mb) / mb if mb else 0.0
        summary[name] = (mb, ma, rel)
        if abs(rel) > tolerance:
            lines.append(f"{name} over hits: median {mb:.5f} -> {ma:.5f} px ({100 * rel:+.2f}%)")
    return lines, summary


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("--detector", default="cnn")
    ap.add_argument("--tolerance", type=float, default=0.02)
    a = ap.parse_args(argv)
    lines, summary = compare(read_rows(a.before, a.detector), read_rows(a.after, a.detector), a.tolerance)
    for ln in lines:
        print(ln)
    errs = "; ".join(f"{n} median over hits {b:.5f} -> {v:.5f} px ({100 * r:+.2f}%)"
                     for n, (b, v, r) in ((n, summary[n]) for n in ("err_median", "err_max")))
    print(f"{a.detector}: {summary['rows']} rows compared, {len(lines)} differences; {errs}")
    return 1 if lines else 0


if __name__ == "__main__":
    sys.exit(main())
