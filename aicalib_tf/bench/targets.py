"""The detection targets checked against one benchmark run (pure pandas).

:func:`check_targets` reads the summary (one row per condition × detector, see
:func:`aicalib_tf.bench.report.summarize`) and the per-image results of ``python -m aicalib_tf.evaluate``
and says, for the CNN pipeline, which targets the run meets. Conditions or detectors the run
left out are skipped; real photos are checked by ``evaluate --images`` and ``calibrate``, not here.
"""

from __future__ import annotations

import pandas as pd

__all__ = ["DEGRADED", "check_targets"]

DEGRADED = ("noise20", "noise40", "blur2", "blur3", "contrast", "shading", "jpeg15", "saltpepper5", "barrel",
            "tilt60", "small")  # each: full-board detection >= 97%
BASELINES = ("opencv", "opencv-sb")
SPEED_MS = {(640, 480): 10.0, (1920, 1080): 40.0}  # median per image
MAX_OVER_MEDIAN = 3.0  # the slowest image of a size against that size's median


def check_targets(summary: pd.DataFrame, results: pd.DataFrame, detector: str = "cnn") -> pd.DataFrame:
    """One row per target: ``target``, ``measured`` (text) and ``met`` (bool)."""
    rows = []
    s = summary[summary["detector"] == detector].set_index("condition")

    def add(target: str, measured: str, met: bool) -> None:
        rows.append({"target": target, "measured": measured, "met": bool(met)})

    if "clean" in s.index:
        r = s.loc["clean"]
        add("clean: full boards 100%, median error <= 0.03 px",
            f"{r['detection_rate']:.0%}, {r['err_median']:.4f} px", r["detection_rate"] >= 1.0 and r["err_median"] <= 0.03)
    for c in DEGRADED:
        if c in s.index:
            rate = s.loc[c, "detection_rate"]
            add(f"{c}: full boards >= 97%", f"{rate:.0%}", rate >= 0.97)
    if "noise20" in s.index:
        e = s.loc["noise20", "err_median"]
        add("noise20: median error <= 0.10 px", f"{e:.4f} px", e <= 0.10)
    for c in ("clean",) + DEGRADED:
        base = summary[(summary["condition"] == c) & summary["detector"].isin(BASELINES)]
        if c in s.index and len(base):
            best = base["detection_rate"].max()
            add(f"{c}: detection at least OpenCV's best", f"{s.loc[c, 'detection_rate']:.0%} against {best:.0%}",
                s.loc[c, "detection_rate"] >= best)
    for c in ("occluded", "partial"):
        if c in s.index:
            r = s.loc[c]
            add(f"{c}: recall >= 95%, 0 wrong ids", f"{r['recall']:.1%}, {int(r['wrong_ids'])} wrong ids",
                r["recall"] >= 0.95 and r["wrong_ids"] == 0)
    boards = s[s["boards"] > 0]
    if len(boards):
        n = int(boards["wrong"].sum())
        add("no wrong full board on any condition", f"{n} on {len(boards)} conditions", n == 0)
    if "clutter" in s.index:
        n = int(s.loc["clutter", "false_boards"])
        add("clutter: 0 false boards", f"{n}", n == 0)
    mine = results[results["detector"] == detector]
    for (w, h), limit in SPEED_MS.items():
        t = mine.loc[(mine["width"] == w) & (mine["height"] == h), "time_ms"]
        if len(t):
            med, mx = t.median(), t.max()
            add(f"{w}×{h}: median <= {limit:.0f} ms", f"{med:.1f} ms ({len(t)} images)", med <= limit)
            add(f"{w}×{h}: slowest <= {MAX_OVER_MEDIAN:.0f}× median", f"{mx:.1f} ms = {mx / med:.2f}×",
                mx <= MAX_OVER_MEDIAN * med)
    return pd.DataFrame(rows, columns=["target", "measured", "met"])
