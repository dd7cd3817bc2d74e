"""Rig calibration against the truth: ours against OpenCV's stereo pipeline on data_gen rigs.

Rigs (:mod:`data_gen.rig`, 1280×960, read noise σ 2 grey levels, 20 pairs each; baseline 5–50 cm,
vergence up to 10°, boards cut by the frame in the other camera allowed):

* ``pinhole``: two pinhole lenses (mild or strong barrel); ``mixed``: pinhole + 150–175° fisheye;
* ``fisheye``: two fisheyes; ``three``: pinhole, pinhole, fisheye (pairs cam0-cam1 and cam0-cam2).

Pipelines:

* ``ours``: the CNN detector (partial boards with ids), :func:`aicalib_tf.calib.rig.fit.calibrate_rig`
  (lens model chosen per camera, one joint fit), :func:`aicalib_tf.calib.rig.quality.assess_rig`;
* ``opencv``: ``cv2.findChessboardCorners`` + ``cornerSubPix`` (full boards only), each camera by
  ``cv2.calibrateCamera`` (5 coefficients) or ``cv2.fisheye.calibrate`` for the fisheye lenses (the
  user knows which lens is which), then ``cv2.stereoCalibrate`` / ``cv2.fisheye.stereoCalibrate`` with
  ``CALIB_FIX_INTRINSIC`` on the frames both cameras found. OpenCV has no mixed-model stereo call: a
  mixed pair goes through ``cv2.stereoCalibrate`` on each camera's undistorted (normalized) points
  with K = I, which is the same fixed-intrinsics problem.

Columns per pair: baseline error (% of the true baseline), rotation error (degrees, the angle of
R_est·R_trueᵀ), rectified |Δy| RMS (px) in-sample and on held-out pairs (5-fold leave-pairs-out; the
whole pipeline refitted without the held-out frames), frames used, and seconds (detection, then
calibration with the held-out folds). Both pipelines' |Δy| use the same rectification
(:func:`aicalib_tf.geometry.rectify.rectify_pair`) of their own calibration.

    python benchmarks/stereo_calibration.py [--seeds 3] [--rigs pinhole,mixed,fisheye,three] [--pairs 20]
        [--out stereo_calibration.csv]
    python benchmarks/stereo_calibration.py --real cam0="left/*.jpg" cam1="right/*.jpg" --pattern 9x6 --square 25
        [--fisheye cam1]

``--real`` runs both pipelines on your own pairs (no truth: |Δy| in-sample and held-out only).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aicalib_tf.bench.detectors import make_detectors  # noqa: E402
from aicalib_tf.bench.rigs import RIGS, evaluate_rig, opencv_rig_pair  # noqa: E402
from aicalib_tf.calib.fit import View  # noqa: E402
from aicalib_tf.calib.rig.fit import calibrate_rig  # noqa: E402
from aicalib_tf.calib.rig.quality import assess_rig  # noqa: E402
from aicalib_tf.geometry.pattern import parse_pattern  # noqa: E402


def evaluate_real(items, pattern, square, fisheye=()) -> list[dict]:
    """Both pipelines on real image pairs (no truth): |Δy| RMS in-sample and held-out per pair with camera 0."""
    from aicalib_tf.calib.rig.workflow import pair_images, parse_rig
    from aicalib_tf.io import expand_images, load_image, quantize

    cams = parse_rig(items)
    pairing = pair_images({n: expand_images([g]) for n, g in cams})
    names = [n for n, _ in cams]
    detectors, _ = make_detectors(["cnn", "opencv"], tuple(pattern), relative=True)
    views, sizes, t_det = {d: {n: [] for n in names} for d in detectors}, {}, {d: 0.0 for d in detectors}
    for frame, files in pairing.frames:
        for n, f in files.items():
            img = quantize(load_image(f))
            sizes[n] = (img.shape[1], img.shape[0])
            for d, fn in detectors.items():
                t0 = time.perf_counter()
                found = fn(img)
                t_det[d] += time.perf_counter() - t0
                if len(found.corners) >= 6:
                    views[d][n].append(View(frame, found.corners, found.ids, relative=bool(found.relative)))
    t0 = time.perf_counter()
    rig = calibrate_rig([views["cnn"][n] for n in names], pattern, square, [sizes[n] for n in names], names=names)
    rig = assess_rig(rig, [views["cnn"][n] for n in names])
    t_ours = time.perf_counter() - t0
    rows = []
    for k in range(1, len(names)):
        p = rig.quality["pairs"][k - 1]
        rows.append({"rig": "real", "seed": "", "pair": f"{names[0]}-{names[k]}", "pipeline": "ours",
                     "baseline_mm": p["baseline"], "dy_in_px": p["in_sample_rms_px"], "dy_held_px": p["held_out_rms_px"],
                     "frames": p["pairs"], "t_detect_s": t_det["cnn"], "t_calib_s": t_ours, "note": pairing.rule})
        t0 = time.perf_counter()
        cv = opencv_rig_pair(views["opencv"][names[0]], views["opencv"][names[k]], square, (sizes[names[0]], sizes[names[k]]),
                             (names[0] in fisheye, names[k] in fisheye))
        rows.append({"rig": "real", "seed": "", "pair": f"{names[0]}-{names[k]}", "pipeline": "opencv",
                     "baseline_mm": float(np.linalg.norm(cv["T"])), "dy_in_px": cv["in"], "dy_held_px": cv["held"],
                     "frames": cv["frames"], "t_detect_s": t_det["opencv"], "t_calib_s": time.perf_counter() - t0,
                     "note": ""})
    return rows


def _print(rows) -> None:
    cols = ["rig", "seed", "pair", "pipeline", "lenses", "baseline_mm", "baseline_err_pct", "rot_err_deg", "dy_in_px",
            "dy_held_px", "frames", "t_detect_s", "t_calib_s", "note"]
    print(" | ".join(cols))
    for r in rows:
        print(" | ".join(f"{r[c]:.4g}" if isinstance(r.get(c), float) else str(r.get(c, "")) for c in cols))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--rigs", default=",".join(RIGS))
    ap.add_argument("--pairs", type=int, default=20)
    ap.add_argument("--out", default="stereo_calibration.csv")
    ap.add_argument("--real", nargs="+", metavar="NAME=GLOB", help="real pairs instead of data_gen rigs")
    ap.add_argument("--pattern", default="9x6")
    ap.add_argument("--square", type=float, default=1.0)
    ap.add_argument("--fisheye", default="", help="with --real: the cameras (names) with fisheye lenses, for OpenCV's pipeline")
    args = ap.parse_args(argv)
    import pandas as pd

    if args.real:
        rows = evaluate_real(args.real, parse_pattern(args.pattern), args.square, args.fisheye.split(",") if args.fisheye else ())
        _print(rows)
        pd.DataFrame(rows).to_csv(args.out, index=False)
        return 0
    detectors, _ = make_detectors(["cnn", "opencv"], (9, 6), relative=True)
    rows = []
    for name in args.rigs.split(","):
        for seed in range(args.seeds):
            rows += evaluate_rig(name, seed, args.pairs, detectors)
            _print(rows[-2 * (len(RIGS[name]) - 1):])
    pd.DataFrame(rows).to_csv(args.out, index=False)
    df = pd.DataFrame(rows)
    print("\nmedians by rig and pipeline:")
    print(df.groupby(["rig", "pipeline"])[["baseline_err_pct", "rot_err_deg", "dy_in_px", "dy_held_px",
                                            "t_detect_s", "t_calib_s"]].median().to_string(float_format="%.4g"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
