"""Hand-eye accuracy against OpenCV's five closed-form methods, on rendered sets with exact truth.

    .venv/bin/python benchmarks/handeye.py [--seeds 3] [--cases mild,strong,eye-to-hand,8-views,outliers]
        [--zscore-seeds 20] [--out handeye_bench.json] [--opencv-python PATH]

OpenCV 5.0's Python package has no calibrateHandEye; --opencv-python names an interpreter with
OpenCV 4 (e.g. a venv with opencv-python-headless<5 and numpy) that runs the OpenCV side.

Each case renders sets with ``data_gen.handeye`` (1280×960, 9×6 board of 40 mm squares 0.3–0.7 m
away, robot noise σ 0.01° and 0.05 mm per axis, read noise 2 grey levels):

* mild: f ≈ 1000 px, k1 ≈ −0.05, eye-in-hand, 20 views; strong: f ≈ 650 px, k1 ≈ −0.3 (strong
  barrel); eye-to-hand: mild lens, the board on the flange; 8-views: mild, 8 views;
  outliers: mild, 22 views of which 2 rows have swapped poses.

Ours: ``python -m aicalib_tf.handeye`` (CNN detector, lens model auto, intrinsics fitted jointly).
OpenCV: findChessboardCorners + cornerSubPix, calibrateCamera (plumb_bob), solvePnP per view with
those intrinsics, then cv2.calibrateHandEye with TSAI, PARK, HORAUD, ANDREFF and DANIILIDIS. OpenCV's
detections are put in the board's true order first (a chessboard read turned by 180° would
otherwise break every method; in practice OpenCV has no such help).

The z-score part uses corner-level synthetic sets (the same truth, projected corners with 0.1 px
noise, no rendering): over the seeds, each component of the transform's error divided by its stated σ;
the RMS of those z-scores should be near 1 (0.7–1.5).

Errors: rotation, the angle of X_true⁻¹·X (degrees); translation, |t − t_true| (mm).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]

CASES = {
    "mild": dict(lens="mild", setup="eye-in-hand", views=20),
    "strong": dict(lens="strong", setup="eye-in-hand", views=20),
    "eye-to-hand": dict(lens="mild", setup="eye-to-hand", views=20),
    "8-views": dict(lens="mild", setup="eye-in-hand", views=8),
    "outliers": dict(lens="mild", setup="eye-in-hand", views=22, swap=2),
}
METHODS = {"TSAI": cv2.CALIB_HAND_EYE_TSAI, "PARK": cv2.CALIB_HAND_EYE_PARK, "HORAUD": cv2.CALIB_HAND_EYE_HORAUD,
           "ANDREFF": cv2.CALIB_HAND_EYE_ANDREFF, "DANIILIDIS": cv2.CALIB_HAND_EYE_DANIILIDIS}


def _inv(T):
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = T[:3, :3].T, -T[:3, :3].T @ T[:3, 3]
    return out


def errors(X_true, X) -> tuple[float, float]:
    """(rotation degrees, translation mm)."""
    from aicalib_tf.geometry.transform import inv, rotation_angle

    return (math.degrees(float(rotation_angle((inv(X_true) @ X)[:3, :3]))),
            1e3 * float(np.linalg.norm(X[:3, 3] - X_true[:3, 3])))


def ours(folder: Path, setup: str) -> tuple[np.ndarray, dict, float]:
    """(X, handeye.json, seconds) of the command line on a rendered set."""
    from aicalib_tf.handeye import main

    out = folder / "out"
    t0 = time.perf_counter()
    rc = main([str(folder / "images" / "*.png"), "--poses", str(folder / "poses.csv"), "--pattern", "9x6",
               "--square", "40mm", "--setup", setup, "--out", str(out), "--quiet"])
    dt = time.perf_counter() - t0
    if rc != 0:
        raise RuntimeError(f"handeye failed on {folder}")
    res = json.loads((out / "handeye.json").read_text())
    key = "T_flange_camera" if setup == "eye-in-hand" else "T_base_camera"
    return np.array(res[key]["matrix"]), res, dt


def _opencv_views(folder: Path, truth: dict):
    """OpenCV's corners per image, put in the board's true order (the flip closest to the true projection)."""
    obj = np.zeros((54, 3), np.float32)
    obj[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * truth["square_m"]
    K, dist = np.array(truth["camera"]["K"]), np.array(truth["camera"]["dist"])
    found = []
    for k, name in enumerate(truth["images"]):
        img = cv2.imread(str(folder / "images" / name), cv2.IMREAD_GRAYSCALE)
        ok, c = cv2.findChessboardCorners(img, (9, 6), flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
        if not ok:
            continue
        c = cv2.cornerSubPix(img, c, (5, 5), (-1, -1), (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-3))
        C = np.array(truth["T_camera_board"][k])
        true_px = cv2.projectPoints(obj.astype(np.float64), cv2.Rodrigues(C[:3, :3])[0], C[:3, 3], K, dist)[0]
        c = c if np.abs(c - true_px).mean() < np.abs(c[::-1] - true_px).mean() else c[::-1]
        found.append((k, c))
    return obj, found


def opencv(folder: Path, truth: dict, python: str | None = None) -> dict:
    """{method: X} from OpenCV's own intrinsics and solvePnP poses (in ``python`` when given)."""
    if python:
        import subprocess

        text = subprocess.run([python, __file__, "--opencv-only", str(folder)], capture_output=True, text=True,
                              check=True).stdout
        return {m: np.array(X) for m, X in json.loads(text).items()}
    obj, found = _opencv_views(folder, truth)
    size = tuple(truth["camera"]["image_size"])
    _, K, dist, _, _ = cv2.calibrateCamera([obj] * len(found), [c for _, c in found], size, None, None)
    A = np.array(truth["T_base_flange_reported"])
    Rg, tg, Rt, tt = [], [], [], []
    for k, c in found:
        _, rv, tv = cv2.solvePnP(obj, c, K, dist, flags=cv2.SOLVEPNP_ITERATIVE)
        G = A[k] if truth["setup"] == "eye-in-hand" else _inv(A[k])
        Rg.append(G[:3, :3])
        tg.append(G[:3, 3].reshape(3, 1))
        Rt.append(cv2.Rodrigues(rv)[0])
        tt.append(tv.reshape(3, 1))
    out = {}
    for name, m in METHODS.items():
        R, t = cv2.calibrateHandEye(Rg, tg, Rt, tt, method=m)
        X = np.eye(4)
        X[:3, :3], X[:3, 3] = R, t.ravel()
        out[name] = X
    return out


def run_case(name: str, seeds: int, python: str | None = None) -> dict:
    from data_gen.handeye import HandEyeSetConfig, write_handeye_set

    rows = []
    for seed in range(seeds):
        cfg = HandEyeSetConfig(seed=100 + seed, **CASES[name])
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp)
            write_handeye_set(cfg, folder)
            truth = json.loads((folder / "truth.json").read_text())
            X_true = np.array(truth["X"])
            X, res, dt = ours(folder, cfg.setup)
            cv = {m: errors(X_true, Xm) for m, Xm in opencv(folder, truth, python).items()}
        rejected = sorted(r["image"] for r in res["rejected"])
        rows.append({"seed": cfg.seed, "ours": errors(X_true, X), "sigma_deg": res["T_flange_camera" if cfg.setup ==
                     "eye-in-hand" else "T_base_camera"]["sigma_deg"], "opencv": cv, "seconds": dt,
                     "rejected": rejected, "swapped": sorted(truth["swapped"]), "status": res["status"]})
        print(f"{name} seed {cfg.seed}: ours {rows[-1]['ours'][0]:.4f} deg {rows[-1]['ours'][1]:.3f} mm ({dt:.1f} s); "
              + "; ".join(f"{m} {e[0]:.4f} deg {e[1]:.3f} mm" for m, e in cv.items())
              + (f"; rejected {rejected} swapped {rows[-1]['swapped']}" if rejected or rows[-1]["swapped"] else ""),
              flush=True)
    return {"case": name, "rows": rows}


def summary(case: dict) -> dict:
    rows = case["rows"]
    ours_deg, ours_mm = (np.array([r["ours"][i] for r in rows]) for i in (0, 1))
    best = None
    for m in METHODS:
        d, t = (np.mean([r["opencv"][m][i] for r in rows]) for i in (0, 1))
        if best is None or d + t / 10 < best[1] + best[2] / 10:
            best = (m, d, t)
    named = all(set(r["swapped"]) <= set(r["rejected"]) for r in rows)
    return {"case": case["case"], "seeds": len(rows), "ours_deg_mean": float(ours_deg.mean()),
            "ours_deg_max": float(ours_deg.max()), "ours_mm_mean": float(ours_mm.mean()),
            "ours_mm_max": float(ours_mm.max()), "opencv_best": best[0], "opencv_deg_mean": float(best[1]),
            "opencv_mm_mean": float(best[2]), "swapped_named": named,
            "seconds_mean": float(np.mean([r["seconds"] for r in rows]))}


def zscores(seeds: int, views: int = 20, noise_px: float = 0.1) -> dict:
    """RMS z-score of the transform's error over ``seeds`` corner-level sets (module docstring)."""
    from aicalib_tf.calib.fit import View, calibrate_camera
    from aicalib_tf.calib.handeye.calibrate import calibrate_handeye
    from aicalib_tf.geometry.pattern import pattern_ids
    from data_gen.handeye import HandEyeSetConfig, sample_handeye

    z = []
    for seed in range(seeds):
        s = sample_handeye(HandEyeSetConfig(views=views, seed=500 + seed))
        rng = np.random.default_rng(seed)
        ids = pattern_ids((9, 6))
        obj = s.board.object_points() * 1e-3
        views_ = [View(f"v{k:02d}", s.camera.lens.project(obj @ C[:3, :3].T + C[:3, 3])
                       + rng.normal(0, noise_px, (54, 2)), ids) for k, C in enumerate(s.C)]
        poses = {f"v{k:02d}": s.A_reported[k] for k in range(views)}
        cal = calibrate_camera(views_, (9, 6), s.square_m, s.camera.image_size, model="plumb_bob", square_unit="m")
        r = calibrate_handeye(views_, poses, "eye-in-hand", cal.lens, s.square_m, pattern_size=(9, 6),
                              free_intrinsics=True, halves=False)
        w = cv2.Rodrigues(np.ascontiguousarray(s.X[:3, :3] @ r.X[:3, :3].T))[0].ravel()
        e = np.concatenate([s.X[:3, 3] - r.X[:3, 3], w])
        z.append(e / np.sqrt(np.diag(r.cov_X)))
    z = np.array(z)
    return {"seeds": seeds, "rms_z": float(np.sqrt(np.mean(z ** 2))), "rms_z_translation": float(np.sqrt(np.mean(z[:, :3] ** 2))),
            "rms_z_rotation": float(np.sqrt(np.mean(z[:, 3:] ** 2)))}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--opencv-only"]:  # the OpenCV side in another interpreter
        folder = Path(argv[1])
        found = opencv(folder, json.loads((folder / "truth.json").read_text()))
        print(json.dumps({m: X.tolist() for m, X in found.items()}))
        return 0
    sys.path.insert(0, str(ROOT))
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--zscore-seeds", type=int, default=20)
    ap.add_argument("--out", default=None, help="write the figures as JSON here")
    ap.add_argument("--opencv-python", default=None, help="an interpreter whose cv2 has calibrateHandEye")
    args = ap.parse_args(argv)
    report = {"cases": [], "summary": []}
    if args.zscore_seeds:
        report["zscore"] = zscores(args.zscore_seeds)
        print(f"z-score over {args.zscore_seeds} seeds: {report['zscore']}", flush=True)
    for name in filter(None, args.cases.split(",")):
        case = run_case(name, args.seeds, args.opencv_python)
        report["cases"].append(case)
        report["summary"].append(summary(case))
        print(json.dumps(report["summary"][-1]), flush=True)
    if args.out:
        Path(args.out).write_text(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
