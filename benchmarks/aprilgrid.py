"""AprilGrid detection and calibration on rendered pinhole views with exact truth.

    .venv/bin/python benchmarks/aprilgrid.py [--views 24] [--calib-views 8] [--seed 0]

Each view renders Kalibr's 6x6 AprilGrid (tag 88 mm, spacing 0.3) through a pinhole camera
(fx = fy = 900 px, 1280x960) by a homography with 4x4 supersampling, then a Gaussian blur
(σ 0.7 px) and noise (σ 2/255); a third of the views put the board partly out of frame. Truth is
the projection of each tag corner. For the corners of the tags seen whole (all four corners at
least 3 px inside the image) it reports recall, wrong ids (a corner nearer another corner's true
place than its own), corners over 2 px off, and the corner error of:

* ours: OpenCV's aruco decodes the tags, the project's saddle fit places the corners
  (:func:`aicalib_tf.detect.boards.aprilgrid.detect_aprilgrid`);
* OpenCV's aruco with CORNER_REFINE_SUBPIX, and with CORNER_REFINE_APRILTAG.

``--lens MODEL --dist ...`` (and ``--fx``) renders through that lens of :mod:`aicalib_tf.geometry.lens`
instead (each supersampled pixel's ray from ``unproject``, 3x3 samples a pixel; e.g. ``--lens
equidistant --dist 0.05 -0.01 0 0 --fx 400``, a fisheye), truth projected through it, and the
calibration fits that model.

Then it calibrates (:func:`aicalib_tf.calib.fit.calibrate_camera`, the rendered lens's model) from the first
``--calib-views`` views and reports the focal length's and the principal point's errors.
"""

from __future__ import annotations

import argparse
import functools
import sys
import time

import cv2
import numpy as np

from aicalib_tf.detect.boards.aprilgrid import detect_aprilgrid
from aicalib_tf.geometry.aprilgrid import layout_image, parse_board, render_view
from aicalib_tf.geometry.lens import project, unproject

BOARD = "aprilgrid:6x6,tag=88mm,spacing=0.3"
SIZE = (1280, 960)
K = np.array([[900.0, 0, 639.5], [0, 900.0, 479.5], [0, 0, 1]])
PX_PER_UNIT = 8  # layout px per lattice unit: 80 px a tag, 8 px a bit


def random_view(board, rng, partial: bool):
    """(rvec, tvec) in lattice units: the board tilted up to ~45°, its centre at a random image
    point (near an edge when ``partial``)."""
    L = np.array(board.pattern_size, np.float64) - 1
    tilt = rng.uniform(-0.7, 0.7, 2)
    rvec = np.array([tilt[0], tilt[1], rng.uniform(-0.5, 0.5)])
    R, _ = cv2.Rodrigues(rvec)
    z = rng.uniform(90, 150) * K[0, 0] / 900.0  # the same size in the image at any focal length
    if partial:
        p = np.array([rng.choice([0.05, 0.95]) * SIZE[0], rng.uniform(0.2, 0.8) * SIZE[1]])
    else:
        p = np.array([rng.uniform(0.4, 0.6) * SIZE[0], rng.uniform(0.4, 0.6) * SIZE[1]])
    ray = unproject(p, LENS["model"], K, LENS["dist"])
    ray = ray / ray[2]
    tvec = z * ray - R @ np.array([L[0] / 2, L[1] / 2, 0.0])
    return rvec, tvec


LENS = {"model": "plumb_bob", "dist": np.zeros(5)}  # the rendered lens (--lens, --dist); zero plumb_bob: a pinhole
SUPER = 3  # samples a pixel along each axis through a distorting lens


def distorted() -> bool:
    return LENS["model"] != "plumb_bob" or bool(np.any(LENS["dist"]))


@functools.lru_cache(maxsize=1)
def _rays(model: str, dist: tuple) -> np.ndarray:
    """(h·S, w·S, 3) float64 unit rays of the supersampled pixels (``geometry.lens.unproject``)."""
    s = SUPER
    ys, xs = np.mgrid[0: SIZE[1] * s, 0: SIZE[0] * s].astype(np.float64)
    px = np.stack([(xs - (s - 1) / 2) / s, (ys - (s - 1) / 2) / s], axis=-1)
    return unproject(px, model, K, np.asarray(dist))


def _render_distorted(layout, margin, R, tvec) -> np.ndarray:
    """(H, W) float32 in [0, 1]: the layout seen through LENS, area-averaged over SUPER² samples."""
    rays = _rays(LENS["model"], tuple(LENS["dist"]))
    b = rays @ np.linalg.inv(np.column_stack([R[:, 0], R[:, 1], tvec])).T  # λ·(X, Y, 1) for the ray λ·d
    with np.errstate(invalid="ignore", divide="ignore"):
        front = b[..., 2] > 0
        X = np.where(front, b[..., 0] / b[..., 2], -1e6)
        Y = np.where(front, b[..., 1] / b[..., 2], -1e6)
    mx = np.nan_to_num(margin - 0.5 + X * PX_PER_UNIT, nan=-1e6).astype(np.float32)
    my = np.nan_to_num(margin - 0.5 + Y * PX_PER_UNIT, nan=-1e6).astype(np.float32)
    big = cv2.remap(layout.astype(np.float32) / 255.0, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                    borderValue=1.0)
    return cv2.resize(big, SIZE, interpolation=cv2.INTER_AREA)


def render(board, layout, margin, rvec, tvec, rng) -> np.ndarray:
    """(H, W) uint8 view of the board at pose (rvec, tvec), blurred and noisy."""
    R, _ = cv2.Rodrigues(np.asarray(rvec, np.float64))
    if distorted():
        img = _render_distorted(layout, margin, R, np.asarray(tvec, np.float64))
    else:
        img = render_view(layout, PX_PER_UNIT, margin, K @ np.column_stack([R[:, 0], R[:, 1], tvec]), SIZE, 4)
    img = cv2.GaussianBlur(img, (0, 0), 0.7) + rng.normal(0, 2 / 255, img.shape).astype(np.float32)
    return np.clip(np.rint(img * 255), 0, 255).astype(np.uint8)


def truth(board, ids, rvec, tvec) -> np.ndarray:
    """(N, 2) px: where lattice ids (N, 2) project."""
    obj = board.object_points(ids) / board.square_size
    R, _ = cv2.Rodrigues(np.asarray(rvec, np.float64))
    return project(obj @ R.T + np.asarray(tvec, np.float64), LENS["model"], K, LENS["dist"])


def whole_tag_corners(board, rvec, tvec) -> set:
    """Lattice ids (as tuples) of the corners of the tags seen whole, 3 px inside the image."""
    out = set()
    for k in board.tag_ids():
        ids = board.tag_corner_ids(int(k))
        px = truth(board, ids, rvec, tvec)
        if ((px >= 3) & (px <= np.array(SIZE) - 4)).all():
            out |= {tuple(int(v) for v in i) for i in ids}
    return out


def score(board, det, rvec, tvec, expected: set) -> dict:
    """Of the corners in ``expected``: how many came back, how many are over 2 px off, how many
    lie nearer another corner's true place than their own (wrong ids), and their errors px."""
    keep = np.array([tuple(int(v) for v in i) in expected for i in det.ids], bool)
    if not keep.any():
        return {"found": 0, "off": 0, "wrong": 0, "err": np.zeros(0)}
    err = np.linalg.norm(det.corners[keep] - truth(board, det.ids[keep], rvec, tvec), axis=1)
    every = truth(board, board.corner_ids(), rvec, tvec)
    nearest = np.min(np.linalg.norm(det.corners[keep][:, None] - every[None], axis=2), axis=1)
    return {"found": int(keep.sum()), "off": int(np.sum(err > 2.0)), "wrong": int(np.sum(err > nearest + 1e-9)),
            "err": err}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--views", type=int, default=24)
    ap.add_argument("--calib-views", type=int, default=8)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--lens", default="plumb_bob", help="the rendered lens model (geometry.lens), e.g. equidistant")
    ap.add_argument("--dist", type=float, nargs="+", default=[0.0] * 5, help="its coefficients, OpenCV's order")
    ap.add_argument("--fx", type=float, default=900.0, help="focal length px (fx = fy)")
    args = ap.parse_args(argv)
    LENS.update(model=args.lens, dist=np.asarray(args.dist, np.float64))
    K[0, 0] = K[1, 1] = args.fx
    from aicalib_tf.calib.fit import View, calibrate_camera

    board = parse_board(BOARD)
    margin = board.fraction[0] * PX_PER_UNIT + 8
    layout = layout_image(board, PX_PER_UNIT, margin)
    rng = np.random.default_rng(args.seed)
    methods = ("saddle", "opencv", "apriltag")
    stats = {m: {"found": 0, "off": 0, "wrong": 0, "err": [], "s": 0.0} for m in methods}
    expected_total, views = 0, []
    for v in range(args.views):
        rvec, tvec = random_view(board, rng, partial=v % 3 == 2)
        img = render(board, layout, margin, rvec, tvec, rng)
        expected = whole_tag_corners(board, rvec, tvec)
        expected_total += len(expected)
        for m in methods:
            t = time.perf_counter()
            det = detect_aprilgrid(img, board, m)
            stats[m]["s"] += time.perf_counter() - t
            s = score(board, det, rvec, tvec, expected)
            stats[m]["found"] += s["found"]
            stats[m]["off"] += s["off"]
            stats[m]["wrong"] += s["wrong"]
            stats[m]["err"].append(s["err"])
            if m == "saddle" and len(views) < args.calib_views:
                views.append(View(f"view{v}", det.corners, det.ids))
    print(f"{args.views} views, {expected_total} corners of tags seen whole")
    for m in methods:
        e = np.concatenate(stats[m]["err"])
        print(f"{m:9s} recall {stats[m]['found'] / expected_total:.3f} "
              f"(within 2 px {(stats[m]['found'] - stats[m]['off']) / expected_total:.3f})  wrong ids {stats[m]['wrong']}  over 2 px off {stats[m]['off']}  "
              f"median {np.median(e):.4f} px  p95 {np.percentile(e, 95):.4f} px  max {e.max():.3f} px  "
              f"{1000 * stats[m]['s'] / args.views:.0f} ms/view")
    cal = calibrate_camera(views, board.pattern_size, board.square_size, SIZE, model=LENS["model"], square_unit=board.unit)
    fx, fy = cal.K[0, 0], cal.K[1, 1]
    cx, cy = cal.K[0, 2], cal.K[1, 2]
    print(f"calibration from {len(views)} views: rms {cal.rms:.4f} px, fx {fx:.2f} ({100 * (fx / K[0, 0] - 1):+.3f}%), "
          f"fy {fy:.2f} ({100 * (fy / K[1, 1] - 1):+.3f}%), cx {cx - K[0, 2]:+.2f} px, cy {cy - K[1, 2]:+.2f} px, "
          f"k1 {cal.dist.ravel()[0]:+.4f} (truth {LENS['dist'][0]:+.4f}), k2 {cal.dist.ravel()[1]:+.4f} "
          f"(truth {LENS['dist'][1]:+.4f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
