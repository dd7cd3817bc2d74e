"""Calibration of fisheye (and mild / barrel) sequences against the truth: ours against OpenCV's pipelines.

Issue #25 item 7. Sequences with exact truth (data_gen; :mod:`aicalib_tf.bench.conditions`):

* ``fisheye185``: circular 185° equidistant lens, 1280×960, the image circle inside the frame;
* ``fisheye150``: full-frame 150° equidistant lens, 1280×960;
* ``mild-0``, ``mild-1``, ``barrel-2``, ``barrel-3``: the benchmark's 640×480 ``calib`` sequences.

All with ~20 views of a 9×6 board; the fisheye ones with noise σ 2 grey levels. Pipelines:

* ``cnn+auto``: our CNN detector, then ``aicalib_tf.calib.fit.calibrate_camera`` (model "auto");
* ``cnn+plumb_bob``: the same detections with the model forced to OpenCV's 5 coefficients
  (today's pipeline: the reference the issue's "no worse than today" target compares with);
* ``classic+calibrateCamera`` / ``classic+fisheye``: ``cv2.findChessboardCorners`` +
  ``cornerSubPix``, then ``cv2.calibrateCamera`` (5 coefficients) or ``cv2.fisheye.calibrate``;
* ``sb+calibrateCamera`` / ``sb+fisheye``: ``cv2.findChessboardCornersSB``, then the same.

``cv2.fisheye.calibrate`` is tried first without a guess; when it raises, again with
``CALIB_USE_INTRINSIC_GUESS`` and K0 = [[f0, 0, (w-1)/2], [0, f0, (h-1)/2]] with f0 = min(w, h)/π
(a 180° circle across the shorter side); failures are recorded as failures.

Columns: the chosen model, projection error field against the true lens (unproject a pixel grid
with the true lens, project with the estimate; :func:`aicalib_tf.bench.metrics.calibration_errors`)
as the mean over the area the boards covered ("seen") and over the whole image or image circle,
the share of it the estimate cannot project ("fail"), the focal error (%), the RMS (px), and for our
pipelines the predicted projection uncertainty ("σ px": the 1σ map of
:func:`aicalib_tf.calib.quality.assess`, median over the covered area), to set beside "seen px"; and "rot px": "seen px" after fitting out a rotation of the camera frame
(mrcal's comparison; a principal-point error that the views' poses absorb leaves it).

    python benchmarks/fisheye_calibration.py [--views 20] [--out fisheye_calibration.csv] [--only fisheye]
        [--seeds N] [--pipelines cnn+auto,classic+fisheye]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aicalib_tf.bench.conditions import CALIB_CAMERAS, CALIB_SEED, PATTERN, calibration_sequences  # noqa: E402
from aicalib_tf.bench.detectors import make_detectors  # noqa: E402
from aicalib_tf.bench.metrics import calibration_errors  # noqa: E402
from aicalib_tf.bench.opencv_calib import fisheye_calibrate  # noqa: E402
from aicalib_tf.geometry.pattern import board_points  # noqa: E402

_CRIT = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-10)


def _opencv_pinhole(views, square, size):
    obj = [board_points(i, square).astype(np.float32) for _, c, i in views]
    img = [c.astype(np.float32).reshape(-1, 1, 2) for _, c, i in views]
    rms, K, dist, _, _ = cv2.calibrateCamera(obj, img, size, None, None, flags=0, criteria=_CRIT)
    return {"model": "plumb_bob", "K": K, "dist": dist.ravel()[:5], "rms": rms, "note": ""}


def _opencv_fisheye(views, square, size):
    obj = [board_points(i, square).reshape(1, -1, 3) for _, c, i in views]
    img = [c.astype(np.float64).reshape(1, -1, 2) for _, c, i in views]
    rms, K, D, why = fisheye_calibrate(obj, img, size, _CRIT)
    note = f"needed K guess f0={min(size) / math.pi:.0f} (no guess: {why[:60]})" if why else "no guess"
    return {"model": "equidistant", "K": K, "dist": D.ravel(), "rms": rms, "note": note}


def _ours(views, square, size, model="auto"):
    from aicalib_tf.calib.fit import View, calibrate_camera

    vs = [View(n, c, i) for n, c, i in views]
    kw = {} if model == "auto" else {"model": model}
    from aicalib_tf.calib.quality import assess

    cal = calibrate_camera(vs, PATTERN, square, size, **kw)
    sigma = (assess(cal, vs)["sigma_px"] or {}).get("median_covered", float("nan"))
    return {"model": cal.model, "K": cal.K, "dist": np.asarray(cal.dist).ravel(), "rms": float(cal.rms),
            "sigma": sigma, "note": f"{len(cal.views)} views used"}


PIPELINES = {
    "cnn+auto": ("cnn", _ours),
    "cnn+plumb_bob": ("cnn", lambda v, s, z: _ours(v, s, z, "plumb_bob")),
    "classic+calibrateCamera": ("opencv", _opencv_pinhole),
    "classic+fisheye": ("opencv", _opencv_fisheye),
    "sb+calibrateCamera": ("opencv-sb", _opencv_pinhole),
    "sb+fisheye": ("opencv-sb", _opencv_fisheye),
}


def sequences(views: int, only: str | None, seed: int = CALIB_SEED):
    """[(name, [Sample])]: the two fisheye sequences, then the mild and barrel ones (cameras and poses from ``seed``)."""
    out = []
    if only in (None, "fisheye"):
        out += [(n, s) for n, (_, s) in zip(("fisheye185", "fisheye150"),
                                             calibration_sequences(views, (), seed, fisheye=("fisheye185", "fisheye150")))]
    if only in (None, "pinhole"):
        for cam, s in calibration_sequences(views, CALIB_CAMERAS, seed):
            out.append((f"{'barrel' if s[0].label['dist'][0] < -0.2 else 'mild'}-{cam}", s))
    return out


def _rotation_compensated(lab, r, views, size) -> float:
    """Mean over the covered area of the true-lens vs estimate projection difference after fitting out a
    rotation of the camera frame (:func:`aicalib_tf.calib.quality.rotation_compensated_diff`), px:
    what is left once the principal point's trade with the views' poses is taken out."""
    from aicalib_tf.calib import quality as Q
    from aicalib_tf.calib.coverage import coverage_counts
    from aicalib_tf.calib.fit import View
    from aicalib_tf.geometry.lens import Lens

    true = Lens(lab.get("distortion_model", "plumb_bob"), lab["K"], lab["dist"], size)
    est = Lens(r["model"], r["K"], r["dist"], size)
    pts = Q.grid_points(size)
    covered = coverage_counts([View(n, c, i) for n, c, i in views], size, (32, 24)).ravel() > 0
    d, _ = Q.rotation_compensated_diff(true, est, pts, fit_mask=covered)
    return float(np.nanmean(d[covered]))


def evaluate_sequence(name, samples, detectors, pipelines=tuple(PIPELINES)) -> list[dict]:
    """Detect with every detector, calibrate with every pipeline, score against the truth."""
    lab = samples[0].label
    size = tuple(lab["image_size"])
    square = float(lab["square_size"])
    found = {d: [] for d in detectors}
    for s in samples:
        for d, fn in detectors.items():
            f = fn(s.image)
            if len(f.corners) >= 6:
                found[d].append((f"view{s.label['index']:03d}", f.corners, f.ids))
    seen = np.concatenate([s.corners[s.visible] for s in samples])
    theta = math.radians(lab["max_theta_deg"]) if lab.get("max_theta_deg") else None
    rows = []
    for pipe, (det, fn) in ((p, PIPELINES[p]) for p in pipelines):
        row = {"sequence": name, "seed": samples[0].label["seed"], "true_model": lab.get("distortion_model", "plumb_bob"), "pipeline": pipe,
               "views": len(samples), "views_found": len(found[det])}
        t0 = time.perf_counter()
        try:
            if len(found[det]) < 3:
                raise RuntimeError(f"only {len(found[det])} views detected")
            r = fn(found[det], square, size)
            err = calibration_errors(r["K"], r["dist"], lab["K"], lab["dist"], size, model=r["model"],
                                     model_true=row["true_model"], max_theta_true=theta, seen=seen, grid=(64, 48))
            row.update(model=r["model"], seen_px=err["proj_err_seen_mean_px"], image_px=err["proj_err_mean_px"],
                       rot_px=_rotation_compensated(lab, r, found[det], size),
                       fail=err["proj_err_fail_frac"], fx_pct=err["fx_pct"], rms=r["rms"], note=r["note"],
                       sigma_px=r.get("sigma", float("nan")))
        except Exception as exc:  # a pipeline's failure is a result, recorded as such
            row.update(model="failed", note=f"{type(exc).__name__}: {str(exc).strip().splitlines()[-1][:90]}")
        row["s"] = time.perf_counter() - t0
        rows.append(row)
    return rows


def _fmt(rows) -> str:
    head = f"{'sequence':11} {'pipeline':24} {'views':>5} {'model':20} {'seen px':>8} {'image px':>9} {'fail':>5} " \
           f"{'fx %':>8} {'RMS':>7} {'σ px':>7} {'rot px':>7}  note"
    lines = [head, "-" * len(head)]
    for r in rows:
        if r["model"] == "failed":
            lines.append(f"{r['sequence']:11} {r['pipeline']:24} {r['views_found']:>5} {'FAILED':20} {'':>8} {'':>9} "
                         f"{'':>5} {'':>8} {'':>7}  {r['note']}")
            continue
        lines.append(f"{r['sequence']:11} {r['pipeline']:24} {r['views_found']:>5} {r['model']:20} {r['seen_px']:8.3f} "
                     f"{r['image_px']:9.3f} {r['fail']:5.0%} {r['fx_pct']:+8.2f} {r['rms']:7.3f} {r['sigma_px']:7.3f} {r['rot_px']:7.3f}  {r['note']}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--views", type=int, default=20)
    ap.add_argument("--only", choices=("fisheye", "pinhole"), default=None)
    ap.add_argument("--out", default=None, help="CSV path for the rows")
    ap.add_argument("--seeds", type=int, default=1, help="run the sequences of this many seeds (CALIB_SEED, +1, ...)")
    ap.add_argument("--pipelines", default=",".join(PIPELINES), help="comma-separated subset of the pipelines")
    a = ap.parse_args(argv)
    pipes = tuple(p for p in a.pipelines.split(",") if p)
    unknown = [p for p in pipes if p not in PIPELINES]
    if unknown:
        ap.error(f"unknown pipeline(s) {unknown}; choose from {', '.join(PIPELINES)}")
    detectors, _ = make_detectors(sorted({PIPELINES[p][0] for p in pipes}), PATTERN)
    rows = []
    for k in range(a.seeds):
        for name, samples in sequences(a.views, a.only, CALIB_SEED + k):
            rows += evaluate_sequence(name, samples, detectors, pipes)
            print(f"{name} seed {CALIB_SEED + k}: done", file=sys.stderr, flush=True)
    print(_fmt(rows))
    if a.seeds > 1:
        import pandas as pd

        ok = pd.DataFrame([r for r in rows if r["model"] != "failed"])
        print("\nmean over seeds (px):")
        print(ok.groupby(["sequence", "pipeline"], sort=False)[["seen_px", "image_px", "sigma_px", "rot_px"]].agg(["mean", "max", "count"])
              .round(3).to_string())
    if a.out:
        import pandas as pd

        pd.DataFrame(rows).to_csv(a.out, index=False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
