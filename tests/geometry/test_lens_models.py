"""The lens-model interface and registry, and the two unified models: Double Sphere and EUCM."""

from __future__ import annotations

import math

import numpy as np
import pytest

from aicalib_tf.geometry import lens
from aicalib_tf.geometry.lens_model import LensModel
from aicalib_tf.geometry.lens_registry import REGISTRY, get_model, model_from_file_name

K = np.array([[300.0, 0.0, 640.5], [0.0, 299.0, 480.5], [0.0, 0.0, 1.0]])
UNIFIED = {"ds": [-0.18, 0.59], "eucm": [0.63, 1.08]}


def _rays(theta_deg, n=12):
    t = np.radians(np.asarray(theta_deg, np.float64))[:, None]
    phi = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)[None, :] + 0.3
    return np.stack([np.sin(t) * np.cos(phi), np.sin(t) * np.sin(phi), np.cos(t) + 0 * phi], axis=-1).reshape(-1, 3)


def test_every_model_has_the_interface():
    for name, spec in REGISTRY.items():
        assert isinstance(spec, LensModel) and spec.NAME == name and get_model(name) is spec
        assert len(spec.DEFAULT) == len(spec.FIT_START) == spec.n_coeffs
        assert set(spec.NAMES) == {"opencv", "ros", "kalibr"} and spec.START in ("opencv", "rays", "layout")
        assert spec.IS_FISHEYE == (spec.MAX_ANGLE > math.pi / 2)
        assert set(spec.EXTRA_COEFFS) <= set(spec.COEFF_NAMES)
        assert model_from_file_name(spec.NAMES["ros"], spec.n_coeffs) in REGISTRY
    assert sorted(r.RANK for r in REGISTRY.values()) == sorted({r.RANK for r in REGISTRY.values()})
    with pytest.raises(ValueError, match="unknown lens model"):
        get_model("omni")


def test_registry_docstring_examples():
    import doctest

    from aicalib_tf.geometry import lens_registry

    result = doctest.testmod(lens_registry, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted >= 1 and result.failed == 0


def test_file_names_of_the_unified_models():
    assert lens.model_from_ros("ds", 2) == "ds" and lens.model_from_ros("double_sphere", 2) == "ds"
    assert lens.model_from_ros("EUCM", 2) == "eucm"
    assert get_model("ds").NAMES["kalibr"] == ("ds", "none") and get_model("eucm").NAMES["opencv"] is None
    with pytest.raises(ValueError, match="cannot map"):
        lens.model_from_ros("ds", 4)


@pytest.mark.parametrize("model, dist, match", [
    ("ds", [-1.0, 0.5], "xi"), ("ds", [0.2, 1.2], "alpha"), ("eucm", [-0.1, 1.0], "alpha"), ("eucm", [0.5, 0.0], "beta"),
])
def test_unified_models_refuse_coefficients_out_of_range(model, dist, match):
    with pytest.raises(ValueError, match=match):
        lens.Lens(model, K, dist, (1280, 960))


@pytest.mark.parametrize("model", sorted(UNIFIED))
def test_unified_models_round_trip_past_180_degrees(model):
    d = UNIFIED[model]
    top = math.degrees(lens.max_angle(model, d))
    assert top > 100.0  # these coefficients image past 200°
    P = _rays(np.linspace(0.0, min(top - 0.5, 110.0), 45)) * 2.5
    uv = lens.project(P, model, K, d)
    assert np.isfinite(uv).all()
    rays = lens.unproject(uv, model, K, d)
    np.testing.assert_allclose(rays, P / np.linalg.norm(P, axis=1, keepdims=True), atol=1e-9)
    np.testing.assert_allclose(lens.project(rays, model, K, d), uv, atol=1e-8)


@pytest.mark.parametrize("model, dist", [("ds", [-0.18, 0.59]), ("ds", [0.3, 0.3]), ("ds", [-0.4, 0.7]),
                                         ("eucm", [0.63, 1.08]), ("eucm", [0.35, 1.6]), ("eucm", [0.8, 0.7])])
def test_unified_models_are_valid_and_monotonic_up_to_max_angle(model, dist):
    top = lens.max_angle(model, dist)
    t = np.linspace(0.0, top, 2000)[1:-1]
    r = np.array([lens.project_normalized(np.array([np.tan(a), 0.0]), model, dist)[0] if a < math.pi / 2 - 1e-6
                  else np.nan for a in t])
    P = np.stack([np.sin(t), np.zeros_like(t), np.cos(t)], axis=1)
    a = lens.project(P, model, np.eye(3), dist)[:, 0]
    assert np.isfinite(a).all() and np.all(np.diff(a) > 0)  # the radial map increases to the domain's edge
    fin = np.isfinite(r)
    np.testing.assert_allclose(r[fin], a[fin], rtol=1e-9)
    beyond = np.array([[math.sin(top + 0.01), 0.0, math.cos(top + 0.01)]])
    if top + 0.01 < math.pi:
        assert np.isnan(lens.project(beyond, model, K, dist)).all()


def test_unified_models_special_cases():
    P = _rays(np.linspace(0.0, 80.0, 9)) * 3.0
    pin = lens.project(P, "plumb_bob", K, None)
    np.testing.assert_allclose(lens.project(P, "ds", K, None), pin, atol=1e-9)  # ξ = α = 0: a pinhole
    np.testing.assert_allclose(lens.project(P, "eucm", K, None), pin, atol=1e-9)  # α = 0: a pinhole
    np.testing.assert_allclose(lens.project(P, "ds", K, [0.0, 0.45]), lens.project(P, "eucm", K, [0.45, 1.0]), atol=1e-9)
    assert lens.max_angle("eucm", [0.5, 1.0]) == pytest.approx(math.pi) and lens.max_angle("ds", [0.0, 0.0]) == pytest.approx(math.pi / 2)


@pytest.mark.parametrize("model", sorted(UNIFIED))
def test_unified_field_of_view_is_never_nan(model):
    d = UNIFIED[model]
    cam = lens.Lens(model, [[220.0, 0, 639.5], [0, 220.0, 479.5], [0, 0, 1]], d, (1280, 960))
    assert np.isnan(cam.unproject([[-0.5, -0.5]])).all()  # the image corner is beyond the valid region
    fov = cam.field_of_view()
    assert all(np.isfinite(v) for v in fov.values())
    assert fov["diagonal"] == pytest.approx(2 * math.degrees(lens.max_angle(model, d)))
