"""calib.bundle: the least-squares fit over all views, its fisheye start, covariance and errors."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from aicalib_tf.calib.bundle import CalibrationError, bundle_adjust, poses_from_rays, solve_pose
from aicalib_tf.calib.starts import fisheye_start
from aicalib_tf.geometry import lens as L
from aicalib_tf.geometry.pattern import board_points
from tests.calib.synthetic import SQUARE, synthetic_views

FISHEYE_SIZE = (1280, 960)
# 185° across the diagonal circle of radius 470 px: θ_d(92.5°) = 1.641 rad -> f ≈ 290 px
FISHEYE = L.Lens("equidistant", [[288.0, 0, 641.5], [0, 287.4, 478.2], [0, 0, 1]], [0.02, -0.01, 0.004, -0.001],
                 FISHEYE_SIZE)
PINHOLE = L.Lens("plumb_bob", [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]], [-0.25, 0.08, 0.001, -0.0005, 0.0],
                 (640, 480))


def _problem(views):
    return [board_points(v.ids, SQUARE) for v in views], [v.corners for v in views]


def test_fisheye_start_and_fit_recover_a_185_degree_lens_without_a_guess():
    views = synthetic_views(FISHEYE, 16, 0.0, seed=3, distance=(0.15, 0.4))
    obj, px = _problem(views)
    rays = np.concatenate([FISHEYE.unproject(p) for p in px])
    assert np.degrees(np.arccos(rays[:, 2].min())) > 80  # the views reach far off-axis
    free = np.ones(8, bool)
    intr0, poses = fisheye_start(obj, px, FISHEYE_SIZE, free)
    fit = bundle_adjust("equidistant", obj, px, intr0, *poses)
    np.testing.assert_allclose(fit.intrinsics[:4], FISHEYE.intrinsics()[:4], atol=1e-4)
    np.testing.assert_allclose(fit.intrinsics[4:], FISHEYE.dist, atol=1e-6)
    assert fit.rms < 1e-6 and fit.note == ""


@pytest.mark.parametrize("model, dist", [("ds", [-0.2, 0.6]), ("eucm", [0.62, 1.15])])
def test_ds_and_eucm_fits_recover_the_lens_without_a_guess(model, dist):
    true = L.Lens(model, [[250.0, 0, 641.5], [0, 249.6, 478.2], [0, 0, 1]], dist, FISHEYE_SIZE)
    views = synthetic_views(true, 12, 0.01, seed=5, distance=(0.15, 0.4))
    obj, px = _problem(views)
    intr0, poses = fisheye_start(obj, px, FISHEYE_SIZE, np.ones(6, bool), model)
    fit = bundle_adjust(model, obj, px, intr0, *poses)
    sd = np.sqrt(np.diag(fit.covariance))
    assert np.all(np.abs(fit.intrinsics - true.intrinsics()) < 4 * sd), (fit.intrinsics, sd)
    assert abs(fit.rms - 0.01 * np.sqrt(2)) < 0.003


def test_plumb_bob_fit_reaches_opencvs_minimum_and_its_standard_deviations():
    views = synthetic_views(PINHOLE, 12, 0.3, seed=5)
    obj, px = _problem(views)
    o32 = [o.astype(np.float32) for o in obj]
    p32 = [p.astype(np.float32).reshape(-1, 1, 2) for p in px]
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
    rms, K, d, rv, tv, std, _, _ = cv2.calibrateCameraExtended(o32, p32, (640, 480), None, None, criteria=crit)
    start = np.concatenate([[K[0, 0], K[1, 1], K[0, 2], K[1, 2]], d.ravel()[:5]])
    poses = poses_from_rays(L.Lens("plumb_bob", K, d.ravel()[:5], (640, 480)), obj, px)
    fit = bundle_adjust("plumb_bob", obj, px, start * [1.01, 0.99, 1, 1, 1, 1, 1, 1, 1], *poses)
    assert abs(fit.rms - rms) < 1e-5
    np.testing.assert_allclose(fit.intrinsics[:4], start[:4], atol=2e-3)
    np.testing.assert_allclose(np.sqrt(np.diag(fit.covariance))[:9], std.ravel()[:9], rtol=0.05)
    assert fit.converged and fit.nfev < 200
    short = bundle_adjust("plumb_bob", obj, px, start * [1.01, 0.99, 1, 1, 1, 1, 1, 1, 1], *poses, max_nfev=2)
    assert not short.converged and short.nfev == 2 and short.rms > fit.rms


def test_solve_pose_with_fixed_intrinsics_finds_the_view():
    views = synthetic_views(FISHEYE, 3, 0.0, seed=8, distance=(0.15, 0.4))
    pose = solve_pose(FISHEYE, board_points(views[1].ids, SQUARE), views[1].corners)
    assert pose is not None and pose[2] < 1e-6


def test_too_few_corners_and_rank_deficient_fits_name_the_model():
    start = np.concatenate([PINHOLE.intrinsics(), np.zeros(7)])  # thin_prism: 16 intrinsics
    views = synthetic_views(PINHOLE, 2, 0.2, seed=1)
    obj, px = [o[:6] for o in _problem(views)[0]], [p[:6] for p in _problem(views)[1]]
    with pytest.raises(CalibrationError, match="^thin_prism: 12 corners give 24 residuals for 28 parameters"):
        bundle_adjust("thin_prism", obj, px, start, *poses_from_rays(PINHOLE, obj, px))
    # three views all but fronto-parallel at one distance cannot separate 16 intrinsics
    flat = synthetic_views(PINHOLE, 3, 0.0, seed=1, distance=(0.55, 0.6))
    o, p = _problem(flat)
    with pytest.raises(CalibrationError, match="^thin_prism: "):
        bundle_adjust("thin_prism", o, p, start, *poses_from_rays(PINHOLE, o, p))


def test_a_diverging_fit_is_an_error_not_a_result():
    views = synthetic_views(FISHEYE, 16, 0.0, seed=3, distance=(0.15, 0.4))[:6]
    obj, px = _problem(views)
    K = PINHOLE.K.copy()
    start = np.array([K[0, 0], K[1, 1], 641.5, 478.2, 0, 0, 0, 0, 0])
    poses = poses_from_rays(FISHEYE, obj, px)
    try:
        fit = bundle_adjust("plumb_bob", obj, px, start, *poses, covariance=False)
    except CalibrationError as exc:
        assert str(exc).startswith("plumb_bob: ")
    else:  # a pinhole model cannot see past 90°: if it ends at all, it ends far off
        assert fit.rms > 1.0


def test_poses_from_rays_places_a_board_seen_past_90_degrees():
    ids = np.stack(np.meshgrid(np.arange(9), np.arange(6)), -1).reshape(-1, 2)
    X = board_points(ids, SQUARE) - [4 * SQUARE, 2.5 * SQUARE, 0]
    a = np.radians(91.0)  # the board's centre 91° off-axis, facing the camera
    R = cv2.Rodrigues(np.array([0.0, a, 0.0]))[0]
    t = 0.35 * np.array([np.sin(a), 0.0, np.cos(a)])
    uv = FISHEYE.project(X @ R.T + t)
    seen = np.isfinite(uv).all(axis=1)
    assert seen.sum() >= 20 and (FISHEYE.unproject(uv[seen])[:, 2] < 0.05).mean() >= 0.5
    rv, tv = poses_from_rays(FISHEYE, [X[seen]], [uv[seen]])
    np.testing.assert_allclose(cv2.Rodrigues(rv[0])[0], R, atol=1e-6)
    np.testing.assert_allclose(tv[0], t, atol=1e-7)


def test_a_fit_that_ends_on_the_edge_of_the_models_range_is_refused_with_the_coefficient():
    # an EUCM lens at α = 1: on these views the fit runs into α = 1 with the wrong β (RMS 2.8 px)
    true = L.Lens("eucm", [[250.0, 0, 641.5], [0, 249.6, 478.2], [0, 0, 1]], [1.0, 0.8], FISHEYE_SIZE)
    views = synthetic_views(true, 12, 0.05, seed=0, distance=(0.15, 0.4))
    obj, px = _problem(views)
    intr0, poses = fisheye_start(obj, px, FISHEYE_SIZE, np.ones(6, bool), "eucm")
    with pytest.raises(CalibrationError, match=r"^eucm: the fit stopped at the edge of the model's valid range \(alpha = 1\)"):
        bundle_adjust("eucm", obj, px, intr0, *poses)
    loose = bundle_adjust("eucm", obj, px, intr0, *poses, strict=False)  # what was refused
    assert loose.intrinsics[4] == pytest.approx(1.0, abs=1e-6) and loose.rms > 1.0
    views = synthetic_views(true, 12, 0.05, seed=1, distance=(0.15, 0.4))  # here the fit finds the lens inside
    obj, px = _problem(views)
    fit = bundle_adjust("eucm", obj, px, *_start(obj, px, "eucm"))
    assert fit.rms < 0.1 and 0.99 < fit.intrinsics[4] < 1.0


def _start(obj, px, model):
    intr0, poses = fisheye_start(obj, px, FISHEYE_SIZE, np.ones(6, bool), model)
    return (intr0, *poses)


def test_a_start_outside_the_models_range_is_refused_with_the_reason():
    views = synthetic_views(L.Lens("ds", [[250.0, 0, 641.5], [0, 249.6, 478.2], [0, 0, 1]], [-0.2, 0.6], FISHEYE_SIZE),
                            6, 0.0, seed=2, distance=(0.15, 0.4))
    obj, px = _problem(views)
    intr0, poses = fisheye_start(obj, px, FISHEYE_SIZE, np.ones(6, bool), "ds")
    intr0[4] = 1.5
    with pytest.raises(CalibrationError, match=r"^ds: the start is outside the model's valid range .*xi must be in \(-1, 1\]"):
        bundle_adjust("ds", obj, px, intr0, *poses)


def test_flex_jacobian_matches_finite_differences_and_unit_weights_change_nothing():
    from aicalib_tf.calib.bundle import _Problem
    from aicalib_tf.geometry.board_flex import flex_basis

    views = synthetic_views(PINHOLE, 4, 0.1, seed=2)
    obj, px = _problem(views)
    basis = [flex_basis(v.ids[:, 0], v.ids[:, 1], (9, 6)) for v in views]
    poses = poses_from_rays(PINHOLE, obj, px)
    prob = _Problem("plumb_bob", obj, px, PINHOLE.intrinsics(), np.ones(9, bool), None, basis, [0.003, -0.002])
    x = np.concatenate([PINHOLE.intrinsics(), [0.003, -0.002], np.hstack(poses).ravel()])
    r, Jg, _, _ = prob._evaluate(x)
    for k in (9, 10):  # the two flex columns
        dx = np.zeros_like(x)
        dx[k] = 1e-7
        num = (prob.fun(x + dx) - prob.fun(x - dx)) / 2e-7
        np.testing.assert_allclose(Jg[:, :, k].ravel(), num, rtol=1e-5, atol=1e-6)
    plain = bundle_adjust("plumb_bob", obj, px, PINHOLE.intrinsics(), *poses)
    ones = bundle_adjust("plumb_bob", obj, px, PINHOLE.intrinsics(), *poses, sigmas=[np.full(len(p), 0.3) for p in px])
    np.testing.assert_array_equal(ones.intrinsics, plain.intrinsics)
    np.testing.assert_array_equal(ones.covariance, plain.covariance)
