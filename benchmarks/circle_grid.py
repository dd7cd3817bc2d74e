"""Circle grid detection and calibration on rendered views with exact truth, with and without the
projected-centre bias correction, against cv2.findCirclesGrid + cv2.calibrateCamera.

    .venv/bin/python benchmarks/circle_grid.py [--board circles:4x11,spacing=20mm,asymmetric] [--views 12] [--seed 0]
        [--blur SIGMA] [--gradient G]

Each view renders the grid (:func:`aicalib_tf.geometry.circles.render_view`, 4x4 supersampling,
optionally a blur and a light gradient, then noise σ 1/255) at a random pose (distance 300-500 mm, tilts up to 45°) through two cameras
of 800x600 px, fx = fy = 700, (cx, cy) = (405, 296): a pinhole, and a barrel lens (OpenCV's
plumb_bob, k1 = -0.3, k2 = 0.1). Truth is the projection of each circle's centre. It reports, per
camera, the centre error of OpenCV's centres and of ours (dark-area centroid) before and after the
correction with the true lens and poses, then the calibration errors (fx %, principal point px,
RMS px) of:

* ours, no correction: the project's centres, :func:`aicalib_tf.calib.fit.calibrate_camera` (plumb_bob);
* ours, corrected: the same with :func:`aicalib_tf.calib.circle_bias.calibrate_circles` (2 iterations);
* OpenCV: cv2.findCirclesGrid's centres and cv2.calibrateCamera (5 coefficients).
"""

from __future__ import annotations

import argparse
import functools
import sys
import time

import cv2
import numpy as np

from aicalib_tf.calib.circle_bias import calibrate_circles, centre_offsets
from aicalib_tf.calib.fit import View, calibrate_camera
from aicalib_tf.detect.boards.circles import find_grid, refine_centres
from aicalib_tf.geometry.circles import CircleGrid, parse_board, pose_maps, render_view

SIZE = (800, 600)
K_TRUE = np.array([[700.0, 0.0, 405.0], [0.0, 700.0, 296.0], [0.0, 0.0, 1.0]])
LENSES = {"pinhole": np.zeros(5), "barrel": np.array([-0.3, 0.1, 0.0, 0.0, 0.0])}


def random_pose(board: CircleGrid, rng: np.random.Generator, K=K_TRUE, size=SIZE):
    """(rvec, tvec) of a board at 300-500 mm, tilted up to 45°, its centre near the image's."""
    pts = board.object_points()
    mid = (pts.min(axis=0) + pts.max(axis=0)) / 2
    while True:
        tilt = rng.uniform(-0.78, 0.78, 2)
        rvec = np.array([tilt[0], tilt[1], rng.uniform(-0.3, 0.3)])
        R, _ = cv2.Rodrigues(rvec)
        z = rng.uniform(300, 500)
        aim = np.array([rng.uniform(-0.25, 0.25) * z, rng.uniform(-0.2, 0.2) * z, z])
        tvec = aim - R @ mid
        uv = cv2.projectPoints(pts, rvec, tvec, K, None)[0].reshape(-1, 2)
        if np.all((uv > 40) & (uv < np.array(size) - 40)):
            return rvec, tvec


def render(board, K, dist, rvec, tvec, rng, size=SIZE, noise=1 / 255, blur=0.0, gradient=0.0):
    """uint8 image of the board at that pose through (K, dist): a Gaussian blur (σ px), light
    falling linearly by ``gradient`` from the left edge to the right, Gaussian noise."""
    img = render_view(board, size, *pose_maps(K, dist, rvec, tvec), supersample=4).astype(np.float64)
    if blur:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    img = img * (1 - gradient * np.linspace(0, 1, size[0])[None, :]) + rng.normal(0, noise, img.shape)
    return np.round(np.clip(img, 0, 1) * 255).astype(np.uint8)


def measure(board, dist, poses, rng, blur=0.0, gradient=0.0):
    """Per view: (truth, OpenCV's centres, ours) (N, 2) each, None where OpenCV found no grid."""
    out = []
    for rvec, tvec in poses:
        img = render(board, K_TRUE, dist, rvec, tvec, rng, blur=blur, gradient=gradient)
        truth = cv2.projectPoints(board.object_points(), rvec, tvec, K_TRUE, dist)[0].reshape(-1, 2)
        cv_centres = find_grid(img, board)
        out.append(None if cv_centres is None else (truth, cv_centres, refine_centres(img, cv_centres)))
    return out


def calib_errors(K, rms):
    return {"fx_%": 100 * (K[0, 0] / K_TRUE[0, 0] - 1), "pp_px": float(np.hypot(*(K[:2, 2] - K_TRUE[:2, 2]))),
            "rms_px": float(rms)}


def compare(board, dist, poses, found):
    """{name: calib_errors} for ours (0 and 2 corrections) and OpenCV's."""
    keep = [(p, f) for p, f in zip(poses, found) if f is not None]
    views = [View(f"v{k}", f[2], board.circle_ids()) for k, (_, f) in enumerate(keep)]
    fit = functools.partial(calibrate_camera, pattern_size=board.pattern_size, square_size=board.square_size,
                            image_size=SIZE, model="plumb_bob", reject_outliers=False, flex="off")
    res = {}
    for it in (0, 2):
        cal, _ = calibrate_circles(views, board, fit, iterations=it)
        res[f"ours, {it} corrections"] = calib_errors(cal.K, cal.rms)
    obj = [board.object_points().astype(np.float32) for _ in keep]
    img = [f[1].astype(np.float32) for _, f in keep]
    rms, K, *_ = cv2.calibrateCamera(obj, img, SIZE, None, None)
    res["OpenCV findCirclesGrid + calibrateCamera"] = calib_errors(K, rms)
    return res


def centre_table(board, dist, poses, found):
    """Mean centre errors (px) of OpenCV's, ours, and ours corrected with the true lens and poses."""
    e = {"OpenCV": [], "ours": [], "ours corrected (true lens)": []}
    for (rvec, tvec), f in zip(poses, found):
        if f is None:
            continue
        truth, cvc, ours = f
        off = centre_offsets(board.object_points(), board.radius, rvec, tvec, "plumb_bob", K_TRUE, dist)
        for name, c in zip(e, (cvc, ours, ours - off)):
            e[name].append(np.linalg.norm(c - truth, axis=1))
    return {k: float(np.mean(np.concatenate(v))) for k, v in e.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--board", default="circles:4x11,spacing=20mm,asymmetric")
    ap.add_argument("--views", type=int, default=12)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--blur", type=float, default=0.0, help="Gaussian blur σ, px (default 0)")
    ap.add_argument("--gradient", type=float, default=0.0,
                    help="light falling by this fraction from the left edge to the right (default 0)")
    args = ap.parse_args(argv)
    board = parse_board(args.board)
    rng = np.random.default_rng(args.seed)
    poses = [random_pose(board, rng) for _ in range(args.views)]
    for lens, dist in LENSES.items():
        t0 = time.perf_counter()
        found = measure(board, dist, poses, rng, args.blur, args.gradient)
        print(f"{lens}: {sum(f is not None for f in found)}/{len(found)} views found "
              f"({time.perf_counter() - t0:.1f} s to render and detect)")
        for k, v in centre_table(board, dist, poses, found).items():
            print(f"  centre error, {k}: {v:.4f} px")
        for k, v in compare(board, dist, poses, found).items():
            print(f"  calibration, {k}: fx {v['fx_%']:+.4f}%  principal point {v['pp_px']:.3f} px  rms {v['rms_px']:.4f} px")
    return 0


if __name__ == "__main__":
    sys.exit(main())
