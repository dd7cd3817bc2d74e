"""Which σ each corner enters a calibration fit with (aicalib_tf.calib.weights), and the weights from them."""

import numpy as np
import pytest

from aicalib_tf.calib import weights
from aicalib_tf.calib.weights import CLIP, corner_weights, fit_sigmas


def test_the_view_rule_gives_each_corner_its_views_median_and_views_without_sigma_the_others_median():
    given = [np.array([0.1, 0.2, 0.9]), None, np.array([0.4, 0.4])]
    got = fit_sigmas(given, [3, 4, 2], "view")
    np.testing.assert_array_equal(got[0], [0.2, 0.2, 0.2])
    np.testing.assert_allclose(got[1], np.full(4, 0.3))  # the median of the medians 0.2 and 0.4
    np.testing.assert_array_equal(got[2], [0.4, 0.4])
    assert fit_sigmas([None, None], [3, 4]) is None


def test_the_clipped_rule_holds_each_corner_within_its_views_median_and_the_corner_rule_keeps_it():
    given = [np.array([0.01, 0.2, 0.21, 0.22, 5.0])]
    clipped = fit_sigmas(given, [5], "clipped")[0]
    np.testing.assert_allclose(clipped, [CLIP[0] * 0.21, 0.2, 0.21, 0.22, CLIP[1] * 0.21])
    np.testing.assert_array_equal(fit_sigmas(given, [5], "corner")[0], given[0])


def test_the_shipped_rule_is_the_default(monkeypatch):
    given = [np.array([0.1, 0.3, 0.5])]
    assert weights.WEIGHTING == "components"
    np.testing.assert_array_equal(fit_sigmas(given, [3])[0], given[0])
    for rule in ("view", "view-components"):
        monkeypatch.setattr(weights, "WEIGHTING", rule)
        np.testing.assert_array_equal(fit_sigmas(given, [3])[0], np.full(3, 0.3))


@pytest.mark.parametrize("given, counts, why", [([np.array([0.1, 0.2])], [3], "3 finite values"),
                                                ([np.array([0.1, -1.0])], [2], "> 0 px"),
                                                ([np.array([0.1, np.nan])], [2], "finite")])
def test_bad_sigmas_are_refused(given, counts, why):
    with pytest.raises(ValueError, match=why):
        fit_sigmas(given, counts)
    with pytest.raises(ValueError, match="weighting must be one of"):
        fit_sigmas([np.ones(2)], [2], "each")


def test_weights_are_the_median_sigma_over_each_and_zero_for_rejected_corners():
    w = corner_weights([np.array([0.1, 0.2]), np.array([0.4])], np.array([True, True, False]), 3)
    np.testing.assert_allclose(w, [2.0, 1.0, 0.0])
    assert corner_weights(None, None, 3) is None


def _draws(a, tau, n=4000, seed=0, gross=0):
    """Per view (100,) σ log-uniform in 0.01-0.3 px and (100, 2) residuals of variance a·σ² + τ² per axis."""
    rng = np.random.default_rng(seed)
    sig = np.exp(rng.uniform(np.log(0.01), np.log(0.3), n))
    res = rng.standard_normal((n, 2)) * np.sqrt(a * sig ** 2 + tau ** 2)[:, None]
    res[rng.choice(n, gross, replace=False)] *= 50.0  # gross errors
    return np.split(sig, n // 100), np.split(res, n // 100)


@pytest.mark.parametrize("a, tau, gross, want_a", [(0.5, 0.05, 0, 0.5), (1.0, 0.1, 0, 1.0), (0.5, 0.05, 40, 0.5),
                                                   (3.0, 0.05, 0, 1.0)])
def test_variance_components_recover_the_unexplained_share_of_known_residuals(a, tau, gross, want_a):
    sig, res = _draws(a, tau, gross=gross)
    got_a, got_t2 = weights.variance_components(sig, res)
    assert got_a == pytest.approx(want_a, rel=0.12)
    if want_a == a:
        assert np.sqrt(got_t2) == pytest.approx(tau, rel=0.1)
    else:  # a > 1 is held at 1 (the detector's σ is not scaled up): τ takes the rest
        assert np.sqrt(got_t2) > tau
    one_a, one_t2 = weights.variance_components(sig, res, scale=False)
    assert one_a == 1.0 and (np.sqrt(one_t2) == pytest.approx(tau, rel=0.1) if a == 1.0 else one_t2 > 0)


def test_variance_components_correct_for_the_parameters_the_fit_absorbed():
    sig, res = _draws(1.0, 0.1)
    shrunk = [r * np.sqrt(0.5) for r in res]  # as if the fit had taken half the degrees of freedom
    _, t2 = weights.variance_components(sig, shrunk, n_params=4000, scale=False)
    assert np.sqrt(t2) == pytest.approx(0.1, rel=0.1)
    assert weights.variance_components([np.full(3, 0.1)], [np.full((3, 2), np.nan)]) == (1.0, 0.0)
    exact = weights.total_sigmas([np.array([0.1, 0.2, 0.4])], [np.zeros((3, 2))], 0, "components")[0]
    assert np.all(exact > 0) and np.ptp(exact) < 1e-3 * exact[0]  # residuals of 0: nothing to tell the corners apart


def _fit_with(noise, said, seed=4):
    """A plumb_bob fit of 12 synthetic views whose corners have per-axis noise ``noise(k)`` px while the
    detector says ``said(k)`` px, weighted by what it says; (fit, the σ it said per view)."""
    from aicalib_tf.calib.bundle import bundle_adjust, solve_pose
    from aicalib_tf.geometry import lens as L
    from aicalib_tf.geometry.pattern import board_points
    from tests.calib.synthetic import SQUARE, synthetic_views

    lens = L.Lens("plumb_bob", [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]], [-0.25, 0.08, 0.001, -0.0005, 0.0],
                  (640, 480))
    views = synthetic_views(lens, 12, noise_of=noise, seed=seed)
    obj = [board_points(v.ids, SQUARE) for v in views]
    poses = [solve_pose(lens, o, v.corners) for o, v in zip(obj, views)]
    sig = [np.full(len(v.ids), said(k)) for k, v in enumerate(views)]
    fit = bundle_adjust("plumb_bob", obj, [v.corners for v in views], lens.intrinsics(), np.array([p[0] for p in poses]),
                        np.array([p[1] for p in poses]), sigmas=sig)
    return fit, sig


def _ratio(total):
    """The noisy views' (odd) σ_total over the clean ones' (even)."""
    return float(np.median(np.concatenate(total[1::2])) / np.median(np.concatenate(total[0::2])))


def test_components_weigh_views_by_their_true_noise_when_the_detector_misses_a_shared_error(monkeypatch):
    from aicalib_tf.calib.robust import with_floor

    # clean views: σ 0.01 px said, 0.1 px true (an error the detector does not see); noisy ones 0.5 said, 0.3 true
    fit, sig = _fit_with(lambda k: 0.3 if k % 2 else 0.1, lambda k: 0.5 if k % 2 else 0.01)
    for rule in ("components", "view-components"):
        monkeypatch.setattr(weights, "WEIGHTING", rule)
        assert 2.2 < _ratio(with_floor(sig, fit)) < 3.8  # true 3
    monkeypatch.setattr(weights, "WEIGHTING", "view")
    assert _ratio(with_floor(sig, fit)) > 20  # the residuals' variance minus the mean σ²: no floor at all


def test_components_follow_the_detector_where_its_noise_dominates(monkeypatch):
    from aicalib_tf.calib.robust import with_floor

    fit, sig = _fit_with(lambda k: 0.4 if k % 2 else 0.02, lambda k: 0.4 if k % 2 else 0.02)
    monkeypatch.setattr(weights, "WEIGHTING", "components")
    assert 15 < _ratio(with_floor(sig, fit)) <= 20.5  # the noisy views weighed down as the detector says
