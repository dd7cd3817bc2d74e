import zipfile

import numpy as np
import pytest

keras = pytest.importorskip("keras")

from aicalib_tf.cnn.model import (  # noqa: E402
    build_model,
    compile_model,
    corner_map_loss,
    load_model,
    model_kind,
    save_model,
)


def _stack(model):
    return [(type(layer).__name__, getattr(layer, "filters", getattr(layer, "units", None))) for layer in model.layers]


def test_report_architecture_is_the_reports_stack():
    m = build_model("report")
    assert isinstance(m, keras.Sequential)
    assert _stack(m) == [
        ("Conv2D", 16), ("MaxPooling2D", None),
        ("Conv2D", 32), ("MaxPooling2D", None),
        ("Conv2D", 64), ("MaxPooling2D", None),
        ("Conv2D", 128), ("MaxPooling2D", None),
        ("Flatten", None), ("Dense", 64), ("Dense", 1),
    ]
    assert all(l.kernel_size == (3, 3) for l in m.layers if isinstance(l, keras.layers.Conv2D))
    assert m.input_shape == (None, 32, 32, 1) and m.output_shape == (None, 1)
    y = m(np.zeros((2, 32, 32, 1), np.float32))
    assert y.shape == (2, 1) and np.all((np.asarray(y) >= 0) & (np.asarray(y) <= 1))
    assert model_kind(m) == "patch"


def test_default_architecture_is_the_documented_stack():
    m = build_model("default")
    assert _stack(m) == [
        ("Conv2D", 4), ("Conv2D", 8),
        ("Conv2D", 16), ("MaxPooling2D", None),
        ("Conv2D", 32), ("Conv2D", 32), ("Conv2D", 32), ("Conv2D", 3),
    ]
    assert m.get_layer("conv1").strides == (2, 2)  # conv1 at stride 2 in place of conv1 + pool1
    assert m.get_layer("conv0").strides == (1, 1) and m.count_params() == 24_739
    v1 = build_model("default_v1")  # the earlier shipped stack
    assert _stack(v1) == _stack(m)[1:2] + [("MaxPooling2D", None)] + _stack(m)[2:] and v1.count_params() == 24_483
    pre = build_model("default_pre")
    assert _stack(pre) == [("Conv2D", 4)] + _stack(v1) and pre.count_params() == 24_739


def test_separable_variants_are_the_documented_stacks(tmp_path):
    sep = build_model("sep")
    assert _stack(sep) == [
        ("Conv2D", 4), ("Conv2D", 8),
        ("SeparableConv2D", 16), ("MaxPooling2D", None),
        ("SeparableConv2D", 32), ("SeparableConv2D", 32), ("SeparableConv2D", 32), ("Conv2D", 3),
    ]
    assert sep.get_layer("conv1").strides == (2, 2) and sep.count_params() == 4_027
    s2 = build_model("sep_s2")  # no full-resolution conv, one more separable layer (receptive field 41 px)
    assert _stack(s2) == _stack(sep)[1:7] + [("SeparableConv2D", 32), ("Conv2D", 3)] and s2.count_params() == 5_115
    assert build_model("sep_w").count_params() == 7_755 and build_model("sep_s2w").count_params() == 10_627
    path = save_model(sep, tmp_path / "sep.keras")  # loads with safe_mode=True
    x = np.random.default_rng(0).normal(size=(1, 48, 64, 1)).astype(np.float32)
    np.testing.assert_allclose(np.asarray(load_model(path, backend="keras")(x)), np.asarray(sep(x)), atol=1e-6)


@pytest.mark.parametrize("arch", ["default", "default_v1", "default_c12", "default_c16", "default_pre",
                                  "sep", "sep_s2", "sep_w", "sep_s2w"])
def test_default_is_fully_convolutional_with_a_stride_4_map(arch):
    m = build_model(arch)
    assert isinstance(m, keras.Sequential) and model_kind(m) == "map"
    assert m.input_shape == (None, None, None, 1) and m.output_shape == (None, None, None, 3)
    assert all(l.name for l in m.layers)
    for h, w in [(64, 96), (480, 640)]:
        y = np.asarray(m(np.zeros((1, h, w, 1), np.float32)))
        assert y.shape == (1, h // 4, w // 4, 3)
        assert np.all((y >= 0) & (y <= 1))


def test_unknown_architecture_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown architecture 'resnet'.*default, report"):
        build_model("resnet")


def test_one_training_step_on_tiny_data_runs():
    rng = np.random.default_rng(0)
    m = compile_model(build_model("default"))
    x = rng.normal(size=(2, 32, 32, 1)).astype(np.float32)
    y = np.zeros((2, 8, 8, 3), np.float32)
    y[0, 3, 4] = [1.0, 0.5, 0.25]
    before = [w.copy() for w in m.get_weights()]
    loss = m.train_on_batch(x, y)
    assert np.isfinite(loss)
    assert any(not np.array_equal(a, b) for a, b in zip(before, m.get_weights()))
    r = compile_model(build_model("report"))
    out = r.train_on_batch(rng.normal(size=(4, 32, 32, 1)).astype(np.float32), np.array([[1], [0], [1], [0]], np.float32))
    assert np.all(np.isfinite(out))


def test_loss_is_zero_only_for_the_exact_map():
    y = np.zeros((1, 2, 2, 3), np.float32)
    y[0, 0, 1] = [1.0, 0.3, 0.6]
    perfect = np.clip(y, 1e-7, 1 - 1e-7)
    perfect[..., 1:] = y[..., 1:]
    assert float(corner_map_loss(y, perfect)) < 1e-4
    off = perfect.copy()
    off[0, 0, 1, 1] = 0.8  # position wrong by half a cell
    assert float(corner_map_loss(y, off)) > 1.0


@pytest.mark.parametrize("gamma", [0.0, 2.0])
def test_both_losses_are_small_for_the_exact_map_and_large_for_a_miss(gamma):
    from aicalib_tf.cnn.model import CornerMapLoss

    y = np.zeros((1, 4, 4, 3), np.float32)
    y[0, 1, 2] = [1.0, 0.5, 0.5]
    good = y.copy()
    good[..., 0] = np.where(y[..., 0] > 0, 0.999, 0.001)
    missed = good.copy()
    missed[0, 1, 2, 0] = 0.01
    loss = CornerMapLoss(gamma=gamma)
    assert float(loss(y, good)) < 0.05
    assert float(loss(y, missed)) > 10 * float(loss(y, good))


def test_compiled_model_round_trips_with_its_loss(tmp_path):
    m = compile_model(build_model("default"), focal_gamma=1.5)
    path = save_model(m, tmp_path / "compiled.keras")
    loaded = load_model(path, compile=True)
    assert loaded.loss.gamma == 1.5


@pytest.mark.parametrize("arch, shape", [("default", (1, 40, 48, 1)), ("report", (3, 32, 32, 1))])
def test_save_load_round_trip_gives_identical_predictions(tmp_path, arch, shape):
    m = build_model(arch)
    x = np.random.default_rng(1).normal(size=shape).astype(np.float32)
    path = save_model(m, tmp_path / f"{arch}.keras")
    assert [p.name for p in tmp_path.iterdir()] == [f"{arch}.keras"]  # no temporary file left behind
    loaded = load_model(path)
    np.testing.assert_array_equal(np.asarray(m(x)), np.asarray(loaded(x)))


def test_missing_corrupt_and_incompatible_models_name_the_path(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.keras"):
        load_model(tmp_path / "nope.keras")
    bad = tmp_path / "corrupt.keras"
    bad.write_bytes(b"\x00not a zip" * 10)
    with pytest.raises(ValueError, match="corrupt.keras"):
        load_model(bad)
    junk = tmp_path / "junk.keras"
    with zipfile.ZipFile(junk, "w") as z:
        z.writestr("hello.txt", "not a model")
    with pytest.raises(ValueError, match="junk.keras"):
        load_model(junk)
    other = keras.Sequential([keras.Input((5,)), keras.layers.Dense(2)])
    path = save_model(other, tmp_path / "other.keras")
    with pytest.raises(ValueError, match="incompatible model .*other.keras"):
        load_model(path)
    with pytest.raises(ValueError, match=r"\.keras"):
        save_model(other, tmp_path / "model.h5")
