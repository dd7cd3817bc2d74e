"""Export the trained Keras models to LiteRT flatbuffers for :mod:`aicalib_tf.cnn.runtime`.

``default.keras`` -> ``default.tflite`` (float32, input (1, H, W, 1) with H and W free: the
runtime resizes the input tensor per image), ``report.keras`` -> ``report.tflite`` (float32, a
batch of (32, 32, 1) patches). Each file gets ``<file>.sha256`` beside it, which the runtime
checks on load. Path: Keras -> SavedModel (``model.export``) -> ``tf.lite.TFLiteConverter``,
TFLite builtin ops only. ``default_int8.tflite`` is ``default`` quantised to int8 (weights and
activations, float input and output), calibrated on data_gen renders (:func:`calibration_images`).

:func:`compare_runtime` measures each export against its Keras model (largest output difference,
ms per call); ``python -m aicalib_tf.export`` writes that into ``models/MODEL_CARD.md``.

Imports TensorFlow: for export only, never at detection time.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from aicalib_tf.cnn.spec import MODELS_DIR, RUNTIME_FILES, write_sha256

__all__ = ["export_tflite", "write_sha256", "calibration_images", "export_all", "compare_runtime"]


CALIBRATION_TRIES = 5  # scenes tried per calibration image before giving up
# The data_gen presets the shipped int8 files were calibrated on, fixed so that a preset added later does not
# change what a re-export calibrates on.
CALIBRATION_PRESETS = ("blur", "calib", "calib_fisheye", "clean", "clutter", "distorted", "fisheye",
                       "fisheye_closeup", "hard", "noisy", "occluded", "partial", "train")


def calibration_images(n: int = 48, seed: int = 0):
    """``n`` network inputs (1, H, W, 1) float32 of data_gen boards (:data:`CALIBRATION_PRESETS` in turn), for int8
    calibration.

    Image i is scene i of preset i mod P; where data_gen finds no pose for that scene, scene i + n, i + 2n, ...
    """
    from aicalib_tf.cnn.corner_map import network_input
    from data_gen import make_sample

    presets = CALIBRATION_PRESETS
    for i in range(n):
        name = presets[i % len(presets)]
        for index in range(i, i + CALIBRATION_TRIES * n, n):  # a scene data_gen finds no pose for: the next one
            try:
                sample = make_sample(name, seed=seed, index=index)
                break
            except RuntimeError:
                continue
        else:
            raise RuntimeError(f"int8 calibration: data_gen drew no {name!r} scene at indices {i}, {i + n}, ... "
                               f"({CALIBRATION_TRIES} tries)")
        yield network_input(sample.image)


def export_tflite(keras_path: Path, out: Path, *, int8: bool = False, images=None) -> Path:
    """Convert one .keras model to a .tflite file at ``out`` (written atomically) and its .sha256."""
    import tensorflow as tf

    from aicalib_tf.cnn.keras_model import load_keras
    from aicalib_tf.cnn.spec import model_kind

    model = load_keras(Path(keras_path))
    shape = (1, None, None, 1) if model_kind(model) == "map" else (None, 32, 32, 1)
    with tempfile.TemporaryDirectory() as tmp:
        import keras

        model.export(tmp, format="tf_saved_model", verbose=False,
                     input_signature=[keras.InputSpec(shape=shape, dtype="float32")])
        conv = tf.lite.TFLiteConverter.from_saved_model(tmp)
        if int8:
            data = list(images if images is not None else calibration_images())
            conv.optimizations = [tf.lite.Optimize.DEFAULT]
            conv.representative_dataset = lambda: ([x] for x in data)
            conv.target_spec.supported_ops = [tf.lite.OpsSet.TFLITE_BUILTINS_INT8]
        blob = conv.convert()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp_out = out.with_name(f".{out.name}.partial-{os.getpid()}")
    tmp_out.write_bytes(blob)
    os.replace(tmp_out, out)
    write_sha256(out)
    return out


def export_all(models_dir: Path = MODELS_DIR) -> list[Path]:
    """Export every runtime file of :data:`~aicalib_tf.cnn.spec.RUNTIME_FILES` (default, report, and
    default_int8, quantised on :func:`calibration_images`); returns the files."""
    return [export_tflite(models_dir / f"{keras}.keras", models_dir / f"{name}.tflite", int8=name.endswith("_int8"))
            for name, keras in RUNTIME_FILES.items()]


def _median_ms(fn, inputs, repeat: int = 3) -> float:
    """Median wall time of ``fn(x)`` over the inputs (after one untimed call each), ms."""
    import time

    times = []
    for x in inputs:
        fn(x)
        for _ in range(repeat):
            t0 = time.perf_counter()
            fn(x)
            times.append(1e3 * (time.perf_counter() - t0))
    return float(np.median(times))


def compare_runtime(name: str, models_dir: Path = MODELS_DIR, *, n: int = 8) -> dict:
    """How ``models/<name>.tflite`` on the runtime compares with the ``.keras`` model it is exported
    from (:data:`~aicalib_tf.cnn.spec.RUNTIME_FILES`; float32).

    The corner-map model runs on ``n`` data_gen images (:func:`calibration_images`), the patch
    classifier on batches of 256 patches cut from them at random places. Returns {"inputs":
    description, "max_abs_diff": largest output difference, "keras_ms", "runtime_ms": median per
    call}.
    """
    from aicalib_tf.cnn.keras_inference import run_map, run_patches
    from aicalib_tf.cnn.model import load_model
    from aicalib_tf.cnn.spec import PATCH_SIZE, model_kind

    keras_model = load_model(models_dir / f"{RUNTIME_FILES[name]}.keras")
    runtime = load_model(models_dir / f"{name}.tflite")
    images = list(calibration_images(n))
    if model_kind(keras_model) == "map":
        inputs, what = images, f"{n} data_gen images (corner maps)"

        def ours(x):
            return runtime(x)[0]

        def theirs(x):
            return run_map(keras_model, x, "float32")
    else:
        rng = np.random.default_rng(0)
        inputs = []
        for x in images:
            h, w = x.shape[1:3]
            ys, xs = rng.integers(0, h - PATCH_SIZE, 256), rng.integers(0, w - PATCH_SIZE, 256)
            inputs.append(np.stack([x[0, y:y + PATCH_SIZE, c:c + PATCH_SIZE] for y, c in zip(ys, xs)]))
        what = f"{n} batches of 256 patches of data_gen images"

        def ours(x):
            return runtime(x)[:, 0]

        def theirs(x):
            return run_patches(keras_model, x)
    diff = max(float(np.max(np.abs(ours(x) - theirs(x)))) for x in inputs)
    return {"inputs": what, "max_abs_diff": diff, "keras_ms": _median_ms(theirs, inputs),
            "runtime_ms": _median_ms(ours, inputs)}
