"""The field check: an unchanged camera holds, a changed one is flagged, for pinhole and fisheye lenses."""

from __future__ import annotations

import dataclasses
import doctest
import json
import math

import numpy as np
import pytest

from aicalib_tf.calib.check import (
    CalibrationError,
    check_calibration,
    corner_noise,
    format_check,
)
from aicalib_tf.calib.fit import View, calibrate_camera
from aicalib_tf.calib.schema import FieldError
from aicalib_tf.calib.significance import (
    chi2_noncentrality,
    chi2_quantile,
    chi2_sf,
    f_noncentrality,
    f_quantile,
    f_sf,
    ncf_sf,
    ncx2_sf,
    t_quantile,
    t_sf,
)
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
    assert abs(r.noise_px / 0.15 - 1) < 0.1 and abs(r.calibration_noise_px / 0.15 - 1) < 0.1
    assert np.all(np.abs(r.drift) < 3 * r.drift_std)
    assert r.drift_chi2 < r.drift_limit and r.lens_chi2 < r.lens_limit and r.lens_dof == 4 + lens.dist.size
    assert not any("noisier" in n for n in r.notes)


@pytest.mark.parametrize("noise", [0.45, 0.9])
def test_noisier_footage_of_an_unchanged_camera_holds_and_says_what_it_can_detect(calibrated, noise):
    """Footage 3-6x noisier than the calibration's (dim light, blur) is judged at its own noise."""
    lens, cal = calibrated
    r = check_calibration(cal, _new_views(lens, noise=noise))
    assert r.holds, format_check(r)
    assert abs(r.noise_px / noise - 1) < 0.1
    clean = check_calibration(cal, _new_views(lens))
    assert r.detectable_fx > 1.5 * clean.detectable_fx and r.detectable_pp > 1.5 * clean.detectable_pp
    note = next(n for n in r.notes if "noisier" in n)
    assert f"{100 * r.detectable_fx:.2f}%" in note and f"{r.detectable_pp:.1f} px" in note
    assert "detects (95% of the time)" in format_check(r)


def test_a_changed_distortion_is_flagged_by_the_lens_test():
    views = synthetic_views(PINHOLE, 20, 0.15, seed=3)
    cal = calibrate_camera(views, PATTERN, SQUARE, PINHOLE.image_size, model="plumb_bob")
    lens = L.Lens("plumb_bob", PINHOLE.K, PINHOLE.dist + [0.02, 0, 0, 0, 0], PINHOLE.image_size)
    r = check_calibration(cal, _new_views(lens))
    assert not r.holds and r.lens_p < r.alpha and any("lens no longer fits" in f for f in r.failures)
    assert r.lr_f > 10


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
    assert d["noise"]["check_px"] > 0 and d["lens_test"]["dof"] >= 6 and d["detectable"]["power"] == 0.95


def _absurd(cal, case):
    cov = np.array(cal.covariance)
    if case == "covariance 1e300":
        return dataclasses.replace(cal, covariance=np.eye(len(cov)) * 1e300)
    if case == "negative variance":
        return dataclasses.replace(cal, covariance=-np.eye(len(cov)))
    if case == "not positive semi-definite":
        cov[0, 1] = cov[1, 0] = 10 * np.sqrt(cov[0, 0] * cov[1, 1])
        return dataclasses.replace(cal, covariance=cov)
    if case == "not symmetric":
        cov[0, 1] += 1.0
        return dataclasses.replace(cal, covariance=cov)
    if case == "σ 1e200, no covariance":
        return dataclasses.replace(cal, covariance=None, std={**cal.std, "fx": 1e200})
    K = cal.K.copy()
    K[0, 0] = 1e300 if case == "fx 1e300" else 1.0
    return dataclasses.replace(cal, K=K)


@pytest.mark.parametrize("case, field, why", [
    ("covariance 1e300", "covariance", "too large to detect a change"),
    ("negative variance", "covariance", "negative variance"),
    ("not positive semi-definite", "covariance", "not positive semi-definite"),
    ("not symmetric", "covariance", "symmetric"),
    ("σ 1e200, no covariance", "std.fx", "too large to detect a change"),
    ("fx 1e300", "camera_matrix", r"fx 1e\+300 px is not a focal length"),
    ("fx 1", "camera_matrix", "fx 1 px is not a focal length"),
])
def test_an_absurd_calibration_is_refused_with_the_field_named(calibrated, case, field, why):
    lens, cal = calibrated
    with pytest.raises(FieldError, match=why) as info:
        check_calibration(_absurd(cal, case), _new_views(lens, n=3))
    assert info.value.field == field


def test_f_and_noncentral_chi_square():
    assert f_sf(2.5, 9, 300) == pytest.approx(0.0090483759, rel=1e-8)  # scipy.stats.f.sf
    assert f_sf(5.0, 2, 20) == pytest.approx(0.0173415299, rel=1e-8)
    assert f_sf(3.0, 4, math.inf) == pytest.approx(chi2_sf(12.0, 4))
    assert f_quantile(0.99, 4, 1000) == pytest.approx(3.33795, rel=1e-5)
    assert ncx2_sf(13.28, 4, 20) == pytest.approx(0.8855065062, rel=1e-8)  # scipy.stats.ncx2.sf
    assert ncx2_sf(20.0, 9, 5) == pytest.approx(0.1591234853, rel=1e-8)
    assert chi2_noncentrality(4, 0.01, 0.95) == pytest.approx(24.3291, rel=1e-4)


def test_noncentral_f():
    assert ncf_sf(3.0, 4, 20, 10.0) == pytest.approx(0.5723611414, rel=1e-8)  # scipy.stats.ncf.sf
    assert ncf_sf(5.0, 4, 2000, 30.0) == pytest.approx(0.9043908704, rel=1e-8)
    assert ncf_sf(3.0, 4, 20, 0.0) == pytest.approx(f_sf(3.0, 4, 20))
    assert f_noncentrality(4, 20, 0.01, 0.95) == pytest.approx(34.2557, rel=1e-4)  # ncf.sf(f.ppf(.99, 4, 20), ...) = .95
    assert f_noncentrality(4, math.inf, 0.01, 0.95) == chi2_noncentrality(4, 0.01, 0.95)
    assert f_noncentrality(4, 14, 0.01, 0.95) > f_noncentrality(4, 50, 0.01, 0.95) > chi2_noncentrality(4, 0.01, 0.95)


def _shared_in_view(views, rms, seed=5):
    """The views with an error every corner of a view shares: a random quadratic field over the board
    (``rms`` px per axis), which the view's pose does not absorb."""
    rng = np.random.default_rng(seed)
    half = (np.array(PATTERN) - 1) / 2
    out = []
    for v in views:
        u = (v.ids - half) / half
        basis = np.stack([u[:, 0] ** 2 - 1 / 3, u[:, 0] * u[:, 1], u[:, 1] ** 2 - 1 / 3], 1) * 2.0
        out.append(View(v.name, v.corners + rms * basis @ rng.standard_normal((3, 2)) / np.sqrt(2), v.ids))
    return out


def test_errors_shared_within_views_make_the_views_the_units():
    """With errors shared within each view the scatter between views sets the scale (κ > 1) and both
    tests take it with about V − 1 degrees of freedom, not the corners' 2N − 6V − p: wider limits and
    a larger smallest detectable change than the corner count would claim. Independent noise keeps
    (nearly) the corners' degrees of freedom."""
    views = synthetic_views(PINHOLE, 20, 0.15, seed=3, distance=DISTANCE["plumb_bob"])
    cal = calibrate_camera(views, PATTERN, SQUARE, PINHOLE.image_size, model="plumb_bob")
    iid = check_calibration(cal, _new_views(PINHOLE))
    shared = check_calibration(cal, _shared_in_view(_new_views(PINHOLE, noise=0.1), 0.1))
    assert iid.holds and shared.holds, format_check(shared)
    assert iid.inflation < 1.3 and iid.test_dof > 0.4 * iid.noise_dof
    assert shared.inflation > 3 and shared.test_dof < 30 < shared.noise_dof / 10
    assert shared.drift_limit > 1.3 * 4 * f_quantile(0.99, 4, shared.noise_dof)
    assert shared.to_dict()["drift_test"]["scale_dof"] == pytest.approx(shared.test_dof)
    assert f"from 15 views, F with {shared.test_dof:.0f} degrees of freedom" in format_check(shared)
    k = shared.detectable_pp * 1.1  # just beyond what the check claims it detects: flagged
    moved = check_calibration(cal, _shared_in_view(_new_views(_moved(PINHOLE, dcx=k * 0.6, dcy=k * 0.8), noise=0.1),
                                                   0.1))
    assert not moved.holds and moved.drift_p < moved.alpha


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


def test_the_views_sigmas_weigh_the_check_as_they_weigh_a_calibration():
    """Every other view 10x noisier: weighed by each view's σ the check detects a four times smaller
    change than with equal weights; one σ for all changes nothing."""
    views = synthetic_views(PINHOLE, 20, 0.15, seed=3, distance=DISTANCE["plumb_bob"])
    cal = calibrate_camera(views, PATTERN, SQUARE, PINHOLE.image_size, model="plumb_bob")
    noise = lambda k: 1.5 if k % 2 else 0.15  # noqa: E731
    new = synthetic_views(PINHOLE, 16, seed=11, distance=DISTANCE["plumb_bob"], noise_of=noise)
    weighed = check_calibration(cal, [View(v.name, v.corners, v.ids, sigmas=np.full(len(v.ids), noise(k)))
                                      for k, v in enumerate(new)])
    equal = check_calibration(cal, new)
    same = check_calibration(cal, [View(v.name, v.corners, v.ids, sigmas=np.full(len(v.ids), 0.3)) for v in new])
    assert weighed.holds and equal.holds
    assert weighed.detectable_fx < 0.4 * equal.detectable_fx and weighed.detectable_pp < 0.4 * equal.detectable_pp
    np.testing.assert_allclose(same.measured, equal.measured)
    assert same.detectable_fx == pytest.approx(equal.detectable_fx)
