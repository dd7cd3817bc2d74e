"""Tests of aicalib_tf.geometry.lens: every model against OpenCV, exact inverses, Jacobians."""

from __future__ import annotations

import dataclasses
import doctest
import importlib
import json
import math
import time

import cv2
import numpy as np
import pytest

from aicalib_tf.geometry import lens

K0 = np.array([[520.0, 0.0, 322.5], [0.0, 515.0, 236.0], [0.0, 0.0, 1.0]])
DISTS = {
    "plumb_bob": [-0.28, 0.08, 8e-4, -5e-4, -0.004],
    "rational_polynomial": [0.45, -0.12, 1e-3, -8e-4, 0.02, 0.75, 0.04, 0.012],
    "thin_prism": [0.45, -0.12, 1e-3, -8e-4, 0.02, 0.75, 0.04, 0.012, 1.5e-3, -3e-4, -8e-4, 2e-4],
    "equidistant": [0.02, -0.005, 0.001, -0.0002],
    "ds": [-0.18, 0.59],
    "eucm": [0.63, 1.08],
    "splined_equidistant": [0.02, -0.005, 0.001, -0.0002] + (0.01 * np.sin(0.7 * np.arange(200))).tolist(),  # 10x10
}
PINHOLE = ("plumb_bob", "rational_polynomial", "thin_prism")


def _rays_at(theta_deg, n=16, rho=2.0):
    """(n, 3) points at off-axis angle theta (degrees) at n azimuths, distance rho."""
    t = np.radians(theta_deg)
    phi = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False) + 0.1
    return rho * np.stack([np.sin(t) * np.cos(phi), np.sin(t) * np.sin(phi), np.full(n, np.cos(t))], axis=1)


def _random_points(rng, model, n=500, max_angle_deg=60.0):
    """Points in front of the camera up to max_angle_deg off-axis and inside the monotonic range."""
    lim = lens.monotonic_limit(model, DISTS[model])
    max_r = math.tan(math.radians(max_angle_deg))
    if not lens.get_model(model).IS_FISHEYE:
        max_r = min(max_r, 0.9 * lim)
    r = max_r * np.sqrt(rng.uniform(0.0, 1.0, n))
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    z = rng.uniform(0.3, 8.0, n)
    return np.stack([r * np.cos(phi) * z, r * np.sin(phi) * z, z], axis=1)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# ----------------------------------------------------------------------------- tables and validation
def test_tables_are_consistent():
    assert lens.MODELS == ("plumb_bob", "rational_polynomial", "thin_prism", "equidistant", "ds", "eucm",
                           "splined_equidistant")
    assert lens.N_COEFFS == {"plumb_bob": 5, "rational_polynomial": 8, "thin_prism": 12, "equidistant": 4, "ds": 2,
                             "eucm": 2, "splined_equidistant": 204}
    for m in lens.MODELS:
        assert len(lens.COEFF_NAMES[m]) == lens.N_COEFFS[m]
        assert lens.model_from_ros(lens.ROS_NAMES[m], lens.N_COEFFS[m]) == m
    assert lens.COEFF_NAMES["thin_prism"][8:] == ("s1", "s2", "s3", "s4")


def test_model_from_ros():
    assert lens.model_from_ros("rational_polynomial", 12) == "thin_prism"
    assert lens.model_from_ros("rational_polynomial", 14) == "thin_prism"
    assert lens.model_from_ros("rational_polynomial", 8) == "rational_polynomial"
    assert lens.model_from_ros("rational_polynomial", 5) == "plumb_bob"
    assert lens.model_from_ros("plumb_bob", 8) == "plumb_bob"
    assert lens.model_from_ros("fisheye", 4) == "equidistant"
    for name, n in [("equidistant", 5), ("plumb_bob", 6), ("kannala", 4), ("rational_polynomial", 3)]:
        with pytest.raises(ValueError, match="distortion_model"):
            lens.model_from_ros(name, n)


def test_check_model_lengths():
    model, d = lens.check_model("plumb_bob", [0.1, 0.01, 0, 0, 0.001, 0, 0, 0])
    assert model == "plumb_bob" and d.tolist() == [0.1, 0.01, 0, 0, 0.001] and d.dtype == np.float64
    assert lens.check_model("plumb_bob", [0.1, 0.01, 0.0, 0.0])[1].tolist() == [0.1, 0.01, 0, 0, 0]
    assert lens.check_model("thin_prism", np.r_[DISTS["thin_prism"], 0.0, 0.0])[1].size == 12
    assert lens.check_model("equidistant", None)[1].tolist() == [0.0] * 4
    with pytest.raises(ValueError, match=r"non-zero extras"):
        lens.check_model("plumb_bob", [0.1, 0.01, 0, 0, 0.001, 0.2, 0, 0])
    with pytest.raises(ValueError, match=r"'equidistant' must have 4 coefficients \[k1, k2, k3, k4\], got 5"):
        lens.check_model("equidistant", [0.0] * 5)
    with pytest.raises(ValueError, match=r"'rational_polynomial' must have 8 coefficients.*got 5"):
        lens.check_model("rational_polynomial", [0.0] * 5)
    with pytest.raises(ValueError, match="unknown lens model 'fisheye'"):
        lens.check_model("fisheye", [0.0] * 4)
    with pytest.raises(ValueError, match="finite"):
        lens.check_model("plumb_bob", [np.nan, 0, 0, 0, 0])


@pytest.mark.parametrize("bad_K, match", [
    (np.eye(2), r"3x3 camera matrix, got shape \(2, 2\)"),
    (np.zeros(9), r"3x3 camera matrix, got shape \(9,\)"),
    (np.diag([-1.0, 1.0, 1.0]), "focal lengths must be positive"),
    (np.array([[500.0, 1.0, 320], [0, 500, 240], [0, 0, 1]]), "no skew"),
    (np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 2]]), "no skew"),
])
def test_bad_K_raises(bad_K, match):
    with pytest.raises(ValueError, match=match):
        lens.project(np.array([0.0, 0.0, 1.0]), "plumb_bob", bad_K, None)


def test_bad_shapes_raise():
    with pytest.raises(ValueError, match=r"points must have shape \(\.\.\., 3\), got \(4, 2\)"):
        lens.project(np.zeros((4, 2)), "plumb_bob", K0, None)
    with pytest.raises(ValueError, match=r"pixels must have shape \(\.\.\., 2\), got \(3,\)"):
        lens.unproject(np.zeros(3), "plumb_bob", K0, None)
    with pytest.raises(ValueError, match="image_size"):
        lens.field_of_view("plumb_bob", K0, None, (0, 480))
    with pytest.raises(ValueError, match="R must be a 3x3"):
        lens.undistort_maps("plumb_bob", K0, None, (64, 48), R=np.eye(2))
    with pytest.raises(ValueError, match="unknown lens model"):
        lens.unproject(np.zeros(2), "pinhole", K0, None)


# ----------------------------------------------------------------------------- agreement with OpenCV
@pytest.mark.parametrize("model", PINHOLE)
def test_project_matches_opencv(model):
    rng = np.random.default_rng(1)
    P = _random_points(rng, model, max_angle_deg=75.0)
    d = np.array(DISTS[model])
    ref, _ = cv2.projectPoints(P, np.zeros(3), np.zeros(3), K0, d)
    uv = lens.project(P, model, K0, d)
    np.testing.assert_allclose(uv, ref.reshape(-1, 2), rtol=0, atol=1e-6)
    np.testing.assert_allclose(lens.project_normalized(P[:, :2] / P[:, 2:], model, d),
                               (uv - K0[:2, 2]) / np.diag(K0)[:2], rtol=0, atol=1e-12)


def test_project_matches_opencv_fisheye():
    rng = np.random.default_rng(2)
    P = _random_points(rng, "equidistant", max_angle_deg=80.0)
    d = np.array(DISTS["equidistant"])
    ref, _ = cv2.fisheye.projectPoints(P.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K0, d)
    np.testing.assert_allclose(lens.project(P, "equidistant", K0, d), ref.reshape(-1, 2), rtol=0, atol=1e-6)


def test_pinhole_nan_behind_and_beyond_fold():
    d = [-0.35, 0.0, 0.0, 0.0, 0.0]  # folds at r = sqrt(1 / 1.05)
    lim = lens.monotonic_limit("plumb_bob", d)
    assert lim == pytest.approx(math.sqrt(1 / 1.05), rel=1e-12)
    pts = np.array([[0.0, 0.0, -1.0], [0.1, 0.1, 0.0], [0.99 * lim, 0, 1], [1.01 * lim, 0, 1]])
    uv = lens.project(pts, "plumb_bob", K0, d)
    assert np.isnan(uv[:2]).all() and np.isfinite(uv[2]).all() and np.isnan(uv[3]).all()
    # Zero distortion has no fold: far off-axis points still project.
    assert np.isfinite(lens.project([30.0, 0.0, 1.0], "plumb_bob", K0, None)).all()


# ----------------------------------------------------------------------------- fisheye beyond 90 degrees
@pytest.mark.parametrize("theta_deg", [90.0, 95.0, 100.0])
def test_equidistant_beyond_90_degrees(theta_deg):
    d = DISTS["equidistant"]
    P = _rays_at(theta_deg)
    uv = lens.project(P, "equidistant", K0, d)
    assert np.isfinite(uv).all()
    t = math.radians(theta_deg)
    expected_rd = t * (1 + d[0] * t**2 + d[1] * t**4 + d[2] * t**6 + d[3] * t**8)
    rd = np.hypot((uv[:, 0] - K0[0, 2]) / K0[0, 0], (uv[:, 1] - K0[1, 2]) / K0[1, 1])
    np.testing.assert_allclose(rd, expected_rd, rtol=1e-12)
    rays = lens.unproject(uv, "equidistant", K0, d)
    np.testing.assert_allclose(rays, _unit(P), atol=1e-12)
    theta_back = np.degrees(np.arctan2(np.hypot(rays[:, 0], rays[:, 1]), rays[:, 2]))
    np.testing.assert_allclose(theta_back, theta_deg, atol=1e-9)


def test_equidistant_axis_and_behind():
    d = DISTS["equidistant"]
    uv = lens.project(np.array([[0.0, 0.0, 3.0], [0.0, 0.0, -3.0], [0.0, 0.0, 0.0]]), "equidistant", K0, d)
    np.testing.assert_array_equal(uv[0], K0[:2, 2])
    assert np.isnan(uv[1:]).all()


# ----------------------------------------------------------------------------- exact inverses
@pytest.mark.parametrize("model", lens.MODELS)
def test_unproject_project_round_trip(model):
    rng = np.random.default_rng(3)
    P = _random_points(rng, model, max_angle_deg=75.0)
    uv = lens.project(P, model, K0, DISTS[model])
    rays = lens.unproject(uv, model, K0, DISTS[model])
    np.testing.assert_allclose(np.linalg.norm(rays, axis=1), 1.0, atol=1e-14)
    np.testing.assert_allclose(rays, _unit(P), atol=1e-10)
    np.testing.assert_allclose(lens.project(rays, model, K0, DISTS[model]), uv, atol=1e-8)


def _grid(w, h):
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    return np.stack([u.ravel(), v.ravel()], axis=1)


def test_pixel_grid_round_trip_strong_barrel():
    w, h = 640, 480
    K = np.array([[420.0, 0, (w - 1) / 2 + 3.0], [0, 421.0, (h - 1) / 2 - 2.0], [0, 0, 1]])
    d = [-0.35, 0.12, 4e-4, -3e-4, 0.0]
    px = _grid(w, h)
    rays = lens.unproject(px, "plumb_bob", K, d)
    assert np.isfinite(rays).all()  # monotone everywhere: the whole image is imaged
    np.testing.assert_allclose(lens.project(rays, "plumb_bob", K, d), px, rtol=0, atol=1e-6)


def test_pixel_grid_nan_beyond_fold():
    w, h = 640, 480
    K = np.array([[420.0, 0, 319.5], [0, 420.0, 239.5], [0, 0, 1]])
    d = [-0.35, 0.0, 0.0, 0.0, 0.0]
    r_fold = lens.monotonic_limit("plumb_bob", d)
    rd_max = r_fold * (1 - 0.35 * r_fold**2)
    px = _grid(w, h)
    rays = lens.unproject(px, "plumb_bob", K, d)
    rd = np.hypot(px[:, 0] - 319.5, px[:, 1] - 239.5) / 420.0
    ok = np.isfinite(rays).all(axis=1)
    clear = np.abs(rd - rd_max) > 1e-6
    np.testing.assert_array_equal(ok[clear], rd[clear] <= rd_max)
    assert (~ok).sum() > 1000 and ok.sum() > 1000
    np.testing.assert_allclose(lens.project(rays[ok], "plumb_bob", K, d), px[ok], rtol=0, atol=1e-6)


def _theta_d(t, k):
    return t * (1 + k[0] * t**2 + k[1] * t**4 + k[2] * t**6 + k[3] * t**8)


@pytest.mark.parametrize("k, all_valid", [([0.01, -0.003, 5e-4, -1e-4], True), ([-0.05, 0.0, 0.0, 0.0], False)])
def test_pixel_grid_round_trip_185_degree_fisheye(k, all_valid):
    w, h = 1280, 960
    f = (w / 2) / _theta_d(math.radians(92.5), k)  # the left and right edges see 92.5 degrees
    K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]])
    px = _grid(w, h)[::3]
    rays = lens.unproject(px, "equidistant", K, k)
    ok = np.isfinite(rays).all(axis=1)
    td_max = _theta_d(lens.monotonic_limit("equidistant", k), k)
    td = np.hypot(px[:, 0] - K[0, 2], px[:, 1] - K[1, 2]) / f
    clear = np.abs(td - td_max) > 1e-6
    np.testing.assert_array_equal(ok[clear], td[clear] <= td_max)
    assert ok.all() == all_valid
    np.testing.assert_allclose(lens.project(rays[ok], "equidistant", K, k), px[ok], rtol=0, atol=1e-6)
    fov = lens.field_of_view("equidistant", K, k, (w, h))
    assert fov["horizontal"] == pytest.approx(185.0, abs=1e-6)


def _existing_undistort():
    for name in ("data_gen.camera", "aicalib_tf.geometry.camera", "data_gen"):
        try:
            mod = importlib.import_module(name)
        except ImportError:
            continue
        if hasattr(mod, "undistort_normalized"):
            return mod.undistort_normalized, getattr(mod, "monotonic_radius", None)
    pytest.skip("no existing undistort_normalized to compare with")


def test_plumb_bob_matches_existing_undistort_normalized():
    undistort_normalized, monotonic_radius = _existing_undistort()
    rng = np.random.default_rng(4)
    for d in ([-0.35, 0.12, 4e-4, -3e-4, -0.002], [-0.4, 0.05, 1e-3, 2e-4, 0.0], [0.2, 0.03, 0.0, 0.0, 0.0]):
        xy_d = rng.uniform(-1.6, 1.6, (4000, 2))
        ref = undistort_normalized(xy_d, d)
        rays = lens.unproject(xy_d, "plumb_bob", np.eye(3), d)
        ours = rays[:, :2] / rays[:, 2:]
        np.testing.assert_array_equal(np.isnan(ours), np.isnan(ref))
        np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-9)
        if monotonic_radius is not None:
            assert lens.monotonic_limit("plumb_bob", d) == monotonic_radius(d)


# ----------------------------------------------------------------------------- monotonic limits
def test_monotonic_limits_are_folds():
    for model, d in [("plumb_bob", [-0.35, 0.02, 0, 0, 0]),
                     ("rational_polynomial", [-0.5, 0.0, 0, 0, 0.0, 0.1, 0.0, 0.0]),
                     ("equidistant", [-0.05, 0.0002, 0.0, 0.0])]:
        lim = lens.monotonic_limit(model, d)
        assert 0.1 < lim < (math.pi if model == "equidistant" else 20.0)
        s = np.linspace(0.0, lim * 1.05, 2001)
        if model == "equidistant":
            rd = _theta_d(s, d)
        else:
            c = np.asarray(d, float)
            num = 1 + c[0] * s**2 + c[1] * s**4 + c[4] * s**6
            den = 1 + c[5] * s**2 + c[6] * s**4 + c[7] * s**6 if c.size > 5 else 1.0
            rd = s * num / den
        slope = np.diff(rd)
        assert (slope[s[1:] <= lim] > 0).all() and (slope[s[:-1] >= lim] < 0).all()
    assert lens.monotonic_limit("plumb_bob", None) == 20.0
    assert lens.monotonic_limit("equidistant", None) == pytest.approx(math.pi)


# ----------------------------------------------------------------------------- field of view, field, maps
def test_field_of_view_pinhole():
    w, h, f = 640, 480, 500.0
    K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]])
    fov = lens.field_of_view("plumb_bob", K, None, (w, h))
    assert fov["horizontal"] == pytest.approx(math.degrees(2 * math.atan(w / 2 / f)), abs=1e-6)
    assert fov["vertical"] == pytest.approx(math.degrees(2 * math.atan(h / 2 / f)), abs=1e-6)
    assert fov["diagonal"] == pytest.approx(math.degrees(2 * math.atan(math.hypot(w, h) / 2 / f)), abs=1e-6)
    K_off = np.array([[f, 0, 200.0], [0, f, 300.0], [0, 0, 1]])  # off-centre: the half-angles differ
    fov = lens.field_of_view("plumb_bob", K_off, None, (w, h))
    assert fov["horizontal"] == pytest.approx(math.degrees(math.atan(200.5 / f) + math.atan(439.5 / f)), abs=1e-6)
    assert fov["vertical"] == pytest.approx(math.degrees(math.atan(300.5 / f) + math.atan(179.5 / f)), abs=1e-6)


def test_field_of_view_200_degree_fisheye():
    w, h = 1000, 1000
    f = (w / 2) / math.radians(100.0)
    K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]])
    fov = lens.Lens("equidistant", K, None, (w, h)).field_of_view()
    assert fov["horizontal"] == pytest.approx(200.0, abs=1e-6)
    assert fov["vertical"] == pytest.approx(200.0, abs=1e-6)
    assert fov["diagonal"] == pytest.approx(200.0 * math.sqrt(2), abs=1e-6)


def test_field_of_view_is_the_valid_region_when_edge_not_imaged():
    d = [-0.35, 0, 0, 0, 0]
    fov = lens.field_of_view("plumb_bob", np.array([[200.0, 0, 319.5], [0, 200, 239.5], [0, 0, 1]]), d, (640, 480))
    full = 2 * math.degrees(math.atan(lens.monotonic_limit("plumb_bob", d)))  # the monotonic radius' diameter
    assert fov["horizontal"] == pytest.approx(full) and fov["diagonal"] == pytest.approx(full)
    assert lens.max_angle("plumb_bob", d) == pytest.approx(math.radians(full / 2))


def test_distortion_field_matches_opencv_undistort_points():
    d = np.array(DISTS["plumb_bob"])
    px = _grid(640, 480)[::97]
    field, ok = lens.distortion_field(px, "plumb_bob", K0, d)
    assert ok.all()
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 500, 1e-14)
    ref = cv2.undistortPoints(px.reshape(-1, 1, 2), K0, d, R=None, P=K0, criteria=crit).reshape(-1, 2)
    np.testing.assert_allclose(field, ref - px, atol=1e-4)
    zero_field, zero_ok = lens.distortion_field(px, "plumb_bob", K0, None)
    assert zero_ok.all() and np.abs(zero_field).max() < 1e-9


def test_distortion_field_fisheye_behind_90_not_ok():
    k = DISTS["equidistant"]
    uv = lens.project(np.vstack([_rays_at(100.0, 4), _rays_at(30.0, 4)]), "equidistant", K0, k)
    field, ok = lens.distortion_field(uv, "equidistant", K0, k)
    np.testing.assert_array_equal(ok, [False] * 4 + [True] * 4)
    assert np.isnan(field[:4]).all() and np.isfinite(field[4:]).all()


def _rectify_setup():
    R = cv2.Rodrigues(np.array([0.02, -0.03, 0.01]))[0]
    new_K = np.array([[430.0, 0, 330.0], [0, 430.0, 230.0], [0, 0, 1]])
    return R, new_K


@pytest.mark.parametrize("model", PINHOLE)
def test_undistort_maps_match_opencv(model):
    R, new_K = _rectify_setup()
    d = np.array(DISTS[model])
    mx, my = lens.undistort_maps(model, K0, d, (640, 480), new_K=new_K, R=R)
    assert mx.dtype == np.float32 and mx.shape == (480, 640)
    rx, ry = cv2.initUndistortRectifyMap(K0, d, R, new_K, (640, 480), cv2.CV_32FC1)
    valid = mx != -1.0
    assert valid.mean() > 0.99
    assert max(np.abs(mx - rx)[valid].max(), np.abs(my - ry)[valid].max()) < 1e-3


def test_undistort_maps_match_opencv_fisheye():
    R, new_K = _rectify_setup()
    d = np.array(DISTS["equidistant"])
    mx, my = lens.undistort_maps("equidistant", K0, d, (640, 480), new_K=new_K, R=R, new_size=(700, 500))
    assert mx.shape == (500, 700)
    rx, ry = cv2.fisheye.initUndistortRectifyMap(K0, d, R, new_K, (700, 500), cv2.CV_32FC1)
    valid = (mx != -1.0) & np.isfinite(rx) & np.isfinite(ry)
    assert valid.mean() > 0.99
    assert max(np.abs(mx - rx)[valid].max(), np.abs(my - ry)[valid].max()) < 1e-3


def test_undistort_maps_identity_without_distortion():
    mx, my = lens.undistort_maps("rational_polynomial", K0, None, (64, 48))
    u, v = np.meshgrid(np.arange(64), np.arange(48))
    assert np.abs(mx - u).max() < 1e-4 and np.abs(my - v).max() < 1e-4


# ----------------------------------------------------------------------------- Jacobians
def _jac_points(model):
    rng = np.random.default_rng(5)
    P = _random_points(rng, model, n=60, max_angle_deg=60.0)
    if lens.get_model(model).IS_FISHEYE:
        P = np.vstack([P, _rays_at(100.0, 8, rho=3.0), _rays_at(89.9, 4), [[0.0, 0.0, 2.0]]])
    return P


@pytest.mark.parametrize("model", lens.MODELS)
def test_projection_jacobian_matches_finite_differences(model):
    P = _jac_points(model)
    d = np.array(DISTS[model])
    uv, Jp, Ji = lens.projection_jacobian(P, model, K0, d)
    n = d.size
    assert uv.shape == (len(P), 2) and Jp.shape == (len(P), 2, 3) and Ji.shape == (len(P), 2, 4 + n)
    np.testing.assert_allclose(uv, lens.project(P, model, K0, d), atol=1e-12)
    scale = np.linalg.norm(P, axis=1)
    Jp_fd = np.empty_like(Jp)
    for j in range(3):
        step = np.zeros_like(P)
        step[:, j] = 1e-6 * scale
        Jp_fd[:, :, j] = (lens.project(P + step, model, K0, d) - lens.project(P - step, model, K0, d)) / (2e-6 * scale[:, None])
    np.testing.assert_allclose(Jp, Jp_fd, rtol=1e-5, atol=1e-6 * np.abs(Jp_fd).max())
    lens_ = lens.Lens(model, K0, d, (640, 480))
    v0 = lens_.intrinsics()
    Ji_fd = np.empty_like(Ji)
    for j in range(4 + n):
        h = 1e-6 * max(1.0, abs(v0[j]))
        vp, vm = v0.copy(), v0.copy()
        vp[j] += h
        vm[j] -= h
        up = lens.Lens.from_intrinsics(model, vp, (640, 480)).project(P)
        um = lens.Lens.from_intrinsics(model, vm, (640, 480)).project(P)
        Ji_fd[:, :, j] = (up - um) / (2 * h)
    np.testing.assert_allclose(Ji, Ji_fd, rtol=1e-5, atol=1e-6 * np.abs(Ji_fd).max())


def test_projection_jacobian_nan_rows():
    uv, Jp, Ji = lens.projection_jacobian(np.array([[0.0, 0.0, -1.0], [0.1, 0.2, 1.0]]), "plumb_bob", K0, None)
    assert np.isnan(uv[0]).all() and np.isnan(Jp[0]).all() and np.isnan(Ji[0]).all()
    assert np.isfinite(uv[1]).all() and np.isfinite(Jp[1]).all() and np.isfinite(Ji[1]).all()


@pytest.mark.parametrize("model", ["thin_prism", "equidistant"])
def test_projection_jacobian_is_fast(model):
    P = _random_points(np.random.default_rng(6), model, n=40 * 54)
    best = math.inf
    for _ in range(20):
        t0 = time.perf_counter()
        lens.projection_jacobian(P, model, K0, DISTS[model])
        best = min(best, time.perf_counter() - t0)
    assert best < 5e-3, f"projection_jacobian of 2160 points took {best * 1e3:.2f} ms"


# ----------------------------------------------------------------------------- Lens
def test_lens_validates_and_is_frozen():
    with pytest.raises(ValueError, match="focal lengths must be positive"):
        lens.Lens("plumb_bob", np.diag([0.0, 500.0, 1.0]), None, (640, 480))
    with pytest.raises(ValueError, match="image_size"):
        lens.Lens("plumb_bob", K0, None, (640, 0))
    with pytest.raises(ValueError, match="must have 5 coefficients"):
        lens.Lens("plumb_bob", K0, [0.1] * 3, (640, 480))
    cam = lens.Lens("thin_prism", K0, DISTS["thin_prism"], (640.0, 480.0))
    assert cam.image_size == (640, 480) and cam.dist.dtype == np.float64
    with pytest.raises(dataclasses.FrozenInstanceError):
        cam.model = "plumb_bob"
    with pytest.raises(ValueError):
        cam.K[0, 0] = 1.0  # read-only


@pytest.mark.parametrize("model", lens.MODELS)
def test_lens_round_trips_and_methods(model):
    cam = lens.Lens(model, K0, DISTS[model], (640, 480))
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (520.0, 515.0, 322.5, 236.0)
    v = cam.intrinsics()
    assert v.shape == (4 + lens.N_COEFFS[model],)
    assert lens.Lens.from_intrinsics(model, v, (640, 480)) == cam
    data = json.loads(json.dumps(cam.to_dict()))
    assert set(data) == {"model", "K", "dist", "image_size"} and data["model"] == model
    back = lens.Lens.from_dict(data)
    assert back == cam and hash(back) == hash(cam)
    P = _random_points(np.random.default_rng(7), model, n=20)
    np.testing.assert_array_equal(cam.project(P), lens.project(P, model, K0, DISTS[model]))
    np.testing.assert_array_equal(cam.unproject(cam.project(P)), lens.unproject(cam.project(P), model, K0, DISTS[model]))
    assert cam.field_of_view() == lens.field_of_view(model, K0, DISTS[model], (640, 480))
    assert cam.monotonic_limit() == lens.monotonic_limit(model, DISTS[model])
    with pytest.raises(ValueError, match="lacks keys"):
        lens.Lens.from_dict({"model": model})


def test_project_keeps_leading_shape():
    P = _random_points(np.random.default_rng(8), "plumb_bob", n=24).reshape(2, 3, 4, 3)
    uv = lens.project(P, "plumb_bob", K0, DISTS["plumb_bob"])
    assert uv.shape == (2, 3, 4, 2)
    assert lens.unproject(uv, "plumb_bob", K0, DISTS["plumb_bob"]).shape == (2, 3, 4, 3)


def test_docstring_examples():
    result = doctest.testmod(lens, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted >= 4 and result.failed == 0
