"""calib.inflation: the views-as-clusters inflation of the covariance, and what quality prints with it."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from aicalib_tf.calib import quality as Q
from aicalib_tf.calib.coverage import covered_mask
from aicalib_tf.calib.fit import View
from aicalib_tf.calib.inflation import _sandwich
from aicalib_tf.geometry import lens as L
from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views

SIZE = (640, 480)
LENS = L.Lens("plumb_bob", [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]], [-0.25, 0.08, 0.001, -0.0005, 0.0], SIZE)


def _shared_error(views, px, seed=0):
    """Each view's corners moved by its own random affine field (~``px`` px): an error shared within the view."""
    rng = np.random.default_rng(seed)
    return [View(v.name, v.corners + (v.corners - v.corners.mean(0)) @ (px * rng.standard_normal((2, 2)) / 100).T
                 + px * rng.standard_normal(2), v.ids) for v in views]


def test_the_inflation_is_one_for_independent_noise_and_large_for_an_error_shared_within_views():
    views = synthetic_views(LENS, 12, 0.3, seed=4)
    fit = Q.default_fit()
    cal = fit(views, PATTERN, SQUARE, SIZE, "plumb_bob")
    cov, kappa = Q.honest_covariance(cal, views)
    assert 1.0 <= kappa < 2.0 and np.allclose(cov, kappa * cal.covariance)
    shared = _shared_error(views, 1.0)
    cal_s = fit(shared, PATTERN, SQUARE, SIZE, "plumb_bob")
    _, kappa_s = Q.honest_covariance(cal_s, shared)
    assert kappa_s > 5.0  # the formal covariance counts each view's 54 corners as independent


def test_the_leverage_corrected_sandwich_is_the_formal_covariance_in_expectation():
    # a linear problem with independent noise: E[S⁻¹ Σ g̃g̃ᵀ S⁻¹] = σ² S⁻¹ (CR2), the uncorrected one is smaller
    rng = np.random.default_rng(0)
    Js = [rng.standard_normal((12, 3)) for _ in range(6)]
    cr2, cr1 = np.zeros((3, 3)), np.zeros((3, 3))
    for _ in range(200):
        e = [rng.standard_normal(12) for _ in Js]
        J, y = np.vstack(Js), np.concatenate(e)
        r = y - J @ np.linalg.lstsq(J, y, rcond=None)[0]
        rs = np.split(r, 6)
        Sinv, robust = _sandwich(Js, rs)
        cr2 += robust / 200
        cr1 += Sinv @ sum(np.outer(j.T @ x, j.T @ x) for j, x in zip(Js, rs)) @ Sinv / 200
    ratio = np.trace(np.linalg.solve(Sinv, cr2)) / 3
    assert ratio == pytest.approx(1.0, abs=0.1)
    assert np.trace(np.linalg.solve(Sinv, cr1)) / 3 < 0.9 * ratio


def test_assess_prints_the_honest_uncertainty_and_keeps_the_formal_covariance():
    views = _shared_error(synthetic_views(LENS, 10, 0.2, seed=2), 0.5, seed=1)
    cal = Q.default_fit()(views, PATTERN, SQUARE, SIZE, "plumb_bob")
    q = Q.assess(cal, views)
    assert q["inflation"] > 2.0
    covered = covered_mask(views, SIZE, (32, 24))
    _, formal = Q.projection_uncertainty(cal, covariance=cal.covariance, fit_mask=covered)
    c = covered & np.isfinite(formal)
    assert q["sigma_px"]["median_covered"] == pytest.approx(np.sqrt(q["inflation"]) * np.median(formal[c]), rel=1e-6)
    std = Q.honest_std(dataclasses.replace(cal, quality=q))
    assert std["fx"] == pytest.approx(np.sqrt(q["inflation"]) * cal.std["fx"])
    assert Q.honest_std(cal)["fx"] == pytest.approx(cal.std["fx"])  # no quality yet: the formal one
