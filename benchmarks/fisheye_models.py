"""Lens-model choice on fisheye (KB, Double Sphere, EUCM) and pinhole lenses, against the truth.

For each lens class and sequence: a camera drawn by data_gen (a new one per sequence), ``--views``
board poses drawn by data_gen's pose sampler (the ``calib_fisheye`` / ``calib`` presets' pose
settings, 9×6 board), the true corners plus Gaussian noise of the CNN detector's size (``--noise``
px per axis for the fisheye classes, ``--noise-pinhole`` for the pinhole ones; no rendering, so
the run measures the model choice and the fit, not the detector). Then:

* ``auto``: :func:`aicalib_tf.calib.fit.calibrate_camera` with model "auto" on all views;
* the projection error against the true lens over the area the boards covered, mean px, after
  fitting out a rotation of the camera frame ("rot px", the metric of
  ``benchmarks/fisheye_calibration.py``) and without ("seen px",
  :func:`aicalib_tf.bench.metrics.calibration_errors`);
* the half-vs-half check: ``auto`` on the even and on the odd views; the chosen models' families
  (fisheye or pinhole) and names, and whether they agree.

Classes: ``kb150`` (equidistant, full frame), ``kb185`` (equidistant, circular), ``ds190`` (Double
Sphere, circular), ``eucm170`` (EUCM, full frame), all 1280×960; ``kb185near``: the 185° lens with
only the views whose corners stay within 80° of the axis (boards that never reach the circle's
rim, as on real circular-fisheye photos); ``mild`` and ``barrel`` (plumb_bob, 640×480).

The image circle: for a lens whose circle leaves the four frame corners black (kb185, ds190,
kb185near) the true circle is passed to ``calibrate_camera`` (``image_circle``), as the photos'
estimate would give it (:func:`aicalib_tf.geometry.image_circle.estimate_image_circle` finds a
rendered circle within 0.1 px); ``--no-circle`` leaves it out, and so does a build whose
``calibrate_camera`` takes none.

    python benchmarks/fisheye_models.py [--sequences 20] [--views 20] [--classes kb150,kb185,ds190,eucm170,mild,barrel]
        [--noise 0.015] [--noise-pinhole 0.05] [--no-circle] [--out fisheye_models.csv]
"""

from __future__ import annotations

import argparse
import inspect
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aicalib_tf.bench.metrics import calibration_errors  # noqa: E402
from aicalib_tf.calib.fit import CalibrationError, View, calibrate_camera  # noqa: E402
from aicalib_tf.geometry.lens import get_model  # noqa: E402
from benchmarks.fisheye_calibration import _rotation_compensated  # noqa: E402
from data_gen.board import Board  # noqa: E402
from data_gen.camera import sample_camera, sample_fisheye, sample_unified_fisheye  # noqa: E402
from data_gen.pose import corner_visibility, sample_pose  # noqa: E402
from data_gen.presets import get_preset  # noqa: E402

PATTERN = (9, 6)
CLASSES = {  # name -> (camera sampler(rng), pose preset, fisheye?, right family)
    "kb150": (lambda r: sample_fisheye(r, (1280, 960), fov_deg=(150.0, 150.0)), "calib_fisheye", True),
    "kb185": (lambda r: sample_fisheye(r, (1280, 960), fov_deg=(185.0, 185.0)), "calib_fisheye", True),
    "ds190": (lambda r: sample_unified_fisheye(r, (1280, 960), "ds", fov_deg=(190.0, 190.0)), "calib_fisheye", True),
    "eucm170": (lambda r: sample_unified_fisheye(r, (1280, 960), "eucm", fov_deg=(170.0, 170.0)), "calib_fisheye", True),
    "mild": (lambda r: sample_camera(r, (640, 480), hfov_deg=(50.0, 80.0), distortion="mild"), "calib", False),
    "barrel": (lambda r: sample_camera(r, (640, 480), hfov_deg=(90.0, 110.0), distortion="strong"), "calib", False),
    "kb185near": (lambda r: sample_fisheye(r, (1280, 960), fov_deg=(185.0, 185.0)), "calib_fisheye", True),  # last: the
    # others keep their random streams (seeded by the class's place)
}
MAX_RAY_DEG = {"kb185near": 80.0}  # class -> views kept only when every corner's true ray is within this angle
CIRCLE_ARG = "image_circle" in inspect.signature(calibrate_camera).parameters


def image_circle(cam):
    """The camera's image circle (px) when it leaves the frame's corners black, else None."""
    if not CIRCLE_ARG or not cam.fisheye or not math.isfinite(cam.circle_radius()):
        return None
    from aicalib_tf.geometry.image_circle import ImageCircle

    w, h = cam.image_size
    if cam.inside_circle(np.array([[-0.5, -0.5], [w - 0.5, -0.5], [-0.5, h - 0.5], [w - 0.5, h - 0.5]])).any():
        return None
    return ImageCircle(float(cam.K[0, 2]), float(cam.K[1, 2]), cam.circle_radius() * 0.5 * (cam.K[0, 0] + cam.K[1, 1]))


def sequence(cls: str, seed: int, views: int, noise: float):
    """(camera, [(name, corners (N, 2) px, ids (N, 2))], true visible corners (M, 2) px) of one sequence."""
    sampler, preset, _ = CLASSES[cls]
    rng = np.random.default_rng([seed, list(CLASSES).index(cls)])
    cam = sampler(rng)
    board, cfg = Board(PATTERN, 1.0), get_preset(preset).pose
    ids = np.stack(np.meshgrid(np.arange(PATTERN[0]), np.arange(PATTERN[1])), -1).reshape(-1, 2)
    out, seen = [], []
    while len(out) < views:
        rv, tv = sample_pose(rng, cam, board, cfg)
        c, vis = corner_visibility(board, rv, tv, cam)
        if vis.sum() < 12:
            continue
        if cls in MAX_RAY_DEG and np.degrees(np.arccos(np.clip(cam.lens.unproject(c[vis])[:, 2], -1, 1))).max() > MAX_RAY_DEG[cls]:
            continue
        out.append((f"view{len(out):03d}", c[vis] + noise * rng.standard_normal((int(vis.sum()), 2)), ids[vis]))
        seen.append(c[vis])
    return cam, out, np.concatenate(seen)


def _auto(views, size, circle=None) -> str:
    try:
        return calibrate_camera([View(*v) for v in views], PATTERN, 1.0, size, **_circle_kw(circle)).model
    except CalibrationError:
        return "failed"


def _circle_kw(circle) -> dict:
    return {"image_circle": circle} if circle is not None and CIRCLE_ARG else {}


def _family(model: str) -> str:
    return "failed" if model == "failed" else ("fisheye" if get_model(model).IS_FISHEYE else "pinhole")


def evaluate(cls: str, seed: int, views: int, noise: float, use_circle: bool = True) -> dict:
    """One sequence's row: chosen model, errors against the truth, widest true ray, the halves' choices."""
    cam, vs, seen = sequence(cls, seed, views, noise)
    circle = image_circle(cam) if use_circle else None
    size, t0 = cam.image_size, time.perf_counter()
    lab = {"distortion_model": cam.model, "K": cam.K, "dist": cam.dist}
    row = {"class": cls, "seed": seed, "true_model": cam.model, "noise_px": noise,
           "widest_deg": float(np.degrees(np.nanmax(np.arccos(np.clip(cam.lens.unproject(seen)[:, 2], -1, 1)))))}
    try:
        cal = calibrate_camera([View(*v) for v in vs], PATTERN, 1.0, size, **_circle_kw(circle))
        r = {"model": cal.model, "K": cal.K, "dist": cal.dist}
        theta = cam.max_theta if cam.max_theta is not None else None
        err = calibration_errors(cal.K, cal.dist, cam.K, cam.dist, size, model=cal.model, model_true=cam.model,
                                 max_theta_true=theta, seen=seen, grid=(64, 48))
        row.update(model=cal.model, rot_px=_rotation_compensated(lab, r, vs, size), seen_px=err["proj_err_seen_mean_px"],
                   rms=cal.rms, views_used=len(cal.views),
                   table=" ".join(f"{t['model']}:{t['cv_rms']:.4f}" for t in cal.model_table if np.isfinite(t["cv_rms"])))
    except CalibrationError as exc:
        row.update(model="failed", note=str(exc)[:100])
    row["circle"] = bool(_circle_kw(circle))
    row["half_a"], row["half_b"] = _auto(vs[0::2], size, circle), _auto(vs[1::2], size, circle)
    row["same_family"] = _family(row["half_a"]) == _family(row["half_b"]) != "failed"
    row["same_model"] = row["half_a"] == row["half_b"] != "failed"
    row["s"] = time.perf_counter() - t0
    return row


def summary(rows) -> str:
    """Per class: how often auto chose the right family, the rotation-fitted error (mean, max), the halves."""
    lines = [f"{'class':8} {'n':>3} {'right family':>12} {'models chosen':34} {'rot px mean':>11} {'max':>6} "
             f"{'seen px':>8} {'halves same family':>18} {'same model':>10} {'widest°':>7}"]
    for cls in dict.fromkeys(r["class"] for r in rows):
        rs = [r for r in rows if r["class"] == cls]
        fish = CLASSES[cls][2]
        right = [r["model"] != "failed" and get_model(r["model"]).IS_FISHEYE == fish
                 and (fish or r["model"] == "plumb_bob") for r in rs]
        chosen = {m: sum(r["model"] == m for r in rs) for m in dict.fromkeys(r["model"] for r in rs)}
        rot = np.array([r.get("rot_px", math.nan) for r in rs])
        seen = np.array([r.get("seen_px", math.nan) for r in rs])
        lines.append(f"{cls:8} {len(rs):3d} {sum(right):5d}/{len(rs):<6d} {str(chosen)[:34]:34} {np.nanmean(rot):11.4f} "
                     f"{np.nanmax(rot):6.3f} {np.nanmean(seen):8.4f} {sum(r['same_family'] for r in rs):11d}/{len(rs):<6d} "
                     f"{sum(r['same_model'] for r in rs):5d}/{len(rs):<4d} {np.mean([r['widest_deg'] for r in rs]):7.1f}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sequences", type=int, default=20)
    ap.add_argument("--views", type=int, default=20)
    ap.add_argument("--classes", default=",".join(CLASSES))
    ap.add_argument("--noise", type=float, default=0.015, help="corner noise, px per axis, fisheye classes")
    ap.add_argument("--noise-pinhole", type=float, default=0.05, help="corner noise, px per axis, pinhole classes")
    ap.add_argument("--seed", type=int, default=9000)
    ap.add_argument("--out", default=None, help="CSV path for the rows")
    ap.add_argument("--no-circle", action="store_true", help="do not pass the image circle to calibrate_camera")
    a = ap.parse_args(argv)
    classes = [c for c in a.classes.split(",") if c]
    unknown = [c for c in classes if c not in CLASSES]
    if unknown:
        ap.error(f"unknown class(es) {unknown}; choose from {', '.join(CLASSES)}")
    rows = []
    for k in range(a.sequences):
        for cls in classes:
            noise = a.noise if CLASSES[cls][2] else a.noise_pinhole
            rows.append(evaluate(cls, a.seed + k, a.views, noise, not a.no_circle))
            r = rows[-1]
            print(f"{cls} seed {a.seed + k}: {r['model']} rot {r.get('rot_px', math.nan):.4f} px, halves "
                  f"{r['half_a']}/{r['half_b']}, widest {r['widest_deg']:.1f}°, {r['s']:.0f} s", file=sys.stderr, flush=True)
            if a.out:  # rewritten after every sequence, so a cut-off run keeps its rows
                import pandas as pd

                pd.DataFrame(rows).to_csv(a.out, index=False)
    print(summary(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
