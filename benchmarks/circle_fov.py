"""The field of view across a circular fisheye's image circle when the rim lies beyond the boards' reach:
the model's own extrapolation, the figure through the fewest equidistant terms the held-out views support
(:func:`aicalib_tf.calib.circle_fov.extrapolated_fov`, what the report prints) and the first-order
continuation past the reach (:func:`continued_fov_deg`), on corner-level synthetic truth.

    .venv/bin/python benchmarks/circle_fov.py [--families ...] [--fovs 150 165 180 195 210]
        [--reaches 70 78 85] [--seeds 2] [--noise 0.3]

True lenses (``COEFFS``): equidistant with k = 0, with data_gen's circular rig lens k1..k4 (r(θ) steepening
past the reach), with the Taylor terms of the equisolid (2 sin θ/2) and stereographic (2 tan θ/2) laws;
Double Sphere and EUCM, two each. Each at field of view --fovs on 1280x960 px with its image circle
(radius 470 px, centred); 20 views of a 9x6 board (:func:`tests.calib.synthetic.synthetic_views`) whose
corners are kept only up to --reaches degrees off-axis (true rays), corner noise --noise px; runs whose
rim lies within 3° of the reach are skipped (nothing is extrapolated). The model is chosen as ``auto``
chooses among equidistant, ds and eucm (:func:`aicalib_tf.calib.select.select_model`, the circle given).
Prints each run and, per family and over all, the |error| mean / 90th percentile / max (degrees) of:
``model`` (the chosen model's own figure), ``rule`` (the order rule where the chosen model is equidistant,
else the model's own) and ``continued`` (the chosen model continued with its slope at the reach).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aicalib_tf.calib.circle_fov import extrapolated_fov  # noqa: E402
from aicalib_tf.calib.fit import View, _fit_model, _calibration  # noqa: E402
from aicalib_tf.calib.robust import SolveOptions  # noqa: E402
from aicalib_tf.calib.select import select_model  # noqa: E402
from aicalib_tf.geometry import lens as L  # noqa: E402
from aicalib_tf.geometry.image_circle import (ImageCircle, boards_reach_deg, circle_fov_deg, rim_angles_deg,  # noqa: E402
                                              rim_points)
from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views  # noqa: E402

SIZE = (1280, 960)
CIRCLE = ImageCircle(640.0, 480.0, 470.0)
# equidistant_k: a Kannala-Brandt lens with the k1..k4 of data_gen's circular rig lens (seed 3), whose r(theta)
# steepens past the boards' reach: the pure equidistant law (k = 0) is exactly the continuation's own.
# equisolid / stereographic: the first four Taylor terms of 2 sin(θ/2) / θ and 2 tan(θ/2) / θ.
COEFFS = {"equidistant": [0.0, 0.0, 0.0, 0.0], "equidistant_k": [0.0129, 0.0018, 0.0019, 0.0006],
          "equisolid": [-1 / 24, 1 / 1920, -1 / 322560, 1 / 92897280], "stereographic": [1 / 12, 1 / 120, 17 / 20160, 31 / 362880],
          "ds": [-0.2, 0.6], "ds_b": [0.1, 0.55], "eucm": [0.6, 1.1], "eucm_b": [0.5, 1.0]}
FAMILY = {"equidistant_k": "equidistant", "equisolid": "equidistant", "stereographic": "equidistant", "ds_b": "ds",
          "eucm_b": "eucm"}  # the lens model of a COEFFS entry, where its name is not one
CANDIDATES = ("equidistant", "ds", "eucm")  # the models auto chooses among for a circular fisheye


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


def boards(truth: L.Lens, reach: float, seed: int, noise: float) -> list[View]:
    """20 views of the board (corners up to ``reach`` degrees off-axis through ``truth``), noise px."""
    rng, views = np.random.default_rng(seed), []
    for v in synthetic_views(truth, n=80, noise=0.0, seed=rng, distance=(0.25, 0.5)):
        ok = off_axis_deg(truth, v.corners) <= reach
        if ok.sum() >= 20 and len(views) < 20:
            views.append(View(v.name, v.corners[ok] + noise * rng.standard_normal((int(ok.sum()), 2)), v.ids[ok]))
    return views


def run(family: str, fov: float, reach: float, seed: int, noise: float) -> dict:
    """{"model", "terms", "reach", "model_err", "rule_err", "continued_err"} (degrees) for one trial."""
    truth = true_lens(family, fov)
    views = boards(truth, reach, seed, noise)
    opts = SolveOptions(PATTERN, "off", True)
    _, model, fit = select_model(views, 1.0, lambda vs, m, start: _fit_model(m, vs, 1.0, SIZE, start, False, True, opts),
                                 CANDIDATES, circle=CIRCLE, pattern_size=PATTERN)
    cal = _calibration(fit, views, PATTERN, SQUARE, SIZE, {}, "", None, (), CIRCLE)
    lens = L.Lens(cal.model, cal.K, cal.dist, SIZE)
    got = boards_reach_deg(lens, np.concatenate([v.corners for v in views]))
    own, true = circle_fov_deg(lens, CIRCLE), circle_fov_deg(truth, CIRCLE)
    rule = extrapolated_fov(cal, views, lens) or {"circle_fov_deg": own, "circle_fov_terms": None}
    return {"model": model, "terms": rule["circle_fov_terms"], "reach": got, "model_err": own - true,
            "rule_err": rule["circle_fov_deg"] - true, "continued_err": continued_fov_deg(lens, CIRCLE, got) - true}


def _images(family: str, fov: float) -> bool:
    """Whether the ``family`` lens of field of view ``fov`` images its whole rim (a unified model has a limit)."""
    try:
        return abs(circle_fov_deg(true_lens(family, fov), CIRCLE) - fov) < 0.5
    except ValueError:
        return False


def _line(title: str, rows: list[dict]) -> str:
    e = np.abs(np.array([[r["model_err"], r["rule_err"], r["continued_err"]] for r in rows]))
    cell = lambda k: f"{e[:, k].mean():.2f}/{np.percentile(e[:, k], 90):.1f}/{e[:, k].max():.1f}"  # noqa: E731
    return f"== {title} ({len(rows)} runs): |error| mean/p90/max model {cell(0)}, rule {cell(1)}, continued {cell(2)} deg"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--families", nargs="+", default=list(COEFFS), choices=list(COEFFS))
    ap.add_argument("--fovs", nargs="+", type=float, default=[150.0, 165.0, 180.0, 195.0, 210.0])
    ap.add_argument("--reaches", nargs="+", type=float, default=[70.0, 78.0, 85.0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--noise", type=float, default=0.3)
    args = ap.parse_args(argv)
    everything = []
    for family in args.families:
        rows = []
        for fov in args.fovs:
            if not _images(family, fov):
                print(f"{family} fov {fov:.0f}: the model cannot image its rim; skipped")
                continue
            for reach in args.reaches:
                if reach > fov / 2 - 3:
                    continue
                for seed in range(args.seeds):
                    rows.append(r := run(family, fov, reach, 100 + seed, args.noise))
                    print(f"{family} fov {fov:.0f} reach {reach:.0f} seed {seed}: {r['model']} k1..k{r['terms']} "
                          f"model {r['model_err']:+.1f} rule {r['rule_err']:+.1f} continued {r['continued_err']:+.1f} "
                          f"(reach through the fit {r['reach']:.1f})", flush=True)
        if rows:
            print(_line(family, rows), flush=True)
            everything += rows
    if everything:
        print(_line("all", everything))
    return 0


if __name__ == "__main__":
    sys.exit(main())
