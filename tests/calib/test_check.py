"""The field check: an unchanged camera holds, a changed one is flagged, for pinhole and fisheye lenses."""

from __future__ import annotations

import dataclasses
import doctest
import json

import numpy as np
import pytest

from aicalib_tf.calib.check import (
    CalibrationError,
    check_calibration,
    corner_noise,
    format_check,
)
from aicalib_tf.calib.significance import chi2_quantile, chi2_sf, t_quantile, t_sf
from aicalib_tf.calib.fit import View, calibrate_camera
from aicalib_tf.geometry import lens as L
from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views

PINHOLE = L.Lens("plumb_bob", [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]], [-0.25, 0.08, 0.001, -0.0005, 0.0],
                 (640, 480))
FISHEYE = L.Lens("equidistant", [[288.0, 0, 641.5], [0, 287.4, 478.2], [0, 0, 1]], [0.02, -0.01, 0.004, -0.001],
                 (1280, 960))
DISTANCE = {"plumb_bob": (0.35, 0.6), "equidistant": (0.15, 0.4)}


def _moved(lens, dfx=0.0, dcx=0.0, dcy=0.0):
    K = lens.K + [[dfx, 0, dcx], [0, 0, dcy], [0, 0, 0]]
    return L.Lens(lens.model, K, lens.dist, lens.image_size)


@pytest.fixture(scope="module", params=[PINHOLE, FISHEYE], ids=["pinhole", "fisheye"])
def calibrated(request):
    lens = request.param
    views = synthetic_views(lens, 20, 0.15, seed=3, distance=DISTANCE[lens.model])
    return lens, calibrate_camera(views, PATTERN, SQUARE, lens.image_size, model=lens.model)


def _new_views(lens, seed=11, n=15, noise=0.15):
    return synthetic_views(lens, n, noise, seed=seed, distance=DISTANCE[lens.model])


def test_an_unchanged_camera_holds(calibrated):
    lens, cal = calibrated
    r = check_calibration(cal, _new_views(lens))
    assert r.holds, format_check(r)
    assert len(r.views) == 15 and not r.skipped and r.failures == []
    assert abs(r.rms / r.expected_rms - 1) < 0.1 and r.rms < r.limit_rms
    assert np.all(np.abs(r.drift) < 3 * r.drift_std)
    assert r.drift_chi2 < r.drift_limit


def test_one_percent_of_fx_is_flagged(calibrated):
    lens, cal = calibrated
    r = check_calibration(cal, _new_views(_moved(lens, dfx=0.01 * lens.fx)))
    assert not r.holds
    assert abs(r.drift[0] - 0.01 * lens.fx) < 4 * r.drift_std[0]
    assert any("fx" in f for f in r.failures), r.failures


def test_a_principal_point_moved_3px_is_flagged(calibrated):
    lens, cal = calibrated
    r = check_calibration(cal, _new_views(_moved(lens, dcx=3.0)))
    assert not r.holds and r.drift_p < r.alpha
    assert abs(r.drift[2] - 3.0) < 4 * r.drift_std[2]


def test_all_intrinsics_refitted_still_reports_the_drift():
    views = synthetic_views(PINHOLE, 20, 0.15, seed=3)
    cal = calibrate_camera(views, PATTERN, SQUARE, PINHOLE.image_size, model="plumb_bob")
    same = check_calibration(cal, _new_views(PINHOLE), hold_distortion=False)
    moved = check_calibration(cal, _new_views(_moved(PINHOLE, dfx=5.0)), hold_distortion=False)
    assert same.holds and not moved.holds and not same.hold_distortion
    assert np.all(same.measured_std >= 0) and abs(moved.drift[0] - 5.0) < 4 * moved.drift_std[0]


def test_a_bad_board_is_skipped_as_an_outlier(calibrated):
    lens, cal = calibrated
    views = _new_views(lens)
    bad = views[4]
    noise = np.random.default_rng(0).normal(0.0, 3.0, bad.corners.shape)
    views[4] = View(bad.name, bad.corners + noise, bad.ids)  # a badly refined board, 3 px off
    r = check_calibration(cal, views)
    assert bad.name in r.skipped and r.skipped[bad.name].startswith("outlier")
    assert r.holds and len(r.views) == 14


def test_too_few_views_is_an_error(calibrated):
    lens, cal = calibrated
    with pytest.raises(CalibrationError, match="needs at least 3"):
        check_calibration(cal, _new_views(lens, n=2))
    with pytest.raises(ValueError, match="alpha"):
        check_calibration(cal, _new_views(lens), alpha=0.7)


def test_a_file_without_covariance_is_taken_as_exact_with_a_note(calibrated):
    lens, cal = calibrated
    bare = dataclasses.replace(cal, covariance=None, std={}, corner_counts=np.zeros(len(cal.views), np.int64))
    r = check_calibration(bare, _new_views(lens))
    assert r.notes and "no uncertainty" in r.notes[0]
    assert np.all(r.calibrated_std == 0)
    assert abs(corner_noise(bare)[0] / corner_noise(cal)[0] - 1) < 0.1  # full boards assumed


def test_the_result_is_strict_json(calibrated):
    lens, cal = calibrated
    d = check_calibration(cal, _new_views(lens)).to_dict()
    text = json.dumps(d, allow_nan=False)
    assert json.loads(text)["drift"].keys() == {"fx", "fy", "cx", "cy"}
    assert d["drift_test"]["dof"] == 4 and d["holds"] is True


def test_chi_square_and_t_tails():
    assert chi2_quantile(0.99, 4) == pytest.approx(13.2767, abs=1e-3)  # exact for even degrees of freedom
    assert chi2_sf(13.2767, 4) == pytest.approx(0.01, abs=1e-5)
    assert chi2_quantile(0.99, 1000) == pytest.approx(1106.97, rel=1e-3)  # Wilson–Hilferty
    assert chi2_quantile(0.95, 3) == pytest.approx(7.8147, abs=1e-3)  # odd
    assert t_quantile(0.99, 6) == pytest.approx(3.1427, rel=0.01) and t_sf(3.1427, 6) == pytest.approx(0.01, rel=0.05)
    assert chi2_quantile(0.99, 1000.5) == pytest.approx(1107.5, rel=1e-3)  # Wilson–Hilferty


def test_the_examples_run():
    from aicalib_tf.calib import significance

    assert doctest.testmod(significance).failed == 0
