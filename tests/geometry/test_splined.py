"""The splined lens model: layout names, exact inverse, Jacobians, validity and its regularization."""

from __future__ import annotations

import math

import numpy as np
import pytest

from aicalib_tf.geometry import lens
from aicalib_tf.geometry._splined import FAMILY_NAME, N_BASE, splined_name
from aicalib_tf.geometry.lens_registry import MODELS, REGISTRY, get_model

K = np.array([[400.0, 0.0, 321.0], [0.0, 402.0, 239.0], [0.0, 0.0, 1.0]])
NAME = splined_name(8, 7, 190.0, 2.0)


def _dist(seed=0, scale=0.01):
    spec = get_model(NAME)
    rng = np.random.default_rng(seed)
    return np.concatenate([[0.02, -0.004, 0.0005, -0.0001], scale * rng.standard_normal(spec.n_coeffs - N_BASE)])


def _points(n=400, max_deg=90.0, seed=1):
    rng = np.random.default_rng(seed)
    t = np.radians(max_deg) * np.sqrt(rng.uniform(0, 1, n))
    p = rng.uniform(0, 2 * np.pi, n)
    rho = rng.uniform(0.5, 5.0, n)
    return rho[:, None] * np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=1)


def test_a_layout_name_resolves_to_its_model():
    spec = get_model(NAME)
    assert NAME in REGISTRY and NAME in MODELS and NAME in lens.N_COEFFS and FAMILY_NAME in MODELS
    assert spec.NAME == NAME and (spec.nx, spec.ny) == (8, 7) and spec.n_coeffs == N_BASE + 2 * 8 * 7
    assert lens.model_from_ros(NAME, spec.n_coeffs) == NAME and spec.NAMES["opencv"] is None
    assert spec.layout()["base"] == "equidistant" and spec.layout()["order"] == 3
    assert math.isclose(spec.layout()["u_range"][1], math.radians(95.0))
    for bad in (f"{FAMILY_NAME}_nx=3_ny=7_fov=190_smooth=2", f"{FAMILY_NAME}_nx=8", "splined"):
        assert bad not in REGISTRY
        with pytest.raises(ValueError, match="unknown lens model"):
            get_model(bad)
    with pytest.raises(ValueError, match="coefficients"):
        lens.Lens(NAME, K, np.zeros(10), (640, 480))


def test_project_unproject_round_trip():
    P = _points()
    d = _dist()
    uv = lens.project(P, NAME, K, d)
    ok = np.isfinite(uv).all(axis=1)
    assert ok.mean() > 0.8  # the 8x7 grid reaches 95° along x, 76° along y
    rays = lens.unproject(uv[ok], NAME, K, d)
    np.testing.assert_allclose(rays, P[ok] / np.linalg.norm(P[ok], axis=1, keepdims=True), atol=1e-10)
    np.testing.assert_allclose(lens.project(rays, NAME, K, d), uv[ok], atol=1e-8)


def test_rays_beyond_the_spline_are_not_imaged():
    spec = get_model(NAME)
    d = np.zeros(spec.n_coeffs)
    inside = math.radians(90.0)
    outside = spec.V + 0.05  # base radius = θ with k = 0
    P = np.array([[math.sin(inside), 0.0, math.cos(inside)], [0.0, math.sin(outside), math.cos(outside)]])
    uv = lens.project(P, NAME, K, d)
    assert np.isfinite(uv[0]).all() and np.isnan(uv[1]).all()
    assert np.isnan(lens.unproject([[321.0, 239.0 + 402.0 * (spec.V + 0.05)]], NAME, K, d)).all()


def test_jacobians_match_finite_differences():
    P = _points(60, 85.0, seed=4)
    d = _dist(2)
    uv, Jp, Ji = lens.projection_jacobian(P, NAME, K, d)
    ok = np.isfinite(uv).all(axis=1)
    P, Jp, Ji = P[ok], Jp[ok], Ji[ok]
    eps = 1e-6
    for j in range(3):
        e = np.zeros(3)
        e[j] = eps
        fd = (lens.project(P + e, NAME, K, d) - lens.project(P - e, NAME, K, d)) / (2 * eps)
        np.testing.assert_allclose(Jp[:, :, j], fd, atol=1e-5 * np.abs(Jp).max())
    intr = np.concatenate([[K[0, 0], K[1, 1], K[0, 2], K[1, 2]], d])
    cols = [0, 2, 4, 5, 6, 7] + list(np.flatnonzero(np.abs(Ji).sum(axis=(0, 1)) > 0)[6:40])
    for c in cols:
        e = np.zeros(intr.size)
        e[c] = eps
        hi = lens.Lens.from_intrinsics(NAME, intr + e, (640, 480)).project(P)
        lo = lens.Lens.from_intrinsics(NAME, intr - e, (640, 480)).project(P)
        np.testing.assert_allclose(Ji[:, :, c], (hi - lo) / (2 * eps), atol=1e-5 * max(1.0, np.abs(Ji[:, :, c]).max()))


def test_the_regularization_penalizes_bending_and_pins_the_affine_part():
    spec = get_model(NAME)
    r0, J = spec.prior(np.zeros(spec.n_coeffs))
    assert J.shape == (r0.size, spec.n_coeffs) and not r0.any() and not J[:, :N_BASE].any()
    xs = (np.arange(spec.nx) - (spec.nx - 1) / 2) * spec.h
    ys = (np.arange(spec.ny) - (spec.ny - 1) / 2) * spec.h
    X, Y = np.meshgrid(xs, ys)
    affine = np.concatenate([np.zeros(N_BASE), (0.01 + 0.02 * X - 0.01 * Y).ravel(), np.zeros(X.size)])
    bent = np.concatenate([np.zeros(N_BASE), (0.01 * X * X).ravel(), np.zeros(X.size)])
    r_aff, r_bent = spec._prior_matrix() @ affine, spec._prior_matrix() @ bent
    assert np.linalg.norm(spec.prior(affine)[0]) > 10.0  # held at 0 by the gauge rows
    # the fit's rows are a compact factor of these: the same cost for every coefficient vector
    for d in (affine, bent):
        np.testing.assert_allclose(np.linalg.norm(spec.prior(d)[0]), np.linalg.norm(spec._prior_matrix() @ d), rtol=1e-9)
    assert J.shape[0] == spec.n_coeffs < spec._prior_matrix().shape[0]
    # an affine field has no second differences: only the ridge and gauge rows see it
    n_smooth = (spec.ny * (spec.nx - 2) + (spec.ny - 2) * spec.nx + (spec.ny - 1) * (spec.nx - 1))
    assert np.abs(r_aff[:n_smooth]).max() < 1e-12 and np.abs(r_bent[:n_smooth]).max() > 1e-4
