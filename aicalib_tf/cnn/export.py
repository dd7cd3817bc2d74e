"""Export the trained Keras models to LiteRT flatbuffers for :mod:`aicalib_tf.cnn.runtime`.

``default.keras`` -> ``default.tflite`` (float32, input (1, H, W, 1) with H and W free: the
runtime resizes the input tensor per image), ``report.keras`` -> ``report.tflite`` (float32, a
batch of (32, 32, 1) patches). Each file gets ``<file>.sha256`` beside it, which the runtime
checks on load. Path: Keras -> SavedModel (``model.export``) -> ``tf.lite.TFLiteConverter``,
TFLite builtin ops only. Optionally an int8 model (weights and activations, float input and
output), calibrated on data_gen renders (:func:`calibration_images`).

Imports TensorFlow: for export only, never at detection time.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from aicalib_tf.cnn.spec import MODELS_DIR, file_sha256

__all__ = ["export_tflite", "write_sha256", "calibration_images", "export_all"]


def write_sha256(path: Path) -> str:
    """Write ``<path>.sha256`` (sha256sum's format) and return the hash."""
    sha = file_sha256(path)
    Path(str(path) + ".sha256").write_text(f"{sha}  {Path(path).name}\n", encoding="ascii")
    return sha


def calibration_images(n: int = 48, seed: int = 0):
    """``n`` network inputs (1, H, W, 1) float32 of data_gen boards (every preset in turn), for int8 calibration."""
    from aicalib_tf.cnn.corner_map import network_input
    from data_gen import PRESETS, make_sample

    presets = sorted(PRESETS)
    for i in range(n):
        yield network_input(make_sample(presets[i % len(presets)], seed=seed, index=i).image)


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


def export_all(models_dir: Path = MODELS_DIR, *, int8: bool = False) -> list[Path]:
    """Export default and report (and ``default_int8.tflite`` with ``int8``); returns the files."""
    out = [export_tflite(models_dir / f"{n}.keras", models_dir / f"{n}.tflite") for n in ("default", "report")]
    if int8:
        out.append(export_tflite(models_dir / "default.keras", models_dir / "default_int8.tflite", int8=True))
    return out
