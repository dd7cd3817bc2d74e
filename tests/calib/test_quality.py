"""calib.quality: uncertainty map, half-vs-half difference, its prediction and the verdict (synthetic views)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from aicalib_tf.calib import quality as Q
from aicalib_tf.geometry import lens as L
from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views

SIZE = (640, 480)
LENS = L.Lens("plumb_bob", [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]], [-0.25, 0.08, 0.001, -0.0005, 0.0], SIZE)
FIT = Q.default_fit()


def _fit(views):
    return FIT(views, PATTERN, SQUARE, SIZE, "plumb_bob")


def test_covariance_matches_opencv_std():
    views = synthetic_views(LENS, 12, 0.3, seed=5)
    cal = _fit(views)
    sd = np.sqrt(np.diag(Q.intrinsics_covariance(cal, views)))
    if getattr(cal, "std", None) and "fx" in cal.std:
        ref = np.array([cal.std[k] for k in ("fx", "fy", "cx", "cy", "k1", "k2")])
        np.testing.assert_allclose(sd[:6], ref, rtol=0.05)
    assert np.all(sd > 0) and np.all(np.isfinite(sd))


def test_uncertainty_positive_and_larger_where_no_board_was():
    views = synthetic_views(LENS, 16, 0.3, seed=2, avoid=(0, 0, 320, 240))
    cal = _fit(views)
    pts, sigma = Q.projection_uncertainty(cal, covariance=Q.intrinsics_covariance(cal, views))
    assert pts.shape == (32 * 24, 2) and sigma.shape == (32 * 24,)
    assert np.all(np.isfinite(sigma)) and np.all(sigma > 0)
    corner = (pts[:, 0] < 160) & (pts[:, 1] < 120)
    covered = (pts[:, 0] > 320) & (pts[:, 1] > 240)
    assert np.median(sigma[corner]) > 1.2 * np.median(sigma[covered])
    d = float(np.median(np.linalg.norm(cal.tvecs, axis=1)))
    _, near = Q.projection_uncertainty(cal, distance=d, covariance=Q.intrinsics_covariance(cal, views))
    assert np.all(np.isfinite(near)) and np.median(near) < np.median(sigma)  # a frame translation absorbs more
    with pytest.raises(ValueError, match="covariance"):
        Q.projection_uncertainty(cal, covariance=np.eye(3))


def test_rotation_compensation_absorbs_a_principal_point_shift():
    pin = L.Lens("plumb_bob", LENS.K, None, SIZE)
    moved = L.Lens("plumb_bob", LENS.K + [[0, 0, 2.0], [0, 0, 0], [0, 0, 0]], None, SIZE)
    pts = Q.grid_points(SIZE, (16, 12))
    d, R = Q.rotation_compensated_diff(pin, moved, pts)
    assert np.nanmedian(d) < 0.4  # a 2 px shift of a pinhole camera is mostly a rotation (exactly, near the centre)
    assert np.degrees(np.arccos((np.trace(R) - 1) / 2)) == pytest.approx(np.degrees(2 / 500), rel=0.2)
    d0, _ = Q.rotation_compensated_diff(pin, pin, pts)
    assert np.nanmax(d0) < 1e-9


def test_half_difference_zero_without_noise_and_grows_with_it():
    clean = synthetic_views(LENS, 12, 0.0, seed=3)
    h0 = Q.half_difference(clean, FIT, PATTERN, SQUARE, SIZE, "plumb_bob", "halves")
    assert h0["median_covered"] < 1e-3 and h0["n_a"] == 6 and h0["n_b"] == 6
    noisy = synthetic_views(LENS, 12, 0.5, seed=3)
    h1 = Q.half_difference(noisy, FIT, PATTERN, SQUARE, SIZE, "plumb_bob", "evenodd")
    assert h1["median_covered"] > 0.02 > h0["median_covered"]
    assert h1["diff"].shape == (32 * 24,) and h1["covered"].any() and not h1["covered"].all()
    with pytest.raises(ValueError, match="split"):
        Q.half_difference(noisy, FIT, PATTERN, SQUARE, SIZE, "plumb_bob", "thirds")


def test_predicted_half_difference_agrees_with_measured():
    """Target: predicted and measured half-vs-half differences within a factor of 2
    (σ 0.3 px, 20 views; means over four view sets so one draw does not decide: single-set ratios
    range 0.5-2.7, as the halves' errors are themselves random)."""
    measured, predicted = [], []
    for seed in (0, 1, 2, 3):
        views = synthetic_views(LENS, 20, 0.3, seed=seed)
        h = Q.half_difference(views, FIT, PATTERN, SQUARE, SIZE, "plumb_bob", "evenodd")
        covs = [Q.intrinsics_covariance(h[f"cal_{k}"], h[f"views_{k}"]) for k in "ab"]
        p = Q.predicted_half_difference(h["cal_a"], h["cal_b"], h["covered"], covariances=covs)
        measured.append(h["median_covered"])
        predicted.append(p["median_covered"])
    ratio = np.mean(measured) / np.mean(predicted)
    print(f"half-diff median over covered area: measured {measured}, predicted {predicted}, ratio {ratio:.2f}")
    assert 0.5 <= ratio <= 2.0


def test_verdict_names_the_uncovered_corner():
    views = synthetic_views(LENS, 16, 0.2, seed=4, avoid=(0, 0, 240, 180))
    cal = _fit(views)
    a = Q.assess(cal, views)
    assert "top-left" in a["uncovered"] and "centre" not in a["uncovered"]
    assert a["verdict"].startswith("good to ") and "no board has covered the top-left" in a["verdict"]
    assert a["sigma_px"]["max_all"] >= a["sigma_px"]["median_covered"] > 0
    assert a["half"] is None


def test_report_prints_model_and_verdict_and_draws_the_map():
    from aicalib_tf.calib.report import field_of_view, format_report, report_figure, uncertainty_map

    views = synthetic_views(LENS, 8, 0.2, seed=6)
    cal = _fit(views)
    text = format_report(cal, views)
    assert "lens model plumb_bob (ROS plumb_bob)" in text and "\nverdict: good to " in text
    assert field_of_view(cal) == pytest.approx((LENS.field_of_view()["horizontal"], LENS.field_of_view()["vertical"]),
                                               abs=1.0)
    pts, sigma = uncertainty_map(cal, views)
    assert sigma.shape == (24, 32) and np.all(sigma > 0)
    assert report_figure(cal, views)[:8] == b"\x89PNG\r\n\x1a\n"


def test_fisheye_uncertainty_is_nan_outside_the_image_circle():
    """An equidistant lens whose radial map peaks at θ = 2.58 rad (r = 140·1.72 px): no ray beyond."""
    fisheye = L.Lens("equidistant", [[140.0, 0, 319.5], [0, 140.0, 239.5], [0, 0, 1]], [-0.05, 0.0, 0.0, 0.0], SIZE)
    cal = SimpleNamespace(model="equidistant", K=fisheye.K, dist=fisheye.dist, image_size=SIZE,
                          covariance=np.diag([0.5, 0.5, 0.3, 0.3, 1e-4, 1e-5, 1e-6, 1e-7]))
    pts, sigma = Q.projection_uncertainty(cal, (32, 24))
    r = np.hypot(pts[:, 0] - 319.5, pts[:, 1] - 239.5)
    rim = 140.0 * 2.582 * (1 - 0.05 * 2.582**2)
    inside, outside = r < rim - 2, r > rim + 2
    assert outside.sum() > 20
    assert np.all(np.isfinite(sigma[inside]) & (sigma[inside] > 0)) and np.all(np.isnan(sigma[outside]))
    views = synthetic_views(fisheye, 6, 0.0, seed=1, distance=(0.15, 0.3))
    share = float(verdict_share(Q.verdict(cal, views, sigma=sigma)))
    assert 0 < share <= 100 * np.mean(np.isfinite(sigma)) + 0.5
    d, _ = Q.rotation_compensated_diff(fisheye, fisheye, pts)
    assert np.all(np.isnan(d[outside])) and np.nanmax(d) < 1e-6


def verdict_share(text: str) -> float:
    """The Y of "good to X px (1σ) over Y% of the image"."""
    return float(text.split(" over ")[1].split("%")[0])



CIRCLE_LENS = L.Lens("equidistant", [[100.0, 0, 319.5], [0, 100.0, 239.5], [0, 0, 1]], [0.0, 0.0, 0.0, 0.0], SIZE)


def _circular_cal(views=None):
    """A 185° equidistant calibration on 640x480 whose image circle (radius 161 px) leaves the corners black."""
    from aicalib_tf.geometry.image_circle import ImageCircle

    return SimpleNamespace(model="equidistant", K=CIRCLE_LENS.K, dist=CIRCLE_LENS.dist, image_size=SIZE,
                           covariance=np.diag([0.5, 0.5, 0.3, 0.3, 1e-4, 1e-5, 1e-6, 1e-7]),
                           image_circle=ImageCircle(319.5, 239.5, 100.0 * np.radians(92.5)), views=(), rvecs=np.zeros((0, 3)))


def test_uncertainty_is_nan_outside_the_image_circle_and_the_verdict_counts_the_circle():
    cal = _circular_cal()
    pts, sigma = Q.projection_uncertainty(cal, (32, 24))
    inside = cal.image_circle.contains(pts)
    assert inside.sum() > 100 and (~inside).sum() > 100
    assert np.all(np.isnan(sigma[~inside])) and np.all(np.isfinite(sigma[inside]))
    views = synthetic_views(CIRCLE_LENS, 8, 0.0, seed=1, distance=(0.15, 0.3))
    text = Q.verdict(cal, views, sigma=sigma)
    assert "of the image circle" in text and verdict_share(text) > 0


def test_verdict_says_when_the_halves_choose_different_model_families():
    views = synthetic_views(LENS, 8, 0.0, seed=1)
    cal = SimpleNamespace(model="plumb_bob", K=LENS.K, dist=LENS.dist, image_size=SIZE, covariance=None)
    half = {"split": "evenodd", "median_covered": 0.1}
    assert "families" not in Q.verdict(cal, views, half=dict(half, models=["plumb_bob", "rational_polynomial"]))
    text = Q.verdict(cal, views, half=dict(half, models=["equidistant", "rational_polynomial"]))
    assert "different lens-model families (equidistant and rational_polynomial)" in text


def test_report_of_a_circular_fisheye_gives_the_circles_field_of_view_and_no_corner_advice():
    import dataclasses

    from aicalib_tf.calib.fit import calibrate_camera
    from aicalib_tf.calib.report import calibration_warnings, fov_line

    circle = _circular_cal().image_circle
    views = [v for v in synthetic_views(CIRCLE_LENS, 40, 0.02, seed=6, distance=(0.15, 0.3))
             if np.all(circle.contains(v.corners))][:12]
    cal = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="equidistant", image_circle=circle)
    assert cal.image_circle == circle
    line = fov_line(cal)
    assert "across the image circle" in line and "nan" not in line
    assert float(line.split("field of view ")[1].split("°")[0]) == pytest.approx(185.0, abs=2.0)
    warnings = calibration_warnings(cal, views)
    assert not any("image corners" in w for w in warnings)
    no_circle = calibration_warnings(dataclasses.replace(cal, image_circle=None), views)
    assert any("image corners" in w for w in no_circle)


def test_fov_line_says_when_the_image_circles_rim_lies_beyond_the_boards_reach():
    from aicalib_tf.calib.report import fov_line

    views = synthetic_views(CIRCLE_LENS, 6, 0.0, seed=1, distance=(0.15, 0.3))
    angles = lambda v: np.degrees(np.arccos(CIRCLE_LENS.unproject(v.corners)[:, 2]))  # noqa: E731
    near = [type(v)(v.name, v.corners[angles(v) <= 70], v.ids[angles(v) <= 70]) for v in views]
    cal = _circular_cal()
    fields = Q.field_of_view_fields(cal, near)
    assert 60 < fields["boards_reach_deg"] <= 70 and fields["circle_fov_deg"] == pytest.approx(185.0, abs=1e-6)
    line = fov_line(cal, near)
    assert f"185.0° across the image circle (beyond the boards' reach, {fields['boards_reach_deg']:.0f}° off-axis: extrapolated)" in line
    cal.quality = {"boards_reach_deg": 95.0}  # the reach camera.json carries is the one used; the rim within it
    assert "185.0° across the image circle (centre" in fov_line(cal, near)


def test_assess_lets_each_half_choose_between_the_chosen_model_and_the_other_familys_best():
    import dataclasses

    views = synthetic_views(LENS, 8, 0.1, seed=3)
    table = ({"model": "plumb_bob", "cv_rms": 0.10, "cv_se": 0.01}, {"model": "rational_polynomial", "cv_rms": 0.09},
             {"model": "equidistant", "cv_rms": 0.11, "cv_se": 0.01}, {"model": "ds", "cv_rms": float("nan")})
    cal = dataclasses.replace(_fit(views), model_table=table)
    asked = []

    def choose(vs, models):
        asked.append(tuple(models))
        return models[len(asked) - 1]  # the first half keeps plumb_bob, the second takes the rival

    q = Q.assess(cal, views, fit=FIT, choose=choose)
    assert asked == [("plumb_bob", "equidistant")] * 2 and q["half"]["models"] == ["plumb_bob", "equidistant"]
    assert "different lens-model families (plumb_bob and equidistant)" in q["verdict"]
    assert "models" not in Q.assess(cal, views, fit=FIT)["half"]


def test_without_a_pattern_size_the_circles_field_of_view_is_the_models_own_past_the_boards_reach():
    """Boards up to 70° off-axis of a lens whose r(θ) steepens past them (k1 > 0), a calibration without a
    pattern size (no refit can choose the polynomial's order, :mod:`aicalib_tf.calib.circle_fov`): the field
    of view across the circle is the model's own, with the boards' reach beside it."""
    import dataclasses

    from aicalib_tf.geometry.image_circle import circle_fov_deg

    cal = _circular_cal()
    steep = L.Lens("equidistant", CIRCLE_LENS.K, [0.02, 0.002, 0.0, 0.0], SIZE)
    cal.dist = steep.dist
    views = synthetic_views(steep, 6, 0.0, seed=1, distance=(0.15, 0.3))
    angles = lambda v: np.degrees(np.arccos(steep.unproject(v.corners)[:, 2]))  # noqa: E731
    near = [dataclasses.replace(v, corners=v.corners[angles(v) <= 70], ids=v.ids[angles(v) <= 70]) for v in views]
    fields = Q.field_of_view_fields(cal, near)
    own = circle_fov_deg(steep, cal.image_circle)
    assert fields["circle_fov_deg"] == pytest.approx(own, abs=1e-9)
    assert 60 < fields["boards_reach_deg"] <= 70.5 and own / 2 > fields["boards_reach_deg"] + 10  # rim past the boards
    assert "circle_fov_terms" not in fields
