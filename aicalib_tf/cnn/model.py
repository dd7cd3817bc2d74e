"""The corner CNNs (Keras 3 Sequential), built by name, and safe loading of trained ones.

Two architectures:

``report``
    The report's network, a patch classifier. Input: a (32, 32, 1) standardised grey patch whose
    centre (between pixels 15 and 16, ±0.5 px) may hold a corner. Four 3×3 Conv2D layers with 16,
    32, 64 and 128 filters and ReLU, each followed by 2×2 max-pooling; Flatten; Dense(64, ReLU);
    Dense(1, sigmoid): the corner weight in [0, 1].
``default``
    Ours, fully convolutional: the same kind of classifier applied at every pixel, cheaply. Input: a
    standardised grey image of any size (multiples of 4). Output: the corner map of
    :mod:`aicalib_tf.cnn.corner_map`, (H/4, W/4, 3) sigmoid channels (corner weight and the corner's
    position inside its 4×4 cell). 3×3 Conv2D 4 at full resolution, 8 at stride 2, 16, 2×2
    max-pooling, 32, 32, 32 (ReLU), then a 1×1 Conv2D to the 3 channels. Receptive field 35 px,
    24,739 parameters.

The experimental variants of ``default`` (``default_v1``, the earlier shipped stack, and
others) are listed in :func:`build_model`.

Loading always uses ``safe_mode=True``: a model file can hold weights and a layer graph, never code.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from aicalib_tf.cnn.spec import (
    ARCHITECTURES,
    MODELS_DIR,
    PATCH_SIZE,
    QUICK_NETWORKS,
    RUNTIME_FILES,
    SHIPPED,
    check_model_file,
    file_sha256,
    model_kind,
)

if TYPE_CHECKING:  # the Keras-side names, imported on first use (__getattr__)
    from aicalib_tf.cnn.keras_model import CornerMapLoss, build_model, compile_model, corner_map_loss, save_model

__all__ = [
    "ARCHITECTURES",
    "PATCH_SIZE",
    "build_model",
    "compile_model",
    "corner_map_loss",
    "CornerMapLoss",
    "load_model",
    "save_model",
    "model_kind",
    "file_sha256",
    "MODELS_DIR",
]

_KERAS_NAMES = ("build_model", "compile_model", "corner_map_loss", "CornerMapLoss", "save_model",
                "POSITIVE_WEIGHT", "OFFSET_WEIGHT")
KERAS_HINT = "TensorFlow/Keras is needed to load a .keras model: pip install 'tensorflow-cpu>=2.16' 'keras>=3'"


def __getattr__(name: str):
    """The Keras-side names (:mod:`aicalib_tf.cnn.keras_model`), imported on first use."""
    if name in _KERAS_NAMES:
        from aicalib_tf.cnn import keras_model

        return getattr(keras_model, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _resolve(weights, backend: str) -> Path:
    if isinstance(weights, str) and weights in RUNTIME_FILES and weights not in ARCHITECTURES:
        return MODELS_DIR / f"{weights}.tflite"  # a runtime-only model (default_int8, quick_int8)
    if isinstance(weights, str) and weights in ARCHITECTURES:
        suffix = ".tflite" if backend == "runtime" and weights in SHIPPED else ".keras"
        return MODELS_DIR / f"{weights}{suffix}"
    return Path(weights)


def load_model(weights: str | os.PathLike = "default", *, compile: bool = False, backend: str = "auto"):
    """Load a trained corner model.

    weights : ``"default"`` or ``"report"`` (the models shipped in ``models/``), ``"default_int8"``
        (default quantised to int8, runtime only: about 2× faster, the same detections on
        evaluate's images; see the model card), or a path to a ``.tflite`` or ``.keras`` file.
        ``"default_int8"`` and ``"default"`` on the runtime come with
        ``quick``, the smaller ``quick`` network (int8 or float32) that the detector's quick passes
        run (:func:`aicalib_tf.detect.pipeline.detect_corners`); a path loads its network alone.
    backend : ``"auto"`` (a name loads the shipped ``.tflite`` on the LiteRT runtime, a path by
        its suffix), ``"runtime"`` or ``"keras"`` (a name loads ``models/<name>.keras``; for
        training and tests). Both kinds of file are checked against their recorded sha256
        (``<file>.sha256``, when there is one); ``.keras`` files load with ``safe_mode=True`` and
        import TensorFlow.
    Returns a :class:`aicalib_tf.cnn.runtime.RuntimeModel` or a ``keras.Model``, either with
    ``aicalib_path``. Raises ``FileNotFoundError`` for a missing file and ``ValueError`` for a
    corrupt or incompatible one, in one line naming the path (and the expected sha256), and
    ``ImportError`` naming what to install for a ``.keras`` model without TensorFlow.
    """
    if backend not in ("auto", "runtime", "keras"):
        raise ValueError(f"backend must be auto, runtime or keras, got {backend!r}")
    path = _resolve(weights, "keras" if backend == "keras" or compile else "runtime")
    if path.suffix == ".tflite":
        if compile:
            raise ValueError(f"compile=True needs a .keras model, got {path}")
        from aicalib_tf.cnn.runtime import load_runtime

        model = load_runtime(path)
        if isinstance(weights, str) and weights in QUICK_NETWORKS:  # a shipped detector network: its quick passes' one
            model.quick = load_runtime(_resolve(QUICK_NETWORKS[weights], "runtime"))
        return model
    check_model_file(path)  # missing, or not the file recorded in <file>.sha256: one line naming both
    try:
        from aicalib_tf.cnn.keras_model import load_keras
    except ImportError as exc:
        raise ImportError(f"cannot load {path}: {KERAS_HINT} ({exc})") from None
    return load_keras(path, compile=compile)
