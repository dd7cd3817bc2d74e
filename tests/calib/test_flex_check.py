"""calib.flex_check: a solved flex's sag is shrunk towards 0 by its standard error (firm shrinkage), that
error measured by leaving each view out (errors that follow a view included), and the board held there."""

from __future__ import annotations

import numpy as np
import pytest

from aicalib_tf.calib.fit import View, _fit_model, calibrate_camera
from aicalib_tf.calib.flex_check import sag_estimate
from aicalib_tf.calib.significance import t_quantile
from aicalib_tf.calib.robust import SolveOptions
from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views
from tests.calib.test_flex import PINHOLE, SIZE


def _wobbly_board(n: int, seed: int, spread: float = 0.01, noise: float = 0.05) -> list[View]:
    """``n`` views of a board that bends differently in every view (w ~ N(0, spread) squares each):
    errors shared by a view's corners, which the fit's own covariance takes for independent ones."""
    rng = np.random.default_rng(seed)
    views = []
    for k in range(n):
        v = synthetic_views(PINHOLE, 1, noise, seed=rng, flex=tuple(rng.normal(0.0, spread, 2)))[0]
        views.append(View(f"v{k:02d}", v.corners, v.ids))
    return views


def test_a_small_flex_in_noisy_corners_is_kept_and_fx_unbiased():
    # sag 0.005 squares at 0.2 px: a flex dropped here leaves fx about 1.65σ off
    views = synthetic_views(PINHOLE, 20, 0.2, seed=np.random.default_rng([0, 47]), flex=(0.003, 0.002))
    cal = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", flex="sag")
    flat = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", flex="off")
    assert cal.flex is not None and cal.flex_note == ""
    assert abs(float(np.sum(cal.flex)) - 0.005) <= 0.002
    assert abs(cal.fx - 500.0) < abs(flat.fx - 500.0) and abs(cal.fx - 500.0) < 1.5 * cal.std["fx"]


def _calibrate_and_spy(views, monkeypatch):
    """(calibrate_camera's flex="sag" Calibration, the (sag, SE) its estimate started from)."""
    from aicalib_tf.calib import flex_check

    seen, inner = {}, flex_check.sag_estimate

    def spy(sag, sigma, loo=None):
        out = inner(sag, sigma, loo)
        seen.update(sag=sag, se=out[1])
        return out

    monkeypatch.setattr(flex_check, "sag_estimate", spy)
    cal = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", flex="sag")
    return cal, seen["sag"], seen["se"]


def test_a_sag_a_95pc_test_would_drop_is_kept_near_its_truth(monkeypatch):
    # sag 0.005 squares, 10 views at 0.3 px: 2.2 standard errors, under the 95% test's 2.26 (9 dof)
    views = synthetic_views(PINHOLE, 10, 0.3, seed=np.random.default_rng([9, 47]), flex=(0.003, 0.002))
    cal, sag, se = _calibrate_and_spy(views, monkeypatch)
    assert abs(sag) < t_quantile(0.975, 9) * se
    assert cal.flex is not None and cal.flex_note == ""
    assert abs(float(np.sum(cal.flex)) - 0.005) <= 0.001 and np.sum(cal.flex) < sag
    c = cal.flex_covariance  # the sag's σ is its leave-one-view-out standard error
    assert np.sqrt(c[0, 0] + c[1, 1] + 2 * c[0, 1]) == pytest.approx(se, rel=1e-6)


def test_a_flat_boards_sag_stays_near_zero(monkeypatch):
    views = synthetic_views(PINHOLE, 10, 0.3, seed=np.random.default_rng([0, 47]))
    cal, sag, _ = _calibrate_and_spy(views, monkeypatch)
    got = 0.0 if cal.flex is None else float(np.sum(cal.flex))
    assert abs(got) <= 0.0005 < abs(sag)


def test_a_flex_that_only_the_fits_own_sigma_believes_is_reported_with_the_views_spread(monkeypatch):
    views = _wobbly_board(12, seed=1)
    fit = _fit_model("plumb_bob", views, 1.0, SIZE, None, options=SolveOptions(PATTERN, "sag"))
    c = fit.flex_covariance
    sigma = np.sqrt(c[0, 0] + c[1, 1] + 2 * c[0, 1])
    assert fit.flex is not None and abs(np.sum(fit.flex)) > 5 * sigma
    cal, sag, se = _calibrate_and_spy(views, monkeypatch)
    assert se > 3 * sigma  # the bends that follow each view: several times the fit's own σ
    got = 0.0 if cal.flex is None else float(np.sum(cal.flex))
    t = abs(sag) / se
    assert got == pytest.approx(0.0 if t <= 0.5 else sag * min(1.0, 4 * (1 - 0.5 / t) / 3.5), abs=1e-12)


def test_the_estimate_on_given_numbers():
    assert sag_estimate(0.003, 0.001, None)[:2] == (pytest.approx(0.003 * 4 * (1 - 0.5 / 3) / 3.5), 0.001)
    assert sag_estimate(-0.0005, 0.001, None)[0] == 0.0  # t 0.5: flat
    assert sag_estimate(-0.0041, 0.001, None)[0] == -0.0041  # t 4.1: as solved
    loo = 0.006 + 0.001 * np.array([-1.0, 1.0, -1.0, 1.0, -1.0, 1.0])  # σ_J = √(5/6 · 6e-6) = 0.00224
    est, se, how = sag_estimate(-0.006, 0.0005, loo)
    assert se == pytest.approx(0.002236, abs=1e-6) and how == "from leaving each of the 6 views out"
    assert est == pytest.approx(-se * 4 * (0.006 / se - 0.5) / 3.5)
    assert sag_estimate(0.004, 0.003, np.full(6, 0.004))[1:] == (0.003, "the fit's own σ")  # no spread: σ_s
    ests = [sag_estimate(s, 0.001, None)[0] for s in np.linspace(0.0, 0.006, 61)]
    assert np.all(np.diff(ests) >= 0) and np.max(np.diff(ests)) < 0.0002  # continuous: no jump at a threshold


def test_a_board_held_at_the_solved_flex_refits_to_the_same_camera():
    views = synthetic_views(PINHOLE, 8, 0.1, seed=3, flex=(0.01, 0.01))
    free = _fit_model("plumb_bob", views, 1.0, SIZE, None, options=SolveOptions(PATTERN, "sag"))
    held = _fit_model("plumb_bob", views, 1.0, SIZE, None,
                      options=SolveOptions(PATTERN, "off", flex_value=tuple(free.flex)))
    assert held.flex is None
    np.testing.assert_allclose(held.intrinsics, free.intrinsics, rtol=1e-5, atol=1e-4)
    with pytest.raises(ValueError, match="flex_value"):
        SolveOptions(PATTERN, "sag", flex_value=(0.01, 0.0))


def test_doctests():
    import doctest

    from aicalib_tf.calib import flex_check

    assert doctest.testmod(flex_check).failed == 0
