"""calib.select: the lens model chosen by cross-validation over views, and the table it prints."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from aicalib_tf.calib.bundle import CalibrationError
from aicalib_tf.calib.fit import _fit_model, calibrate_camera
from aicalib_tf.calib.fit import View
from aicalib_tf.calib.select import COMPLEXITY, choose, cross_validate, select_model, widest_ray_deg
from aicalib_tf.geometry.pattern import board_points
from aicalib_tf.geometry import lens as L
from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views

FISHEYE = L.Lens("equidistant", [[288.0, 0, 641.5], [0, 287.4, 478.2], [0, 0, 1]], [0.02, -0.01, 0.004, -0.001],
                 (1280, 960))
MILD = L.Lens("plumb_bob", [[620.0, 0, 322], [0, 621.0, 238], [0, 0, 1]], [-0.08, 0.01, 4e-4, -3e-4, 0.0], (640, 480))


def _row(model, cv, se):
    return {"model": model, "n_params": 4 + L.N_COEFFS[model], "cv_rms": cv, "cv_se": se}


def test_choose_takes_the_simplest_model_within_one_standard_error():
    rows = [_row("plumb_bob", 0.105, 0.01), _row("rational_polynomial", 0.100, 0.01), _row("equidistant", 0.101, 0.01)]
    assert choose(rows) == "plumb_bob"  # equidistant has fewer parameters, but plumb_bob ranks simpler
    rows[0]["cv_rms"] = 0.2
    assert choose(rows) == "equidistant"
    rows[2]["cv_rms"] = 0.2
    assert choose(rows) == "rational_polynomial"
    assert choose([_row("plumb_bob", float("nan"), float("nan"))]) is None
    assert set(COMPLEXITY) == set(L.MODELS)


def test_choose_prefers_a_model_whose_extras_are_determined():
    rows = [_row("plumb_bob", 0.5, 0.01), _row("ds", 0.100, 0.01), _row("eucm", 0.101, 0.01)]
    assert choose(rows) == "ds"
    rows[1]["determined"] = False  # ξ within 2σ of 0: DS is no more than the unified model
    assert choose(rows) == "eucm"
    rows[2]["determined"] = False
    assert choose(rows) == "ds"  # none determined: the simplest


def test_a_held_out_gain_within_its_own_noise_does_not_count():
    a, b = [0.075, 0.066, 0.078, 0.071, 0.074], [0.068, 0.072, 0.067, 0.074, 0.070]  # plumb_bob, equidistant
    rows = [dict(_row("plumb_bob", np.mean(a), np.std(a, ddof=1) / np.sqrt(5)), cv_folds=a),
            dict(_row("equidistant", np.mean(b), np.std(b, ddof=1) / np.sqrt(5)), cv_folds=b)]
    assert rows[0]["cv_rms"] > rows[1]["cv_rms"] + rows[1]["cv_se"]  # beyond the best's own standard error
    assert choose(rows) == "plumb_bob"  # but within that of the fold-by-fold gain
    del rows[0]["cv_folds"]
    assert choose(rows) == "equidistant"
    erratic = [0.02, 0.5, 0.02, 0.9, 0.02]  # a model that fails some folds is no alternative
    rows = [dict(_row("plumb_bob", np.mean(erratic), np.std(erratic, ddof=1) / np.sqrt(5)), cv_folds=erratic),
            dict(_row("equidistant", 0.0202, 0.0002), cv_folds=[0.0201, 0.0203, 0.02, 0.0204, 0.0202])]
    assert choose(rows) == "equidistant"



def _folds_row(model, folds, rms, determined=True, corners=500):
    f = np.asarray(folds)
    return dict(_row(model, float(f.mean()), float(f.std(ddof=1) / np.sqrt(len(f)))), cv_folds=list(folds),
                determined=determined, rms=rms, corners=corners)


def test_a_gain_that_one_fold_carries_alone_does_not_count():
    # one half of an EUCM 170° sequence: EUCM's edge over equidistant is all in fold 3, the in-sample fits alike
    eq = [0.02076, 0.0222, 0.0239, 0.02068, 0.02278]
    eucm = [0.02069, 0.02223, 0.02101, 0.02061, 0.0228]
    rows = [_folds_row("equidistant", eq, 0.02130), _folds_row("eucm", eucm, 0.02132)]
    assert choose([dict(r, cv_folds=None) for r in rows]) == "eucm"  # the mean alone: beyond the noise
    assert choose(rows) == "equidistant"
    # a KB 150° half: every model misses fold 3's view, equidistant most; it wins the four other folds
    rows = [_folds_row("equidistant", [0.02255, 0.02184, 0.0714, 0.02043, 0.02206], 0.02126),
            _folds_row("ds", [0.02649, 0.02572, 0.04779, 0.02761, 0.02487], 0.02526),
            _folds_row("eucm", [0.02487, 0.0238, 0.03909, 0.02488, 0.02362], 0.02338)]
    assert choose(rows) == "equidistant"
    # an EUCM 170° half: equidistant extrapolates to fold 4's pose 0.011 px worse, and fits the views 0.00001
    # px worse in-sample, less than two parameters buy on noise (0.0204 · 2 / (4 · 500) = 0.00002 px)
    rows = [_folds_row("equidistant", [0.01906, 0.02164, 0.02033, 0.03254, 0.01963], 0.02041),
            _folds_row("eucm", [0.01905, 0.02157, 0.02031, 0.02195, 0.01951], 0.02040)]
    assert choose(rows) == "equidistant"
    # a KB 150° half where every model misses fold 2's pose, equidistant by 0.25 px, EUCM by 0.06
    rows = [_folds_row("equidistant", [0.02074, 0.25225, 0.01965, 0.02227, 0.02115], 0.02080),
            _folds_row("eucm", [0.02294, 0.05873, 0.02043, 0.02286, 0.02137], 0.02193)]
    assert choose(rows) == "equidistant"
    # a Double Sphere 190° half: DS, with fewer parameters, also fits the views better; its edge counts
    rows = [_folds_row("equidistant", [0.0209, 0.02253, 0.02206, 0.0181, 0.02081], 0.02050),
            _folds_row("ds", [0.02055, 0.02053, 0.02185, 0.01812, 0.02018], 0.02005)]
    assert choose(rows) == "ds"
    assert choose([rows[0], dict(rows[1], rms=0.0206)]) == "equidistant"
    # a gain in every fold counts, however it is spread
    rows = [_folds_row("equidistant", [0.0230, 0.0231, 0.0260, 0.0229, 0.0232], 0.0200),
            _folds_row("eucm", [0.0210, 0.0211, 0.0212, 0.0209, 0.0210], 0.0201)]
    assert choose(rows) == "eucm"
    # a model that fits the views worse and fails a fold is no alternative
    rows = [_folds_row("plumb_bob", [0.0201, 0.0203, 0.0200, 0.5, 0.0202], 0.0590),
            _folds_row("equidistant", [0.0202, 0.0203, 0.0201, 0.0204, 0.0202], 0.0200)]
    assert choose(rows) == "equidistant"

def _views_past_90_degrees(lens, n=10, seed=0, noise=0.01):
    """Boards facing the camera with their centres 50–88° off-axis, corners beyond 90° kept."""
    rng = np.random.default_rng(seed)
    ids = np.stack(np.meshgrid(np.arange(9), np.arange(6)), -1).reshape(-1, 2)
    X = board_points(ids, SQUARE) - [4 * SQUARE, 2.5 * SQUARE, 0.0]
    views = []
    while len(views) < n:
        t, phi = np.radians(rng.uniform(50.0, 88.0)), rng.uniform(0, 2 * np.pi)
        c = np.array([np.sin(t) * np.cos(phi), np.sin(t) * np.sin(phi), np.cos(t)])
        z = -c  # the board faces the camera, turned by up to 30°
        x = np.cross([0.3, 0.5, 0.8], z)
        x /= np.linalg.norm(x)
        R = cv2.Rodrigues(rng.uniform(-0.5, 0.5, 3))[0] @ np.stack([x, np.cross(z, x), z], axis=1)
        uv = lens.project(X @ R.T + c * rng.uniform(0.2, 0.35))
        w, h = lens.image_size
        ok = np.isfinite(uv).all(1) & (uv[:, 0] > 0) & (uv[:, 0] < w - 1) & (uv[:, 1] > 0) & (uv[:, 1] < h - 1)
        if ok.sum() >= 20:
            views.append(View(f"v{len(views):02d}", uv[ok] + noise * rng.standard_normal((int(ok.sum()), 2)), ids[ok]))
    return views


def test_auto_picks_a_fisheye_model_for_a_185_degree_lens_and_skips_the_pinholes():
    views = _views_past_90_degrees(FISHEYE, 10)
    fit = lambda vs, m, start: _fit_model(m, vs, SQUARE, FISHEYE.image_size, start)  # noqa: E731
    table, chosen, best = select_model(views, SQUARE, fit)
    assert chosen == "equidistant" and widest_ray_deg(best, views) > 90.0
    rows = {r["model"]: r for r in table}
    assert [r["model"] for r in table] == list(L.MODELS)
    for m in ("plumb_bob", "rational_polynomial", "thin_prism"):
        assert "images less than 90°" in rows[m]["note"] and not np.isfinite(rows[m]["cv_rms"])
    assert all(np.isfinite(rows[m]["cv_rms"]) or rows[m]["note"] for m in ("equidistant", "ds", "eucm"))


def test_auto_picks_equidistant_for_a_185_degree_fisheye():
    views = synthetic_views(FISHEYE, 12, 0.1, seed=3, distance=(0.15, 0.4))
    cal = calibrate_camera(views, PATTERN, SQUARE, FISHEYE.image_size)
    assert cal.model == "equidistant"
    table = {r["model"]: r for r in cal.model_table}
    assert set(table) == set(L.MODELS) and table["equidistant"]["chosen"]
    assert table["equidistant"]["cv_rms"] < 0.2
    assert abs(cal.fx / FISHEYE.fx - 1) < 1e-3


def test_auto_picks_plumb_bob_for_a_mild_lens():
    views = synthetic_views(MILD, 15, 0.1, seed=4)
    cal = calibrate_camera(views, PATTERN, SQUARE, MILD.image_size)
    assert cal.model == "plumb_bob", cal.model_table
    assert all(np.isfinite(r["cv_rms"]) or r["note"] for r in cal.model_table)


def test_a_model_that_cannot_be_fitted_gets_a_note_and_auto_goes_on():
    views = synthetic_views(MILD, 4, 0.1, seed=6, distance=(0.55, 0.6))
    cal = calibrate_camera(views, PATTERN, SQUARE, MILD.image_size, reject_outliers=False)
    table = {r["model"]: r for r in cal.model_table}
    assert table["thin_prism"]["note"].startswith("thin_prism: ") and not table["thin_prism"]["chosen"]
    assert table[cal.model]["chosen"] and np.isfinite(table[cal.model]["cv_rms"])


def test_forced_model_and_bad_model_name():
    views = synthetic_views(MILD, 6, 0.1, seed=7)
    cal = calibrate_camera(views, PATTERN, SQUARE, MILD.image_size, model="rational_polynomial")
    assert cal.model == "rational_polynomial" and cal.dist.size == 8
    assert [r["note"] for r in cal.model_table] == ["forced"]
    with pytest.raises(ValueError, match="unknown lens model 'fisheye'"):
        calibrate_camera(views, PATTERN, SQUARE, MILD.image_size, model="fisheye")


def test_relative_ids_calibrate_as_the_true_ids_do():
    """Each view has its own pose: ids shifted or turned a quarter (handedness kept) change the
    poses only, so a board larger than the frame counts as a view."""
    from aicalib_tf.calib.fit import View

    views = synthetic_views(MILD, 8, 0.1, seed=9)
    rel = []
    for k, v in enumerate(views):
        ids = v.ids - v.ids.min(axis=0)
        if k % 2:  # (c, r) -> (span_r - 1 - r, c): a quarter turn
            ids = np.stack([ids[:, 1].max() - ids[:, 1], ids[:, 0]], axis=1)
        rel.append(View(v.name, v.corners, ids, relative=True))
    a = calibrate_camera(views, PATTERN, SQUARE, MILD.image_size, model="plumb_bob", flex="off")  # relative ids
    b = calibrate_camera(rel, (9, 9), SQUARE, MILD.image_size, model="plumb_bob")  # cannot place a flex: flat
    np.testing.assert_allclose(b.K, a.K, rtol=1e-7)
    np.testing.assert_allclose(b.dist, a.dist, atol=1e-7)


def test_a_fold_that_does_not_converge_fails_the_models_cross_validation():
    views = synthetic_views(MILD, 10, 0.1, seed=4)
    full = _fit_model("plumb_bob", views, SQUARE, MILD.image_size)
    calls = []

    def fit(vs, model, start):  # the real fit; the second fold is reported as having run out of evaluations
        calls.append(len(vs))
        out = _fit_model(model, vs, SQUARE, MILD.image_size, start)
        return dataclasses.replace(out, converged=False) if len(calls) == 2 else out

    cv, se = cross_validate(views, SQUARE, lambda vs, m, s: _fit_model(m, vs, SQUARE, MILD.image_size, s), "plumb_bob", full)
    assert 0.05 < cv < 0.2 and se > 0
    with pytest.raises(CalibrationError, match=r"plumb_bob: fold 2 of 5 did not converge in \d+ evaluations"):
        cross_validate(views, SQUARE, fit, "plumb_bob", full)
    assert calls == [8, 8]  # the folds after it are not fitted


def test_the_image_circles_rim_makes_pinholes_ineligible_when_the_boards_stop_short_of_it():
    from aicalib_tf.geometry.image_circle import ImageCircle

    near = [v for v in synthetic_views(FISHEYE, 60, 0.02, seed=7, distance=(0.2, 0.35))
            if np.all(np.hypot(*(v.corners - FISHEYE.K[:2, 2]).T) < 1.2 * FISHEYE.fx)][:10]  # rays below ~70°
    assert len(near) == 10
    fit = lambda vs, m, start: _fit_model(m, vs, SQUARE, FISHEYE.image_size, start)  # noqa: E731
    models = ("plumb_bob", "equidistant")
    rows = {r["model"]: r for r in select_model(near, SQUARE, fit, models)[0]}
    assert np.isfinite(rows["plumb_bob"]["rms"])  # the boards alone leave the pinhole eligible
    rim = FISHEYE.spec.radius(np.radians(92.5), FISHEYE.dist) * FISHEYE.fx
    circle = ImageCircle(FISHEYE.cx, FISHEYE.cy, rim)
    table, chosen, _ = select_model(near, SQUARE, fit, models, circle=circle)
    rows = {r["model"]: r for r in table}
    assert chosen == "equidistant" and not np.isfinite(rows["plumb_bob"]["rms"])
    assert "the image circle's rim is at rays 92." in rows["plumb_bob"]["note"] and "not eligible" in rows["plumb_bob"]["note"]


def test_a_pinhole_needs_a_clear_held_out_margin_once_the_rays_reach_70_degrees():
    from aicalib_tf.calib.select import PINHOLE_MARGIN_SE, WIDE_REACH_DEG, pinhole_margin_note

    eq, ra = [0.170, 0.174, 0.169, 0.172, 0.170], [0.167, 0.171, 0.166, 0.170, 0.166]  # rational 1.5 SE ahead
    rows = [dict(_row("equidistant", np.mean(eq), np.std(eq, ddof=1) / np.sqrt(5)), cv_folds=eq),
            dict(_row("rational_polynomial", np.mean(ra), np.std(ra, ddof=1) / np.sqrt(5)), cv_folds=ra)]
    assert choose(rows) == choose(rows, 60.0) == "rational_polynomial"  # a narrow reach: the one-SE rule alone
    assert choose(rows, WIDE_REACH_DEG) == "equidistant"
    note = pinhole_margin_note(rows, 78.0)["rational_polynomial"]
    assert "rays reach 78.0° off-axis" in note and "over equidistant" in note and "not chosen" in note
    clear = [x - 0.03 for x in eq]  # 18% and many standard errors ahead: the pinhole wins
    rows[1] = dict(rows[1], cv_rms=float(np.mean(clear)), cv_folds=clear, cv_se=float(np.std(clear, ddof=1) / np.sqrt(5)))
    assert pinhole_margin_note(rows, 78.0) == {} and choose(rows, 78.0) == "rational_polynomial"
    uneven = [x - (0.030 if i % 2 == 0 else -0.005) for i, x in enumerate(eq)]  # 9% ahead, but within 2 SE of its gain
    rows[1] = dict(rows[1], cv_rms=float(np.mean(uneven)), cv_folds=uneven,
                   cv_se=float(np.std(uneven, ddof=1) / np.sqrt(5)))
    gain = np.subtract(eq, uneven)
    assert PINHOLE_MARGIN_SE * gain.std(ddof=1) / np.sqrt(5) > gain.mean() > 0.05 * np.mean(eq)
    assert choose(rows) == "rational_polynomial"
    assert choose(rows, 78.0) == "equidistant"
    assert choose([rows[1]], 78.0) == "rational_polynomial"  # no wide model cross-validated: nothing to hold it to

