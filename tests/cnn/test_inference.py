import numpy as np
import pytest

pytest.importorskip("keras")

import tensorflow as tf  # noqa: E402

from aicalib_tf.cnn import inference, keras_inference  # noqa: E402
from aicalib_tf.cnn.corner_map import standardize  # noqa: E402
from aicalib_tf.cnn.model import build_model  # noqa: E402


def _keras_map(model, gray):
    g = standardize(gray)
    return np.asarray(model(g[None, :, :, None], training=False))[0]


def test_corner_map_matches_a_plain_keras_call_at_each_size():
    m = build_model("default")
    rng = np.random.default_rng(0)
    fns = []
    for h, w in ((32, 48), (40, 24), (32, 48), (32, 48)):
        gray = rng.random((h, w)).astype(np.float32)
        out = inference.corner_map(m, gray, precision="float32")
        assert out.shape == (h // 4, w // 4, 3) and out.dtype == np.float32
        np.testing.assert_array_equal(out, _keras_map(m, gray))
        fns.append(set(getattr(m, keras_inference._MAP_FNS_ATTR).fns))
    # a size asked once runs the function for any size; asked again, it gets its own, then reuses it
    anysize, sized = ("float32", (None, None)), ("float32", (32, 48))
    assert fns == [{anysize}, {anysize}, {anysize, sized}, {anysize, sized}]


def test_corner_map_pads_to_multiples_of_4():
    m = build_model("default")
    gray = np.random.default_rng(1).random((30, 45)).astype(np.float32)
    assert inference.corner_map(m, gray).shape == (8, 12, 3)


def test_sizes_beyond_the_cache_share_one_function_with_the_same_output(monkeypatch):
    monkeypatch.setattr(keras_inference, "MAX_MAP_SHAPES", 1)
    m = build_model("default")
    rng = np.random.default_rng(2)
    for _ in range(2):  # asked twice: its own function
        inference.corner_map(m, rng.random((16, 16)).astype(np.float32), precision="float32")
    for h, w in ((24, 20), (20, 28), (24, 20)):
        gray = rng.random((h, w)).astype(np.float32)
        np.testing.assert_array_equal(inference.corner_map(m, gray, precision="float32"), _keras_map(m, gray))
    assert set(getattr(m, keras_inference._MAP_FNS_ATTR).fns) == {("float32", (16, 16)), ("float32", (None, None))}


def test_precision_comes_from_the_argument_then_the_environment(monkeypatch):
    monkeypatch.delenv("TF_ENABLE_ONEDNN_OPTS", raising=False)
    monkeypatch.setenv(inference.PRECISION_ENV, "float32")
    assert inference.resolve_precision() == "float32"
    assert inference.resolve_precision("bfloat16") == "bfloat16"
    monkeypatch.setenv(inference.PRECISION_ENV, "auto")
    assert inference.resolve_precision() == ("bfloat16" if inference.native_bfloat16() else "float32")
    for off in ("0", "FALSE"):  # bfloat16 is emulated, slower, without oneDNN
        monkeypatch.setenv("TF_ENABLE_ONEDNN_OPTS", off)
        assert inference.resolve_precision() == "float32"
        assert inference.resolve_precision("bfloat16") == "bfloat16"
    monkeypatch.setenv(inference.PRECISION_ENV, "half")
    with pytest.raises(ValueError, match="AICALIB_PRECISION.*'half'"):
        inference.resolve_precision()


def test_bfloat16_gives_the_shipped_models_corner_map_closely_and_follows_its_weights():
    from aicalib_tf.cnn.model import load_model
    from data_gen import make_sample

    m = load_model("default", backend="keras")
    gray = make_sample("clean", 3, 0, size=(160, 120), pattern=(5, 4)).image
    exact = inference.corner_map(m, gray, precision="float32")
    half = inference.corner_map(m, gray, precision="bfloat16")
    assert half.dtype == np.float32 and half.shape == exact.shape
    assert np.abs(half - exact).max() < 0.05  # bfloat16 keeps ~3 significant digits
    assert np.abs(half - exact).max() > 0  # it really ran in bfloat16
    assert abs(int((half[..., 0] >= 0.5).sum()) - int((exact[..., 0] >= 0.5).sum())) <= 1
    assert all(layer.compute_dtype == "float32" for layer in m.layers)  # the model is left as it was
    np.testing.assert_array_equal(inference.corner_map(m, gray, precision="float32"), exact)
    # new weights show in both precisions (nothing holds a copy of the old ones)
    m.set_weights([w * 0.5 for w in m.get_weights()])
    exact2 = inference.corner_map(m, gray, precision="float32")
    half2 = inference.corner_map(m, gray, precision="bfloat16")
    assert np.abs(exact2 - exact).max() > 0.1
    assert np.abs(half2 - exact2).max() < 0.05


def test_a_bfloat16_run_that_fails_falls_back_to_float32(monkeypatch):
    m = build_model("default")
    gray = np.random.default_rng(4).random((32, 32)).astype(np.float32)
    real = keras_inference._trace

    def broken(model, dims, precision):
        fn = real(model, dims, precision)
        if precision == "float32":
            return fn

        def fail(x):
            raise tf.errors.InternalError(None, None, "could not create a primitive descriptor")
        return fail

    monkeypatch.setattr(keras_inference, "_trace", broken)
    out = inference.corner_map(m, gray, precision="bfloat16")
    np.testing.assert_array_equal(out, inference.corner_map(m, gray, precision="float32"))
    assert getattr(m, keras_inference._MAP_FNS_ATTR).no_bfloat16
