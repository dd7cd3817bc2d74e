import numpy as np
import pytest

pytest.importorskip("keras")

from aicalib_tf import inference  # noqa: E402
from aicalib_tf.corner_map import standardize  # noqa: E402
from aicalib_tf.model import build_model  # noqa: E402


def _keras_map(model, gray):
    g = standardize(gray)
    return np.asarray(model(g[None, :, :, None], training=False))[0]


def test_corner_map_matches_a_plain_keras_call_at_each_size():
    m = build_model("default")
    rng = np.random.default_rng(0)
    for h, w in ((32, 48), (40, 24), (32, 48)):  # the first size again: its function is reused
        gray = rng.random((h, w)).astype(np.float32)
        out = inference.corner_map(m, gray, precision="float32")
        assert out.shape == (h // 4, w // 4, 3) and out.dtype == np.float32
        np.testing.assert_array_equal(out, _keras_map(m, gray))
    assert len(getattr(m, inference._MAP_FNS_ATTR).fns) == 2


def test_corner_map_pads_to_multiples_of_4():
    m = build_model("default")
    gray = np.random.default_rng(1).random((30, 45)).astype(np.float32)
    assert inference.corner_map(m, gray).shape == (8, 12, 3)


def test_sizes_beyond_the_cache_share_one_function_with_the_same_output(monkeypatch):
    monkeypatch.setattr(inference, "MAX_MAP_SHAPES", 1)
    m = build_model("default")
    rng = np.random.default_rng(2)
    inference.corner_map(m, rng.random((16, 16)).astype(np.float32), precision="float32")
    for h, w in ((24, 20), (20, 28)):
        gray = rng.random((h, w)).astype(np.float32)
        np.testing.assert_array_equal(inference.corner_map(m, gray, precision="float32"), _keras_map(m, gray))
    assert set(getattr(m, inference._MAP_FNS_ATTR).fns) == {("float32", (16, 16)), ("float32", (None, None))}


def test_precision_comes_from_the_argument_then_the_environment(monkeypatch):
    monkeypatch.setenv(inference.PRECISION_ENV, "float32")
    assert inference.resolve_precision() == "float32"
    assert inference.resolve_precision("bfloat16") == "bfloat16"
    monkeypatch.setenv(inference.PRECISION_ENV, "auto")
    assert inference.resolve_precision() == ("bfloat16" if inference.native_bfloat16() else "float32")
    monkeypatch.setenv("TF_ENABLE_ONEDNN_OPTS", "0")  # bfloat16 is emulated, slower, without oneDNN
    assert inference.resolve_precision() == "float32"
    assert inference.resolve_precision("bfloat16") == "bfloat16"
    monkeypatch.setenv(inference.PRECISION_ENV, "half")
    with pytest.raises(ValueError, match="AICALIB_PRECISION.*'half'"):
        inference.resolve_precision()


def test_bfloat16_twin_gives_the_shipped_models_corner_map_closely():
    from aicalib_tf.model import load_model
    from data_gen import make_sample

    m = load_model("default")
    n_weights = len(m.weights)
    gray = make_sample("clean", 3, 0, size=(160, 120), pattern=(5, 4)).image
    exact = inference.corner_map(m, gray, precision="float32")
    half = inference.corner_map(m, gray, precision="bfloat16")
    assert half.dtype == np.float32 and half.shape == exact.shape
    assert np.abs(half - exact).max() < 0.05  # bfloat16 keeps ~3 significant digits
    assert np.abs(half - exact).max() > 0  # it really ran in bfloat16
    np.testing.assert_array_equal((half[..., 0] >= 0.5).sum(), (exact[..., 0] >= 0.5).sum())
    twin = inference.inference_model(m, "bfloat16")
    assert twin is not m and twin.layers[0].compute_dtype == "bfloat16" and twin.layers[-1].compute_dtype == "float32"
    assert inference.inference_model(m, "bfloat16") is twin  # made once
    assert inference.inference_model(m, "float32") is m
    assert len(m.weights) == n_weights  # the twin is not tracked as part of the model
