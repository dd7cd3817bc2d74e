"""The noise floor of a fisheye calibration: the true lens model forced, fresh noise on the same poses.

For each sequence of ``benchmarks/fisheye_models.py`` (the same camera and board poses for a seed),
the corners get ``--draws`` fresh draws of Gaussian noise (σ ``--noise`` px per axis) and the
camera is calibrated with its *true* model forced (no model choice). The rotation-fitted
projection error over the covered area (the metric of ``fisheye_models.py``) then shows what the
poses and the noise alone allow: a sequence whose oracle fits miss a target often cannot be
expected to meet it, whatever ``auto`` does.

    python benchmarks/fisheye_floor.py [--class kb150] [--seeds 9000-9019] [--draws 8] [--views 20,40]
        [--noise 0.015] [--target 0.02]

Prints per seed and view count: the mean and median error over the draws and the share above
``--target``; then the mean share over the seeds (the expected share of sequences missing it).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aicalib_tf.calib.fit import View, calibrate_camera  # noqa: E402
from benchmarks import fisheye_models as FM  # noqa: E402
from benchmarks.fisheye_calibration import _rotation_compensated  # noqa: E402


def oracle_errors(cls: str, seed: int, views: int, noise: float, draws: int) -> np.ndarray:
    """(draws,) rotation-fitted errors, px, of the true model fitted to the seed's poses with fresh noise."""
    out = []
    for d in range(draws):
        cam, vs, _ = FM.sequence(cls, seed, views, 0.0)
        rng = np.random.default_rng([seed, 77, d])
        vs = [(n, c + noise * rng.standard_normal(c.shape), i) for n, c, i in vs]
        cal = calibrate_camera([View(*v) for v in vs], FM.PATTERN, 1.0, cam.image_size, model=cam.model,
                               **FM._circle_kw(FM.image_circle(cam)))
        truth = {"distortion_model": cam.model, "K": cam.K, "dist": cam.dist}
        out.append(_rotation_compensated(truth, {"model": cal.model, "K": cal.K, "dist": cal.dist}, vs, cam.image_size))
    return np.array(out)


def _seeds(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--class", dest="cls", default="kb150", choices=[c for c in FM.CLASSES if FM.CLASSES[c][2]])
    ap.add_argument("--seeds", default="9000-9019", help="a seed or a range, e.g. 9000-9019")
    ap.add_argument("--draws", type=int, default=8)
    ap.add_argument("--views", default="20", help="comma list of view counts")
    ap.add_argument("--noise", type=float, default=0.015, help="px per axis")
    ap.add_argument("--target", type=float, default=0.02, help="px")
    a = ap.parse_args(argv)
    counts = [int(v) for v in a.views.split(",")]
    share = {v: [] for v in counts}
    for seed in _seeds(a.seeds):
        cells = [f"seed {seed}"]
        for v in counts:
            e = oracle_errors(a.cls, seed, v, a.noise, a.draws)
            share[v].append(float(np.mean(e > a.target)))
            cells.append(f"{v} views: mean {e.mean():.4f} median {np.median(e):.4f} px, above {a.target} {share[v][-1]:.0%}")
        print(" | ".join(cells), flush=True)
    for v in counts:
        print(f"{a.cls}, {v} views, true model forced: {np.mean(share[v]):.0%} of fits above {a.target} px "
              f"(mean over {len(share[v])} seeds of {a.draws} draws)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
