"""The LiteRT runtime's interpreters: one planned per input shape, bounded, same outputs."""

import numpy as np

from aicalib_tf.cnn import runtime
from aicalib_tf.cnn.model import load_model


def test_each_shape_keeps_its_interpreter_and_outputs_do_not_change():
    model = load_model("default")
    rng = np.random.default_rng(0)
    a = rng.normal(size=(1, 48, 64, 1)).astype(np.float32)
    b = rng.normal(size=(1, 32, 40, 1)).astype(np.float32)
    first = model(a)
    model(b)
    assert model.planned_shapes() == [a.shape, b.shape]
    again = model(a)  # served by a's own interpreter, now the most recently used
    assert model.planned_shapes() == [b.shape, a.shape]
    np.testing.assert_array_equal(first, again)
    assert first.shape == (1, 12, 16, 3)


def test_least_recently_used_shapes_are_dropped(monkeypatch):
    monkeypatch.setattr(runtime, "MAX_SHAPES", 2)
    model = load_model("default")
    shapes = [(1, 16 + 4 * k, 16, 1) for k in range(3)]
    for s in shapes:
        model(np.zeros(s, np.float32))
    assert model.planned_shapes() == shapes[1:]
    monkeypatch.setattr(runtime, "MAX_PIXELS", 16 * 16)  # only the newest fits: it is kept all the same
    model(np.zeros((1, 16, 16, 1), np.float32))
    assert model.planned_shapes() == [(1, 16, 16, 1)]
