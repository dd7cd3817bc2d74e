"""Time of ``calibrate_camera(model="auto")`` and of the quality assessment on 40 views (target ≤ 10 s).

Views are synthetic projections of a 9x6 board (``tests/calib/synthetic.py``) with 0.1 px corner
noise, for a mild pinhole lens (640x480) and a 185° fisheye (1280x960); OpenCV's
``calibrateCamera`` on the same pinhole views is timed beside them, as the machine's speed drifts.

    python benchmarks/calib_speed.py [--views 40] [--repeat 3]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aicalib_tf.calib.fit import calibrate_camera, fit_views  # noqa: E402
from aicalib_tf.calib.quality import assess  # noqa: E402
from aicalib_tf.geometry import lens as L  # noqa: E402
from aicalib_tf.geometry.pattern import board_points  # noqa: E402
from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views  # noqa: E402

LENSES = {
    "mild 640x480": (L.Lens("plumb_bob", [[620.0, 0, 322], [0, 621.0, 238], [0, 0, 1]],
                            [-0.08, 0.01, 4e-4, -3e-4, 0.0], (640, 480)), (0.35, 0.6)),
    "fisheye185 1280x960": (L.Lens("equidistant", [[288.0, 0, 641.5], [0, 287.4, 478.2], [0, 0, 1]],
                                   [0.02, -0.01, 0.004, -0.001], (1280, 960)), (0.15, 0.4)),
}


def _best(fn, repeat):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--views", type=int, default=40)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args(argv)
    print(f"{'lens':20} {'views':>5} {'auto s':>7} {'chosen':12} {'assess s':>9} {'opencv s':>9}")
    for name, (lens, dist) in LENSES.items():
        views = synthetic_views(lens, a.views, 0.1, seed=11, distance=dist)
        t_auto, cal = _best(lambda: calibrate_camera(views, PATTERN, SQUARE, lens.image_size), a.repeat)
        t_q, _ = _best(lambda: assess(cal, views, fit=fit_views), a.repeat)
        t_cv = float("nan")
        if lens.model == "plumb_bob":
            obj = [board_points(v.ids, SQUARE).astype(np.float32) for v in views]
            img = [v.corners.astype(np.float32).reshape(-1, 1, 2) for v in views]
            t_cv, _ = _best(lambda: cv2.calibrateCamera(obj, img, lens.image_size, None, None), a.repeat)
        print(f"{name:20} {len(views):5d} {t_auto:7.2f} {cal.model:12} {t_q:9.2f} {t_cv:9.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
