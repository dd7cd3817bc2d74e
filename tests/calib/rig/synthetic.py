"""Synthetic rig views for the tests: known lenses and camera poses see a 9x6 board in random poses."""

from __future__ import annotations

import functools
import json

import numpy as np
from scipy.spatial.transform import Rotation

from aicalib_tf.calib.fit import View
from aicalib_tf.geometry.lens import Lens
from aicalib_tf.geometry.pattern import board_points

PATTERN = (9, 6)
SQUARE = 0.04  # m


def pinhole(f=600.0, size=(800, 600), k1=-0.1) -> Lens:
    w, h = size
    return Lens("plumb_bob", [[f, 0, (w - 1) / 2 + 3], [0, f * 1.001, (h - 1) / 2 - 2], [0, 0, 1]],
                [k1, 0.3 * k1 * k1, 1e-4, -2e-4, 0.0], size)


def fisheye(f=280.0, size=(800, 600)) -> Lens:
    w, h = size
    return Lens("equidistant", [[f, 0, (w - 1) / 2 - 2], [0, f, (h - 1) / 2 + 1], [0, 0, 1]],
                [0.02, -0.005, 0.001, -0.0003], size)


def rig_pose(baseline=0.12, vergence_deg=3.0) -> tuple[np.ndarray, np.ndarray]:
    """(R, T) of camera 1 from camera 0: to the right by ``baseline`` m, turned in by ``vergence_deg``."""
    R = Rotation.from_euler("yxz", [-vergence_deg, 0.4, -0.3], degrees=True).as_matrix()
    c1 = np.array([baseline, 0.002, -0.001])  # camera 1's centre in camera 0's frame
    return R, -R @ c1


def rig_views(lenses, Rs, Ts, n=20, noise=0.0, *, seed=0, distance=(0.45, 0.8), min_corners=12, names=None):
    """Per camera, ``n`` frames' views (name f00, f01, ...) of one board pose each; corners off the image
    are dropped (partial boards); a camera seeing fewer than ``min_corners`` of a frame gets no view."""
    rng = np.random.default_rng(seed)
    cols, rows = PATTERN
    ids = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), -1).reshape(-1, 2)
    X = board_points(ids, SQUARE) - [(cols - 1) * SQUARE / 2, (rows - 1) * SQUARE / 2, 0]
    out = [[] for _ in lenses]
    frame = 0
    while frame < n:
        centre = np.array([rng.uniform(-0.15, 0.25), rng.uniform(-0.12, 0.12), rng.uniform(*distance)])
        R = Rotation.from_euler("xyz", rng.uniform(-35, 35, 3) * [1, 1, 0.5], degrees=True).as_matrix()
        P0 = X @ R.T + centre
        got = []
        for lens, Rk, Tk in zip(lenses, Rs, Ts):
            uv = lens.project(P0 @ np.asarray(Rk).T + Tk)
            w, h = lens.image_size
            ok = np.all(np.isfinite(uv), 1) & (uv[:, 0] > 0) & (uv[:, 0] < w - 1) & (uv[:, 1] > 0) & (uv[:, 1] < h - 1)
            got.append((uv, ok))
        if sum(ok.sum() >= min_corners for _, ok in got) < 2:
            continue
        name = f"f{frame:02d}"
        for k, (uv, ok) in enumerate(got):
            if ok.sum() >= min_corners:
                out[k].append(View(name, uv[ok] + noise * rng.standard_normal((int(ok.sum()), 2)), ids[ok]))
        frame += 1
    return out


@functools.lru_cache(maxsize=1)
def circular_rig(pairs: int = 9):
    """(truth, frames) of data_gen's rendered rig of two circular fisheyes (180–195°) at 640x480, rendered once."""
    from data_gen.rig import make_rig_sequence

    return make_rig_sequence(3, pairs=pairs, lenses=("circular", "circular"), size=(640, 480), baseline=(80.0, 150.0))


def true_circle(cam) -> tuple[float, float, float]:
    """(cx, cy, radius) px of a data_gen circular fisheye camera's image circle."""
    return float(cam.K[0, 2]), float(cam.K[1, 2]), cam.circle_radius() * 0.5 * float(cam.K[0, 0] + cam.K[1, 1])


def check_circular_rig_output(out, truth, text: str) -> None:
    """Asserts that a rig calibration folder ``out`` of :func:`circular_rig` kept each camera's image circle
    (within 1 px of the truth, in rig.json and the camera's camera.json) and used it: the verdict and
    the field of view are the circle's, no corner region outside it is asked for, nothing is NaN."""
    rig = json.loads((out / "rig.json").read_text())
    assert rig["quality"]["status"] == "ok" and "nan" not in text.lower(), text
    for k, name in enumerate(rig["names"]):
        cx, cy, r = true_circle(truth.cameras[k])
        for c in (json.loads((out / name / "camera.json").read_text())["image_circle"], rig["cameras"][k]["image_circle"]):
            assert abs(c["cx"] - cx) < 1.0 and abs(c["cy"] - cy) < 1.0 and abs(c["radius"] - r) < 1.0, (c, (cx, cy, r))
        q = rig["cameras"][k]["quality"]
        assert "of the image circle" in q["verdict"] and np.isfinite(q["sigma_px"]["max_all"]), q
        assert not {"top-left", "top-right", "bottom-left", "bottom-right"} & set(q["uncovered"]), q["uncovered"]
    assert text.count("° across the image circle") == len(rig["names"]), text
