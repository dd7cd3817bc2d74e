"""calib.flex_check: a solved flex is kept when its sag stands above the noise of its own estimate,
that noise measured by leaving each view out (errors that follow a view included)."""

from __future__ import annotations

import numpy as np

from aicalib_tf.calib.fit import View, _fit_model, calibrate_camera
from aicalib_tf.calib.flex_check import sag_evidence
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
    cal = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", flex="auto")
    flat = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", flex="off")
    assert cal.flex is not None and cal.flex_note == ""
    assert abs(float(np.sum(cal.flex)) - 0.005) <= 0.002
    assert abs(cal.fx - 500.0) < abs(flat.fx - 500.0) and abs(cal.fx - 500.0) < 1.5 * cal.std["fx"]


def test_a_flex_that_only_the_fits_own_sigma_believes_is_dropped_and_said_so():
    views = _wobbly_board(12, seed=1)
    fit = _fit_model("plumb_bob", views, 1.0, SIZE, None, options=SolveOptions(PATTERN, "auto"))
    c = fit.flex_covariance
    assert fit.flex is not None and abs(np.sum(fit.flex)) > 5 * np.sqrt(c[0, 0] + c[1, 1] + 2 * c[0, 1])
    cal = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", flex="auto")
    assert cal.flex is None
    assert cal.flex_note.startswith("not used: the sag") and "leaving each of the 12 views out" in cal.flex_note


def test_the_evidence_rule_on_given_numbers():
    assert sag_evidence(0.003, 0.001, None)[0] and not sag_evidence(0.0019, 0.001, None)[0]  # no jackknife: 1.96σ
    loo = 0.006 + 0.001 * np.array([-1.0, 1.0, -1.0, 1.0, -1.0, 1.0])  # σ_J = √(5/6 · 6e-6) = 0.00224
    keep, why = sag_evidence(0.006, 0.0005, loo)
    assert keep and why == ""  # |t| 2.68 > 2.57 (5 degrees of freedom)
    keep, why = sag_evidence(0.005, 0.0005, loo)
    assert not keep and "± 0.0022, from leaving each of the 6 views out; |t| 2.2 < 2.57" in why
    keep, why = sag_evidence(0.004, 0.003, np.full(6, 0.004))  # no spread: the fit's own σ is the floor
    assert not keep and "the fit's own σ" in why
    assert sag_evidence(-0.02, 0.001, np.full(6, -0.02))[0]


def test_a_flat_boards_flex_is_left_off():
    views = synthetic_views(PINHOLE, 12, 0.2, seed=5)
    cal = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", flex="auto")
    assert cal.flex is None and cal.flex_note.startswith("not")


def test_doctests():
    import doctest

    from aicalib_tf.calib import flex_check

    assert doctest.testmod(flex_check).failed == 0
