"""Rig sequences scored against the truth: our rig calibration and OpenCV's stereo pipeline side by side.

Rigs come from :mod:`data_gen.rig` (:data:`RIGS`: two pinholes, pinhole + fisheye, two fisheyes,
three cameras). ``ours`` is the CNN detector (partial boards with ids), :func:`aicalib_tf.calib.rig.fit.calibrate_rig`
and :func:`aicalib_tf.calib.rig.quality.assess_rig`. ``opencv`` is ``findChessboardCorners`` +
``cornerSubPix`` (full boards), each camera by ``cv2.calibrateCamera`` or ``cv2.fisheye.calibrate``
(the user knows which lens is a fisheye), then ``cv2.stereoCalibrate`` / ``cv2.fisheye.stereoCalibrate``
with ``CALIB_FIX_INTRINSIC`` on the frames both cameras found (a mixed pair: ``cv2.stereoCalibrate`` on
undistorted, normalized points with K = I: the same fixed-intrinsics problem, which OpenCV has no
mixed-model call for). Both are rectified by :func:`aicalib_tf.geometry.rectify.rectify_pair` of their
own calibration, and both get the same 5-fold leave-pairs-out |Δy|.
"""

from __future__ import annotations

import time

import cv2
import numpy as np

from aicalib_tf.bench.opencv_calib import fisheye_calibrate
from aicalib_tf.calib.fit import View
from aicalib_tf.calib.rig.fit import calibrate_rig
from aicalib_tf.calib.rig.quality import MAX_FOLDS, assess_rig, epipolar_deltas
from aicalib_tf.geometry.lens import Lens
from aicalib_tf.geometry.pattern import board_points
from aicalib_tf.geometry.rectify import rectify_pair, rotation_angle_deg

__all__ = ["RIGS", "RIG_PAIRS", "evaluate_rig", "opencv_rig_pair", "detect_views"]

RIGS = {"pinhole": ("pinhole", "pinhole"), "mixed": ("pinhole", "fisheye"), "fisheye": ("fisheye", "fisheye"),
        "three": ("pinhole", "pinhole", "fisheye")}
RIG_PAIRS = 20  # pairs per rig sequence
_CRIT = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-10)


def detect_views(images, detector) -> tuple[list[View], float]:
    """(views named by frame index, seconds) of one camera's images (uint8 grey)."""
    t0, out = time.perf_counter(), []
    for f, img in enumerate(images):
        found = detector(img)
        if len(found.corners) >= 6:
            out.append(View(f"{f:02d}", found.corners, found.ids, relative=bool(found.relative),
                            sigmas=found.sigmas))
    return out, time.perf_counter() - t0


# ----------------------------------------------------------------------------- OpenCV's pipeline
def _cv_camera(views, square, size, fisheye: bool) -> Lens:
    obj = [board_points(v.ids, square).astype(np.float64).reshape(1, -1, 3) for v in views]
    img = [v.corners.astype(np.float64).reshape(1, -1, 2) for v in views]
    if not fisheye:
        _, K, D, _, _ = cv2.calibrateCamera([o.reshape(-1, 3).astype(np.float32) for o in obj],
                                            [i.reshape(-1, 1, 2).astype(np.float32) for i in img], size, None, None,
                                            criteria=_CRIT)
        return Lens("plumb_bob", K, D.ravel()[:5], size)
    _, K, D, _ = fisheye_calibrate(obj, img, size, _CRIT)
    return Lens("equidistant", K, D.ravel(), size)


def _normalized(lens: Lens, px) -> np.ndarray:
    rays = lens.unproject(px)
    return (rays[:, :2] / rays[:, 2:]).astype(np.float64)


def _cv_stereo(lens_a: Lens, lens_b: Lens, va, vb, square) -> tuple[np.ndarray, np.ndarray]:
    """(R, T) of camera b from camera a by OpenCV's stereo call with the intrinsics fixed."""
    vb_by = {v.name: v for v in vb}
    pairs = [(v, vb_by[v.name]) for v in va if v.name in vb_by]
    obj = [board_points(a.ids, square).astype(np.float64).reshape(-1, 1, 3) for a, _ in pairs]
    size = lens_a.image_size
    if lens_a.spec.NAMES["opencv"] == lens_b.spec.NAMES["opencv"] == "fisheye":
        out = cv2.fisheye.stereoCalibrate(obj, [a.corners.reshape(-1, 1, 2) for a, _ in pairs],
                                          [b.corners.reshape(-1, 1, 2) for _, b in pairs], lens_a.K.copy(),
                                          lens_a.dist.copy(), lens_b.K.copy(), lens_b.dist.copy(), size, flags=cv2.CALIB_FIX_INTRINSIC, criteria=_CRIT)
        return out[5], out[6].ravel()
    if lens_a.model == lens_b.model and lens_a.spec.NAMES["opencv"] == "calibrateCamera":
        pa = [a.corners.astype(np.float32).reshape(-1, 1, 2) for a, _ in pairs]
        pb = [b.corners.astype(np.float32).reshape(-1, 1, 2) for _, b in pairs]
        out = cv2.stereoCalibrate([o.astype(np.float32) for o in obj], pa, pb, lens_a.K.copy(), lens_a.dist.copy(),
                                  lens_b.K.copy(), lens_b.dist.copy(), size, np.eye(3), np.zeros((3, 1)), flags=cv2.CALIB_FIX_INTRINSIC,
                                  criteria=_CRIT)
        return out[5], out[6].ravel()
    na = [_normalized(lens_a, a.corners).astype(np.float32).reshape(-1, 1, 2) for a, _ in pairs]
    nb = [_normalized(lens_b, b.corners).astype(np.float32).reshape(-1, 1, 2) for _, b in pairs]
    out = cv2.stereoCalibrate([o.astype(np.float32) for o in obj], na, nb, np.eye(3), np.zeros(5), np.eye(3),
                              np.zeros(5), size, np.eye(3), np.zeros((3, 1)), flags=cv2.CALIB_FIX_INTRINSIC,
                              criteria=_CRIT)
    return out[5], out[6].ravel()


def opencv_pair(views_a, views_b, square, size_a, size_b, fish_a, fish_b, held=()):
    """(lens_a, lens_b, R, T) by OpenCV's pipeline on every frame not in ``held``."""
    va = [v for v in views_a if v.name not in held]
    vb = [v for v in views_b if v.name not in held]
    la, lb = _cv_camera(va, square, size_a, fish_a), _cv_camera(vb, square, size_b, fish_b)
    R, T = _cv_stereo(la, lb, va, vb, square)
    return la, lb, R, T


def _dy_rms(la, lb, R, T, va, vb, frames=None) -> float:
    rect = rectify_pair(la, lb, R, T)
    d = epipolar_deltas(la, lb, rect, va, vb, frames)
    allv = np.concatenate(list(d.values())) if d else np.zeros(0)
    return float(np.sqrt(np.mean(allv ** 2))) if allv.size else float("nan")


def opencv_rig_pair(views_a, views_b, square, sizes, fish) -> dict:
    """OpenCV's pipeline on one pair: R, T, |Δy| RMS in-sample and held-out (5-fold over shared frames)."""
    la, lb, R, T = opencv_pair(views_a, views_b, square, *sizes, *fish)
    shared = sorted({v.name for v in views_a} & {v.name for v in views_b})
    k = min(MAX_FOLDS, len(shared))
    held = []
    for f in range(k):
        out = set(shared[f::k])
        try:
            fa, fb, Rf, Tf = opencv_pair(views_a, views_b, square, *sizes, *fish, held=out)
        except cv2.error:
            continue
        rect = rectify_pair(fa, fb, Rf, Tf)
        held += list(epipolar_deltas(fa, fb, rect, views_a, views_b, out).values())
    hv = np.concatenate(held) if held else np.zeros(0)
    return {"R": R, "T": T, "in": _dy_rms(la, lb, R, T, views_a, views_b),
            "held": float(np.sqrt(np.mean(hv ** 2))) if hv.size else float("nan"), "frames": len(shared)}


# ----------------------------------------------------------------------------- one rig
def evaluate_rig(name, seed, pairs, detectors) -> list[dict]:
    """Render rig ``name`` (seed ``1000·index + seed``) with ``pairs`` frames, run both pipelines, score
    each pair with camera 0 against the truth: one dict per pair and pipeline. detectors : {"cnn", "opencv"}
    functions of :func:`aicalib_tf.bench.detectors.make_detectors` (the cnn one with relative ids)."""
    from data_gen.rig import make_rig_sequence

    lenses = RIGS[name]
    truth, frames = make_rig_sequence(1000 * list(RIGS).index(name) + seed, pairs, lenses)
    square = truth.board.square_size
    C = len(lenses)
    sizes = [tuple(c.image_size) for c in truth.cameras]
    rows = []
    det = {d: [detect_views([fr[k].image for fr in frames], detectors[d]) for k in range(C)] for d in ("cnn", "opencv")}
    t0 = time.perf_counter()
    rig = assess_rig(calibrate_rig([v for v, _ in det["cnn"]], (9, 6), square, sizes), [v for v, _ in det["cnn"]])
    t_ours = time.perf_counter() - t0
    for k in range(1, C):
        b_true = truth.baseline(k)
        p = rig.quality["pairs"][k - 1]
        rows.append(_row(name, seed, k, "ours", truth, rig.R[k], rig.T[k], p["in_sample_rms_px"], p["held_out_rms_px"],
                         p["pairs"], sum(t for _, t in det["cnn"]), t_ours, b_true))
        t0 = time.perf_counter()
        views = [v for v, _ in det["opencv"]]
        try:
            cv = opencv_rig_pair(views[0], views[k], square, (sizes[0], sizes[k]),
                                 (lenses[0] == "fisheye", lenses[k] == "fisheye"))
            rows.append(_row(name, seed, k, "opencv", truth, cv["R"], cv["T"], cv["in"], cv["held"], cv["frames"],
                             sum(t for _, t in det["opencv"]), time.perf_counter() - t0, b_true))
        except (cv2.error, ValueError) as exc:
            rows.append({"rig": name, "seed": seed, "pair": f"cam0-cam{k}", "pipeline": "opencv",
                         "note": f"failed: {str(exc).strip().splitlines()[-1][:80]}"})
    return rows


def _row(name, seed, k, pipe, truth, R, T, dy_in, dy_held, n, t_det, t_cal, b_true) -> dict:
    return {"rig": name, "seed": seed, "pair": f"cam0-cam{k}", "pipeline": pipe,
            "lenses": f"{truth.cameras[0].model}+{truth.cameras[k].model}", "baseline_mm": b_true,
            "baseline_err_pct": 100 * abs(np.linalg.norm(T) - b_true) / b_true,
            "rot_err_deg": rotation_angle_deg(np.asarray(R) @ truth.R[k].T), "dy_in_px": dy_in,
            "dy_held_px": dy_held if dy_held is not None else float("nan"), "frames": n, "t_detect_s": t_det,
            "t_calib_s": t_cal, "note": ""}
