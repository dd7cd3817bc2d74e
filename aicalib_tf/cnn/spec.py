"""What every side of the corner CNNs shares, importing neither TensorFlow nor Keras: the
architecture names, the patch size, where the shipped models live, a model's kind and file hashes."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

__all__ = ["ARCHITECTURES", "SHIPPED", "RUNTIME_FILES", "PATCH_SIZE", "MODELS_DIR", "model_kind", "file_sha256"]

ARCHITECTURES = ("default", "report", "default_v1", "default_c12", "default_c16", "default_pre")
SHIPPED = ("default", "report")  # the models shipped in models/ as .keras and .tflite
# every shipped runtime file (models/<name>.tflite) -> the .keras model it is exported from; default_int8 is
# default post-training quantised to int8 (weights and activations), calibrated on data_gen renders
RUNTIME_FILES = {"default": "default", "report": "report", "default_int8": "default"}
PATCH_SIZE = 32
MODELS_DIR = Path(os.environ.get("AICALIB_MODELS", Path(__file__).resolve().parents[2] / "models"))


def model_kind(model) -> str:
    """``"map"`` for a fully convolutional corner-map model, ``"patch"`` for a patch classifier.

    model : a Keras model or a :class:`aicalib_tf.cnn.runtime.RuntimeModel` (its ``kind``).
    Raises ``ValueError`` for a model with neither interface.
    """
    kind = getattr(model, "kind", None)
    if kind in ("map", "patch") and not hasattr(model, "input_shape"):
        return kind
    shape_in = tuple(model.input_shape)
    shape_out = tuple(model.output_shape)
    if len(shape_in) == 4 and shape_in[3] == 1 and shape_in[1] is None and shape_out[1:] == (None, None, 3):
        return "map"
    if shape_in[1:] == (PATCH_SIZE, PATCH_SIZE, 1) and shape_out[1:] == (1,):
        return "patch"
    raise ValueError(
        f"model {model.name!r} has input {shape_in} and output {shape_out}; expected a corner-map model "
        f"(None, None, None, 1) -> (None, None, None, 3) or a patch classifier (None, {PATCH_SIZE}, {PATCH_SIZE}, 1) -> (None, 1)"
    )


def file_sha256(path: str | os.PathLike) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()
