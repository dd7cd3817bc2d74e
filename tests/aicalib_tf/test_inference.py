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
        out = inference.corner_map(m, gray)
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
    inference.corner_map(m, rng.random((16, 16)).astype(np.float32))
    for h, w in ((24, 20), (20, 28)):
        gray = rng.random((h, w)).astype(np.float32)
        np.testing.assert_array_equal(inference.corner_map(m, gray), _keras_map(m, gray))
    assert set(getattr(m, inference._MAP_FNS_ATTR).fns) == {(16, 16), (None, None)}
