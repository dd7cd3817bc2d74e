"""calib.circle_fov: the image circle's field of view past the boards' reach through the fewest terms."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from aicalib_tf.calib.circle_fov import extrapolated_fov, fewest_terms
from aicalib_tf.calib.fit import View, calibrate_camera
from aicalib_tf.geometry import lens as L
from aicalib_tf.geometry.image_circle import ImageCircle, circle_fov_deg
from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views

SIZE = (1280, 960)
CIRCLE = ImageCircle(640.0, 480.0, 470.0)
F = 470.0 / math.radians(92.5)  # an equidistant 185° lens: its rim at 92.5° off-axis
TRUTH = L.Lens("equidistant", [[F, 0, 640.0], [0, F, 480.0], [0, 0, 1]], [0.0, 0.0, 0.0, 0.0], SIZE)


def _row(terms, folds):
    f = np.asarray(folds, np.float64)
    return {"terms": terms, "n_params": 4 + terms, "cv_rms": float(f.mean()), "cv_se": float(f.std(ddof=1) / np.sqrt(len(f))),
            "cv_folds": f.tolist(), "fov_deg": 180.0 + terms}


def test_the_fewest_terms_within_the_noise_of_the_best_are_chosen():
    rows = [_row(2, [0.401, 0.400, 0.402, 0.398, 0.401]), _row(3, [0.400, 0.400, 0.403, 0.398, 0.399]),
            _row(4, [0.400, 0.399, 0.403, 0.397, 0.400])]
    assert fewest_terms(rows)["terms"] == 2
    rows[0] = _row(2, [0.452, 0.449, 0.455, 0.448, 0.451])  # k1..k2 misses every fold by 0.05 px
    assert fewest_terms(rows)["terms"] == 3
    assert fewest_terms([]) is None


def _near_views(reach_deg, n=12, seed=3):
    rng, views = np.random.default_rng(seed), []
    for v in synthetic_views(TRUTH, n=60, noise=0.0, seed=rng, distance=(0.25, 0.5)):
        ok = np.degrees(np.arccos(TRUTH.unproject(v.corners)[:, 2])) <= reach_deg
        if ok.sum() >= 20 and len(views) < n:
            views.append(View(v.name, v.corners[ok] + 0.3 * rng.standard_normal((int(ok.sum()), 2)), v.ids[ok]))
    return views


def test_past_the_boards_reach_the_figure_is_that_of_the_fewest_supported_terms():
    views = _near_views(70.0)
    cal = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="equidistant", image_circle=CIRCLE)
    out = extrapolated_fov(cal, views, cal.lens)
    orders = {r["terms"]: r for r in out["circle_fov_orders"]}
    assert sorted(orders) == [2, 3, 4]
    assert out["circle_fov_deg"] == orders[out["circle_fov_terms"]]["fov_deg"]
    assert out["circle_fov_model_deg"] == pytest.approx(circle_fov_deg(cal.lens, CIRCLE))
    assert out["circle_fov_terms"] < 4 and abs(out["circle_fov_deg"] - 185.0) < 2.0
    assert abs(out["circle_fov_deg"] - 185.0) < abs(out["circle_fov_model_deg"] - 185.0)
    from aicalib_tf.calib.report import fov_line
    quality = {"boards_reach_deg": 70.0, **out}
    line = fov_line(dataclasses.replace(cal, quality=quality))
    assert (f"field of view {out['circle_fov_deg']:.1f}° across the image circle (beyond the boards' reach, 70° off-axis: "
            f"extrapolated through k1..k{out['circle_fov_terms']}, the fewest terms within one standard error held out; "
            f"the model's own {out['circle_fov_model_deg']:.1f}°)") in line
    assert extrapolated_fov(cal, views[:3], cal.lens) is None  # too few views to cross-validate
    assert extrapolated_fov(dataclasses.replace(cal, image_circle=None), views, cal.lens) is None
    inside = ImageCircle(640.0, 480.0, F * math.radians(60.0))  # a rim within the boards' reach
    assert extrapolated_fov(dataclasses.replace(cal, image_circle=inside), views, cal.lens) is None
