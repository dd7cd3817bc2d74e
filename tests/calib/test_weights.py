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
    assert weights.WEIGHTING == "view"
    np.testing.assert_array_equal(fit_sigmas(given, [3])[0], np.full(3, 0.3))
    monkeypatch.setattr(weights, "WEIGHTING", "corner")
    np.testing.assert_array_equal(fit_sigmas(given, [3])[0], given[0])


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
