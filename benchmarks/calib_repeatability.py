"""Repeatability of a calibration on real photos: two disjoint halves of the views,
rotation-compensated projection difference (mrcal's projection_diff), against what the
halves' covariances predict.

    .venv/bin/python benchmarks/calib_repeatability.py tests/data/opencv_left --pattern 9x6
    .venv/bin/python benchmarks/calib_repeatability.py --synthetic 20

Detects every photo with the CNN detector (loads TensorFlow; the calib modules never do), fits
with ``calib.quality.default_fit()`` (``fit.fit_views`` when it exists; else OpenCV's
calibrateCamera without outlier rejection) and prints, for the even/odd and the first/second
split, the median and mean difference over the cells the boards covered and over the whole image
(px), the predicted median, the full calibration's verdict, and the timings.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aicalib_tf.calib import quality as Q  # noqa: E402
from aicalib_tf.calib.fit import View  # noqa: E402
from aicalib_tf.geometry.pattern import parse_pattern  # noqa: E402
from aicalib_tf.io import load_image  # noqa: E402


def detect_views(folder: Path, pattern) -> tuple[list[View], tuple[int, int]]:
    """Views (name-sorted) of every image in ``folder`` with a board, and the image size (w, h)."""
    from aicalib_tf.detect import detect_corners

    views, size = [], None
    for path in sorted(p for p in folder.iterdir() if p.suffix.lower() in (".jpg", ".jpeg", ".png")):
        img = load_image(str(path))
        size = (img.shape[1], img.shape[0])
        det = detect_corners(img, pattern)
        if len(det.corners) >= 6:
            views.append(View(path.name, det.corners, det.ids))
        else:
            print(f"  no board in {path.name}")
    return views, size


def synthetic(sets: int, noise: float = 0.3, n_views: int = 20) -> None:
    """Measured against predicted half-vs-half difference (even/odd) on ``sets`` synthetic sets of
    ``n_views`` views (corner noise ``noise`` px per axis), for a barrel pinhole and a 185° fisheye."""
    import numpy as np

    from aicalib_tf.geometry import lens as L
    from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views

    lenses = {"plumb_bob": (L.Lens("plumb_bob", [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]],
                                   [-0.25, 0.08, 0.001, -0.0005, 0.0], (640, 480)), (0.35, 0.6)),
              "equidistant": (L.Lens("equidistant", [[288.0, 0, 641.5], [0, 287.4, 478.2], [0, 0, 1]],
                                     [0.02, -0.01, 0.004, -0.001], (1280, 960)), (0.15, 0.4))}
    fit = Q.default_fit()
    for model, (lens, dist) in lenses.items():
        meas, pred = [], []
        for k in range(sets):
            views = synthetic_views(lens, n_views, noise, seed=100 + k, distance=dist)
            h = Q.half_difference(views, fit, PATTERN, SQUARE, lens.image_size, model, "evenodd")
            p = Q.predicted_half_difference(h["cal_a"], h["cal_b"], h["covered"],
                                            covariances=[h["cal_a"].covariance, h["cal_b"].covariance])
            meas.append(h["median_covered"])
            pred.append(p["median_covered"])
        meas, pred = np.array(meas), np.array(pred)
        print(f"synthetic {model} ({sets} sets x {n_views} views, noise {noise} px): measured median over covered "
              f"area, mean {meas.mean():.3f} px; predicted mean {pred.mean():.3f} px; ratio measured/predicted "
              f"per set {np.min(meas / pred):.2f}-{np.max(meas / pred):.2f} (median {np.median(meas / pred):.2f})")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("folder", type=Path, nargs="?")
    ap.add_argument("--pattern", default=None, help="inner corners, e.g. 9x6")
    ap.add_argument("--model", default="plumb_bob")
    ap.add_argument("--synthetic", type=int, default=0, help="instead: this many synthetic sets per lens")
    args = ap.parse_args(argv)
    if args.synthetic:
        synthetic(args.synthetic)
        return 0
    if args.folder is None or args.pattern is None:
        ap.error("give a folder and --pattern, or --synthetic N")
    pattern = parse_pattern(args.pattern)
    t0 = time.perf_counter()
    views, size = detect_views(args.folder, pattern)
    t1 = time.perf_counter()
    fit = Q.default_fit()
    cal = fit(views, pattern, 1.0, size, args.model)
    t2 = time.perf_counter()
    print(f"{len(views)} views, {size[0]}x{size[1]}, model {args.model}: RMS {cal.rms:.3f} px "
          f"(detect {t1 - t0:.1f} s, fit {t2 - t1:.2f} s)")
    for split in ("evenodd", "halves"):
        t = time.perf_counter()
        h = Q.half_difference(views, fit, pattern, 1.0, size, args.model, split)
        covs = [Q.intrinsics_covariance(h[f"cal_{k}"], h[f"views_{k}"]) if getattr(h[f"cal_{k}"], "covariance", None)
                is None else h[f"cal_{k}"].covariance for k in "ab"]
        p = Q.predicted_half_difference(h["cal_a"], h["cal_b"], h["covered"], covariances=covs)
        print(f"{split:8s} ({h['n_a']}+{h['n_b']} views): covered area median {h['median_covered']:.3f} mean "
              f"{h['mean_covered']:.3f} px | whole image median {h['median_all']:.3f} mean {h['mean_all']:.3f} px | "
              f"predicted median covered {p['median_covered']:.3f} px (10-90% {p['p10_covered']:.3f}-{p['p90_covered']:.3f}), whole {p['median_all']:.3f} px | "
              f"rotation {h['rotation_deg']:.3f} deg | {time.perf_counter() - t:.2f} s")
    t = time.perf_counter()
    a = Q.assess(cal, views, fit=fit)
    print(f"assess {time.perf_counter() - t:.2f} s; sigma {a['sigma_px']}")
    print(f"verdict: {a['verdict']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
