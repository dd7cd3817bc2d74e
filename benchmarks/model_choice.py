"""How often ``--model auto`` picks the right family of lens model (target ≥ 95%).

Each sequence is a new camera: data_gen draws the lens from the sequence's seed, renders the views
(noise as in the benchmark's calibration presets), the CNN detects the boards and
:func:`aicalib_tf.calib.fit.calibrate_camera` chooses the model by cross-validation over views.

Classes of lens (the "right" pick in brackets):

* ``fisheye185`` / ``fisheye150``: equidistant lenses of 185° (circular image) and 150° diagonal,
  ``calib_fisheye`` preset (noise σ 2) [equidistant];
* ``mild``: the ``calib`` preset's mild pinhole lenses (|k1| ≤ 0.15, HFOV 50–110°, noise σ 10)
  [plumb_bob];
* ``barrel``: its strong barrel lenses (k1 −0.45…−0.25, HFOV 70–110°), reported with the pick but
  not scored: any model that fits them is right.

The pick counts as right when it is the class's model. Rows go to ``--out`` (CSV) with the whole
table of each choice; the summary prints the share right per class and the time per calibration.

    python benchmarks/model_choice.py [--sequences 20] [--views 20] [--size 640x480] [--out choice.csv]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aicalib_tf.bench.conditions import fisheye_preset  # noqa: E402
from aicalib_tf.calib.fit import CalibrationError, View, calibrate_camera  # noqa: E402
from aicalib_tf.detect import detect_corners  # noqa: E402
from aicalib_tf.geometry.pattern import parse_pattern  # noqa: E402
from data_gen import get_preset, make_sample  # noqa: E402

RIGHT = {"fisheye185": "equidistant", "fisheye150": "equidistant", "mild": "plumb_bob", "barrel": None}
SEED0 = 7000  # sequence k of a class uses seed SEED0 + k: cameras the detector never trained on


def preset_of(cls: str, size):
    """The data_gen preset of a lens class at image ``size`` (w, h)."""
    if cls.startswith("fisheye"):
        return fisheye_preset(float(cls[len("fisheye"):]), "calib_fisheye", sizes=(size,))
    level = "mild" if cls == "mild" else "strong"
    return replace(get_preset("calib"), name=f"calib_{cls}", distortion=(level,), sizes=(size,),
                   hfov_deg=(50.0, 110.0) if cls == "mild" else (70.0, 110.0))


def run_sequence(cls: str, k: int, views: int, size) -> dict:
    """Render, detect and calibrate one sequence; returns its row."""
    preset = preset_of(cls, size)
    found, truth = [], None
    for v in range(views):
        s = make_sample(preset, SEED0 + k, v)
        truth = s.label
        d = detect_corners(s.image, tuple(truth["pattern_size"]))
        if len(d.corners) >= 6:
            found.append(View(f"view{v:02d}", d.corners, d.ids))
    row = {"class": cls, "seq": k, "true_model": truth["distortion_model"], "views": len(found),
           "true_k1": truth["dist"][0], "fx_true": truth["K"][0][0]}
    t0 = time.perf_counter()
    try:
        cal = calibrate_camera(found, tuple(truth["pattern_size"]), truth["square_size"], size)
        row.update(model=cal.model, fx_pct=100 * (cal.fx / truth["K"][0][0] - 1), rms=cal.rms)
        for r in cal.model_table:
            row[f"cv_{r['model']}"] = r["cv_rms"]
            row[f"se_{r['model']}"] = r["cv_se"]
    except CalibrationError as exc:
        row.update(model="failed", note=str(exc)[:120])
    row["calib_s"] = time.perf_counter() - t0
    row["right"] = RIGHT[cls] is None or row["model"] == RIGHT[cls]
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sequences", type=int, default=20, help="sequences per class")
    ap.add_argument("--views", type=int, default=20)
    ap.add_argument("--size", default="640x480", help="image size WxH")
    ap.add_argument("--classes", default="fisheye185,fisheye150,mild,barrel")
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    size = parse_pattern(a.size)
    rows = []
    for cls in a.classes.split(","):
        for k in range(a.sequences):
            rows.append(run_sequence(cls, k, a.views, size))
            r = rows[-1]
            print(f"{cls} {k}: {r['model']} ({r['views']} views, {r['calib_s']:.1f} s)", file=sys.stderr, flush=True)
    import pandas as pd

    df = pd.DataFrame(rows)
    if a.out:
        df.to_csv(a.out, index=False)
    print(f"{'class':11} {'n':>3} {'right':>6}  picks{'':28} calib s (median / max)")
    for cls, g in df.groupby("class", sort=False):
        picks = ", ".join(f"{m} {n}" for m, n in g["model"].value_counts().items())
        print(f"{cls:11} {len(g):3d} {g['right'].mean():6.0%}  {picks:33} {g['calib_s'].median():.1f} / {g['calib_s'].max():.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
