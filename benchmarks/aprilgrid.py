"""AprilGrid detection and calibration on rendered pinhole views with exact truth.

    .venv/bin/python benchmarks/aprilgrid.py [--views 24] [--calib-views 8] [--seed 0]

Each view renders Kalibr's 6x6 AprilGrid (tag 88 mm, spacing 0.3) through a pinhole camera
(fx = fy = 900 px, 1280x960) with data_gen's exact renderer (:class:`data_gen.aprilgrid.AprilGridTarget`
and :func:`data_gen.render.render_board`: every edge pixel's coverage from 89-233 samples, rays from
the lens model), on a grey background, then a Gaussian blur (σ 0.7 px) and noise (σ 2/255); a third
of the views put the board partly out of frame. Truth is the projection of each tag corner. For the
corners of the tags seen whole (all four corners at least 3 px inside the image) it reports recall,
wrong ids (a corner nearer another corner's true place than its own), corners over 2 px off, and the
corner error of:

* ours: OpenCV's aruco decodes the tags (those it missed beside placed ones again, seen square-on
  through their neighbours' homography), the project's saddle fit places the corners
  (:func:`aicalib_tf.detect.boards.aprilgrid.detect_aprilgrid`);
* OpenCV's aruco with CORNER_REFINE_SUBPIX, and with CORNER_REFINE_APRILTAG.

``--lens MODEL --dist ...`` (and ``--fx``) renders through that lens of :mod:`aicalib_tf.geometry.lens`
instead (e.g. ``--lens equidistant --dist 0.05 -0.01 0 0 --fx 450``, a fisheye), truth projected
through it, and the calibration fits that model.

Then it calibrates (:func:`aicalib_tf.calib.fit.calibrate_camera`, the rendered lens's model) from the first
``--calib-views`` views and reports the focal length's and the principal point's errors.
"""

from __future__ import annotations

import argparse
import sys
import time

import cv2
import numpy as np

from aicalib_tf.detect.boards.aprilgrid import detect_aprilgrid
from aicalib_tf.geometry.aprilgrid import parse_board
from aicalib_tf.geometry.camera import Camera
from aicalib_tf.geometry.pose import project_points
from data_gen.aprilgrid import AprilGridTarget
from data_gen.render import render_board

BOARD = "aprilgrid:6x6,tag=88mm,spacing=0.3"
SIZE = (1280, 960)
BACKGROUND = 0.5  # grey level around the paper


def random_view(target: AprilGridTarget, cam: Camera, rng, partial: bool):
    """(rvec, tvec), mm: the board tilted up to ~45°, its centre at a random image point (near an
    edge when ``partial``), 0.8-1.3 m away at fx 900 (the same size in the image at any focal length)."""
    tilt = rng.uniform(-0.7, 0.7, 2)
    rvec = np.array([tilt[0], tilt[1], rng.uniform(-0.5, 0.5)])
    R, _ = cv2.Rodrigues(rvec)
    z = rng.uniform(90, 150) * target.square_size * cam.fx / 900.0
    if partial:
        p = np.array([rng.choice([0.05, 0.95]) * SIZE[0], rng.uniform(0.2, 0.8) * SIZE[1]])
    else:
        p = np.array([rng.uniform(0.4, 0.6) * SIZE[0], rng.uniform(0.4, 0.6) * SIZE[1]])
    ray = cam.pixel_to_ray(p)
    return rvec, z * ray / ray[2] - R @ target.centre()


def render(target: AprilGridTarget, cam: Camera, rvec, tvec, rng) -> np.ndarray:
    """(H, W) uint8 view of the board at pose (rvec, tvec), blurred and noisy."""
    img = render_board(cam, target, rvec, tvec, np.full(SIZE[::-1], BACKGROUND, np.float32))
    img = cv2.GaussianBlur(img, (0, 0), 0.7) + rng.normal(0, 2 / 255, img.shape).astype(np.float32)
    return np.clip(np.rint(img * 255), 0, 255).astype(np.uint8)


def truth(board, cam: Camera, ids, rvec, tvec) -> np.ndarray:
    """(N, 2) px: where lattice ids (N, 2) project."""
    return project_points(board.object_points(ids), rvec, tvec, cam)


def whole_tag_corners(board, cam: Camera, rvec, tvec) -> set:
    """Lattice ids (as tuples) of the corners of the tags seen whole, 3 px inside the image."""
    out = set()
    for k in board.tag_ids():
        ids = board.tag_corner_ids(int(k))
        px = truth(board, cam, ids, rvec, tvec)
        if ((px >= 3) & (px <= np.array(SIZE) - 4)).all():
            out |= {tuple(int(v) for v in i) for i in ids}
    return out


def score(board, cam: Camera, det, rvec, tvec, expected: set) -> dict:
    """Of the corners in ``expected``: how many came back, how many are over 2 px off, how many
    lie nearer another corner's true place than their own (wrong ids), and their errors px."""
    keep = np.array([tuple(int(v) for v in i) in expected for i in det.ids], bool)
    if not keep.any():
        return {"found": 0, "off": 0, "wrong": 0, "err": np.zeros(0)}
    err = np.linalg.norm(det.corners[keep] - truth(board, cam, det.ids[keep], rvec, tvec), axis=1)
    every = truth(board, cam, board.corner_ids(), rvec, tvec)
    nearest = np.min(np.linalg.norm(det.corners[keep][:, None] - every[None], axis=2), axis=1)
    return {"found": int(keep.sum()), "off": int(np.sum(err > 2.0)), "wrong": int(np.sum(err > nearest + 1e-9)),
            "err": err}


def _report(stats: dict, expected_total: int, views: int, render_s: float) -> None:
    print(f"{views} views, {expected_total} corners of tags seen whole; render {render_s / views:.2f} s a view")
    for m, st in stats.items():
        e = np.concatenate(st["err"])
        print(f"{m:9s} recall {st['found'] / expected_total:.3f} "
              f"(within 2 px {(st['found'] - st['off']) / expected_total:.3f})  wrong ids {st['wrong']}  "
              f"over 2 px off {st['off']}  median {np.median(e):.4f} px  p95 {np.percentile(e, 95):.4f} px  "
              f"max {e.max():.3f} px  {1000 * st['s'] / views:.0f} ms/view")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--views", type=int, default=24)
    ap.add_argument("--calib-views", type=int, default=8)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--lens", default="plumb_bob", help="the rendered lens model (geometry.lens), e.g. equidistant")
    ap.add_argument("--dist", type=float, nargs="+", default=[0.0] * 5, help="its coefficients, OpenCV's order")
    ap.add_argument("--fx", type=float, default=900.0, help="focal length px (fx = fy)")
    args = ap.parse_args(argv)
    from aicalib_tf.calib.fit import View, calibrate_camera

    K = np.array([[args.fx, 0, (SIZE[0] - 1) / 2], [0, args.fx, (SIZE[1] - 1) / 2], [0, 0, 1]])
    cam = Camera(K, np.asarray(args.dist, np.float64), SIZE, model=args.lens)
    board = parse_board(BOARD)
    target = AprilGridTarget(board, margin=0.25, black=0.0, white=1.0)
    rng = np.random.default_rng(args.seed)
    methods = ("saddle", "opencv", "apriltag")
    stats = {m: {"found": 0, "off": 0, "wrong": 0, "err": [], "s": 0.0} for m in methods}
    expected_total, views, render_s = 0, [], 0.0
    for v in range(args.views):
        rvec, tvec = random_view(target, cam, rng, partial=v % 3 == 2)
        t = time.perf_counter()
        img = render(target, cam, rvec, tvec, rng)
        render_s += time.perf_counter() - t
        expected = whole_tag_corners(board, cam, rvec, tvec)
        expected_total += len(expected)
        for m in methods:
            t = time.perf_counter()
            det = detect_aprilgrid(img, board, m)
            stats[m]["s"] += time.perf_counter() - t
            s = score(board, cam, det, rvec, tvec, expected)
            for key in ("found", "off", "wrong"):
                stats[m][key] += s[key]
            stats[m]["err"].append(s["err"])
            if m == "saddle" and len(views) < args.calib_views:
                views.append(View(f"view{v}", det.corners, det.ids))
    _report(stats, expected_total, args.views, render_s)
    cal = calibrate_camera(views, board.pattern_size, board.square_size, SIZE, model=args.lens, square_unit=board.unit)
    fx, fy = cal.K[0, 0], cal.K[1, 1]
    cx, cy = cal.K[0, 2], cal.K[1, 2]
    dist = np.r_[np.asarray(args.dist, np.float64), 0.0, 0.0]
    print(f"calibration from {len(views)} views: rms {cal.rms:.4f} px, fx {fx:.2f} ({100 * (fx / K[0, 0] - 1):+.3f}%), "
          f"fy {fy:.2f} ({100 * (fy / K[1, 1] - 1):+.3f}%), cx {cx - K[0, 2]:+.2f} px, cy {cy - K[1, 2]:+.2f} px, "
          f"k1 {cal.dist.ravel()[0]:+.4f} (truth {dist[0]:+.4f}), k2 {cal.dist.ravel()[1]:+.4f} (truth {dist[1]:+.4f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
