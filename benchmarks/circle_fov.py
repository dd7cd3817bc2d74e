"""The field of view across a circular fisheye's image circle when the rim lies beyond the boards'
reach: the fitted model's own extrapolation against the first-order continuation past the reach
(:func:`continued_fov_deg`), on corner-level synthetic truth.
The report prints the model's own figure: the continuation wins only where the true r(theta) is linear.

    .venv/bin/python benchmarks/circle_fov.py [--families equidistant ds eucm] [--fit equidistant|same]
        [--seeds 4] [--noise 0.3]

Per true lens family (equidistant k = 0; equidistant_k with data_gen's rig lens k1..k4; ds xi -0.2, alpha 0.6; eucm alpha 0.6, beta 1.1), field of
view 180, 190, 200° on 1280x960 px with its image circle (radius 470 px, centred), boards (9x6,
:func:`tests.calib.synthetic.synthetic_views`) whose corners are kept only up to 70, 80 or 88°
off-axis (true rays), 20 views, corner noise --noise px. One fit (:func:`aicalib_tf.calib.fit.fit_views`,
model --fit; ``same``: the true family); the reach is :func:`boards_reach_deg` through the fit. Prints
each run and, per family and reach, the |error| mean/max (degrees) of the circle's field of view
through the model alone and with the continuation.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aicalib_tf.calib.fit import View, fit_views  # noqa: E402
from aicalib_tf.geometry import lens as L  # noqa: E402
from aicalib_tf.geometry.image_circle import (ImageCircle, boards_reach_deg, circle_fov_deg, rim_angles_deg,  # noqa: E402
                                              rim_points)
from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views  # noqa: E402

SIZE = (1280, 960)
CIRCLE = ImageCircle(640.0, 480.0, 470.0)
# equidistant_k: a Kannala-Brandt lens with the k1..k4 of data_gen's circular rig lens (seed 3), whose r(theta)
# steepens past the boards' reach: the pure equidistant law (k = 0) is exactly the continuation's own.
COEFFS = {"equidistant": [0.0, 0.0, 0.0, 0.0], "equidistant_k": [0.0129, 0.0018, 0.0019, 0.0006],
          "ds": [-0.2, 0.6], "eucm": [0.6, 1.1]}
FAMILY = {"equidistant_k": "equidistant"}  # the lens model of a COEFFS entry, where its name is not one


EXTEND_STEP_DEG = 2.0  # degrees below the boards' reach over which the continuation takes the model's slope


def slope_extended_deg(lens, circle: ImageCircle, reach_deg: float, n: int = 72) -> np.ndarray:
    """(n,) degrees off-axis of the rim points, r(θ) continued beyond ``reach_deg`` with its slope there.

    r is the rim point's distance from the principal point in normalized units ((x − cx)/fx, (y − cy)/fy);
    along each rim point's azimuth the model gives r(reach) and the slope over the 2° below reach (inside
    the boards' data); a rim point further out is at reach + (r − r(reach)) / slope. NaN where the rim
    point is within reach along its azimuth, or the slope is not positive."""
    K = lens.K
    u = (rim_points(circle, n) - K[:2, 2]) / [K[0, 0], K[1, 1]]
    r, phi = np.hypot(u[:, 0], u[:, 1]), np.arctan2(u[:, 1], u[:, 0])

    def r_at(deg: float) -> np.ndarray:
        t = math.radians(deg)
        rays = np.stack([math.sin(t) * np.cos(phi), math.sin(t) * np.sin(phi), np.full_like(phi, math.cos(t))], 1)
        q = (lens.project(rays) - K[:2, 2]) / [K[0, 0], K[1, 1]]
        return np.hypot(q[:, 0], q[:, 1])

    r0 = r_at(reach_deg)
    slope = (r0 - r_at(reach_deg - EXTEND_STEP_DEG)) / EXTEND_STEP_DEG
    with np.errstate(invalid="ignore", divide="ignore"):
        ok = np.isfinite(r0) & (slope > 0) & (r > r0)
        return np.where(ok, reach_deg + (r - r0) / np.where(ok, slope, 1.0), np.nan)


def continued_fov_deg(lens, circle: ImageCircle, reach_deg: float) -> float:
    """Degrees: :func:`circle_fov_deg` with each rim point beyond ``reach_deg`` (finite, > the step)
    placed by :func:`slope_extended_deg` instead of the model's own extrapolation."""
    theta = rim_angles_deg(lens, circle)
    theta = np.where(np.isfinite(theta), theta, math.degrees(lens.max_angle()))
    if math.isfinite(reach_deg) and reach_deg > EXTEND_STEP_DEG:
        ext = slope_extended_deg(lens, circle, float(reach_deg), len(theta))
        theta = np.where(np.isfinite(ext), ext, theta)
    half = len(theta) // 2
    return float(np.mean(theta[:half] + theta[half:2 * half]))


def true_lens(family: str, fov_deg: float) -> L.Lens:
    """The ``family`` lens whose ray fov/2 off-axis lands on the circle's rim."""
    t = math.radians(fov_deg / 2)
    model = FAMILY.get(family, family)
    unit = L.Lens(model, np.eye(3), COEFFS[family], SIZE)
    f = CIRCLE.radius / unit.project(np.array([[math.sin(t), 0.0, math.cos(t)]]))[0, 0]
    return L.Lens(model, [[f, 0, CIRCLE.cx], [0, f, CIRCLE.cy], [0, 0, 1]], COEFFS[family], SIZE)


def off_axis_deg(lens: L.Lens, uv: np.ndarray) -> np.ndarray:
    """(N,) degrees off-axis of the rays of pixels ``uv``."""
    r = lens.unproject(uv)
    return np.degrees(np.arctan2(np.hypot(r[:, 0], r[:, 1]), r[:, 2]))


def run(family: str, fov: float, reach: float, model: str, seed: int, noise: float) -> tuple[float, float, float]:
    """(model's own error, continued error, reach through the fit) in degrees for one trial."""
    truth, rng = true_lens(family, fov), np.random.default_rng(seed)
    views = []
    for v in synthetic_views(truth, n=60, noise=0.0, seed=rng, distance=(0.25, 0.5)):
        ok = off_axis_deg(truth, v.corners) <= reach
        if ok.sum() >= 20 and len(views) < 20:
            views.append(View(v.name, v.corners[ok] + noise * rng.standard_normal((int(ok.sum()), 2)), v.ids[ok]))
    cal = fit_views(views, PATTERN, SQUARE, SIZE, FAMILY.get(family, family) if model == "same" else model)
    fit = L.Lens(cal.model, cal.K, cal.dist, SIZE)
    got = boards_reach_deg(fit, np.concatenate([v.corners for v in views]))
    true = circle_fov_deg(truth, CIRCLE)
    return circle_fov_deg(fit, CIRCLE) - true, continued_fov_deg(fit, CIRCLE, got) - true, got


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--families", nargs="+", default=["equidistant", "equidistant_k", "ds", "eucm"], choices=sorted(COEFFS))
    ap.add_argument("--fit", default="equidistant", help="the fitted model, or 'same' (the true family)")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--noise", type=float, default=0.3)
    args = ap.parse_args(argv)
    for family in args.families:
        for reach in (70.0, 80.0, 88.0):
            rows = []
            for fov in (180.0, 190.0, 200.0):
                for seed in range(args.seeds):
                    rows.append(run(family, fov, reach, args.fit, seed, args.noise))
                    print(f"{family} fov {fov:.0f} reach {reach:.0f} seed {seed}: model {rows[-1][0]:+.1f} "
                          f"continued {rows[-1][1]:+.1f} (reach through the fit {rows[-1][2]:.1f})", flush=True)
            e = np.abs(np.array(rows)[:, :2])
            print(f"== {family} reach {reach:.0f} (fit {args.fit}, {len(rows)} runs): |error| mean/max model "
                  f"{e[:, 0].mean():.1f}/{e[:, 0].max():.1f}, continued {e[:, 1].mean():.1f}/{e[:, 1].max():.1f} deg")
    return 0


if __name__ == "__main__":
    sys.exit(main())
