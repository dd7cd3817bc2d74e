"""The Keras side of the corner CNNs: architectures, the loss, training-time saving and Keras loading.

Imported only to build, train, export, or when the user passes a ``.keras`` model
(:func:`aicalib_tf.cnn.model.load_model` with a ``.keras`` path or ``backend="keras"``): it imports
Keras (and so TensorFlow). See :mod:`aicalib_tf.cnn.model` for the architectures.
"""

from __future__ import annotations

import os
import tempfile
import zipfile
from pathlib import Path

import keras
from keras import layers, ops

from aicalib_tf.cnn.spec import ARCHITECTURES, PATCH_SIZE, model_kind

__all__ = ["build_model", "compile_model", "corner_map_loss", "CornerMapLoss", "load_keras", "save_model"]

POSITIVE_WEIGHT = 2.0  # corners fill ~1% of cells; up-weight them in the loss
OFFSET_WEIGHT = 4.0


def _report() -> keras.Sequential:
    conv = dict(kernel_size=3, padding="same", activation="relu")
    return keras.Sequential(
        [
            keras.Input((PATCH_SIZE, PATCH_SIZE, 1), name="patch"),
            layers.Conv2D(16, name="conv1", **conv),
            layers.MaxPooling2D(2, name="pool1"),
            layers.Conv2D(32, name="conv2", **conv),
            layers.MaxPooling2D(2, name="pool2"),
            layers.Conv2D(64, name="conv3", **conv),
            layers.MaxPooling2D(2, name="pool3"),
            layers.Conv2D(128, name="conv4", **conv),
            layers.MaxPooling2D(2, name="pool4"),
            layers.Flatten(name="flatten"),
            layers.Dense(64, activation="relu", name="dense1"),
            layers.Dense(1, activation="sigmoid", name="corner_weight"),
        ],
        name="report",
    )


def _default(conv1: int = 8, pre: int = 4, strided: bool = True, name: str = "default") -> keras.Sequential:
    """A corner-map network: ``conv1`` filters in the second 3×3 conv, and, when ``pre`` > 0, a 3×3
    conv of ``pre`` filters at full resolution before it. ``strided``: ``conv1`` computes at half
    resolution (stride 2) in place of conv + 2×2 max-pooling. The defaults build ``default``."""
    conv = dict(kernel_size=3, padding="same", activation="relu")
    extra = [layers.Conv2D(pre, name="conv0", **conv)] if pre else []
    first = ([layers.Conv2D(conv1, strides=2, name="conv1", **conv)] if strided
             else [layers.Conv2D(conv1, name="conv1", **conv), layers.MaxPooling2D(2, name="pool1")])
    return keras.Sequential(
        [
            keras.Input((None, None, 1), name="image"),
            *extra,
            *first,
            layers.Conv2D(16, name="conv2", **conv),
            layers.MaxPooling2D(2, name="pool2"),
            layers.Conv2D(32, name="conv3", **conv),
            layers.Conv2D(32, name="conv4", **conv),
            layers.Conv2D(32, name="conv5", **conv),
            layers.Conv2D(3, 1, activation="sigmoid", name="corner_map"),
        ],
        name=name,
    )


def _separable(widths: tuple[int, ...] = (16, 32, 32, 32), pre: int = 4, conv1: int = 8,
               name: str = "sep") -> keras.Sequential:
    """A depthwise-separable corner-map network: ``default``'s stem (a 3×3 conv of ``pre`` filters at
    full resolution when ``pre`` > 0, then a 3×3 conv of ``conv1`` filters at stride 2), then
    SeparableConv2D layers (3×3 depthwise + 1×1 pointwise, ReLU) of ``widths`` filters: the first at
    half resolution, then 2×2 max-pooling, the rest at quarter resolution; the same 1×1 sigmoid head
    (corner map at H/4 × W/4, 3 channels). Receptive field: 35 px with ``pre`` and four widths,
    33 + 8 per width beyond four without ``pre``."""
    conv = dict(kernel_size=3, padding="same", activation="relu")
    stem = [layers.Conv2D(pre, name="conv0", **conv)] if pre else []
    stem.append(layers.Conv2D(conv1, strides=2, name="conv1", **conv))
    body = [layers.SeparableConv2D(widths[0], name="sep2", **conv), layers.MaxPooling2D(2, name="pool2")]
    body += [layers.SeparableConv2D(w, name=f"sep{i}", **conv) for i, w in enumerate(widths[1:], start=3)]
    return keras.Sequential(
        [keras.Input((None, None, 1), name="image"), *stem, *body,
         layers.Conv2D(3, 1, activation="sigmoid", name="corner_map")],
        name=name,
    )


def _quick() -> keras.Sequential:
    """The quick pass's corner-map network: a 3×3 conv of 8 filters at stride 2, 2×2 max-pooling, then
    3×3 convs of 16, 32 and 32 filters at quarter resolution and ``default``'s 1×1 sigmoid head (corner
    map at H/4 × W/4). No full- or half-resolution layer past the first: 15,235 parameters, 72 M
    multiply-adds at 320×240 against default's 141.5 M, receptive field 29 px."""
    conv = dict(kernel_size=3, padding="same", activation="relu")
    return keras.Sequential(
        [
            keras.Input((None, None, 1), name="image"),
            layers.Conv2D(8, strides=2, name="conv1", **conv),
            layers.MaxPooling2D(2, name="pool1"),
            layers.Conv2D(16, name="conv2", **conv),
            layers.Conv2D(32, name="conv3", **conv),
            layers.Conv2D(32, name="conv4", **conv),
            layers.Conv2D(3, 1, activation="sigmoid", name="corner_map"),
        ],
        name="quick",
    )


def build_model(name: str = "default") -> keras.Sequential:
    """A fresh, untrained model: ``"default"`` or ``"report"`` (see the module docstring)."""
    builders = {
        "default": _default,
        "report": _report,
        # experimental variants of default, same corner-map output. default_v1: the default shipped
        # the earlier shipped stack (no full-resolution layer, conv1 + max-pooling); c12/c16: a wider conv1
        "default_v1": lambda: _default(pre=0, strided=False, name="default_v1"),
        "default_c12": lambda: _default(conv1=12, pre=0, strided=False, name="default_c12"),
        "default_c16": lambda: _default(conv1=16, pre=0, strided=False, name="default_c16"),
        "default_pre": lambda: _default(strided=False, name="default_pre"),
        # depthwise-separable variants, same corner-map output; multiply-adds at 320×240 (default: 141.5 M,
        # 24,739 parameters). sep: default's stem, separable 16/32/32/32: 28.3 M, 4,027 parameters, RF 35 px;
        # sep_s2: no full-resolution conv, separable 16/32/32/32/32: 27.7 M, 5,115 parameters, RF 41 px;
        # sep_w: sep with separable 24/48/48/48: 46.9 M, 7,755 parameters, RF 35 px;
        # sep_s2w: sep_s2 wider, conv1 16, separable 24/48/48/48/48: 59.6 M, 10,627 parameters, RF 41 px
        "sep": _separable,
        "sep_s2": lambda: _separable((16, 32, 32, 32, 32), pre=0, name="sep_s2"),
        "sep_w": lambda: _separable((24, 48, 48, 48), name="sep_w"),
        "sep_s2w": lambda: _separable((24, 48, 48, 48, 48), pre=0, conv1=16, name="sep_s2w"),
        "quick": _quick,
    }
    if name not in builders:
        raise ValueError(f"unknown architecture {name!r}; choose from: {', '.join(ARCHITECTURES)}")
    return builders[name]()


@keras.saving.register_keras_serializable(package="aicalib_tf")
class CornerMapLoss(keras.losses.Loss):
    """Loss for the corner map: a loss on the corner weight + L1 on the in-cell position.

    y_true, y_pred : (B, h, w, 3). The position term counts only cells that hold a corner.
    gamma > 0 : focal loss on the weight (easy cells count little), summed and divided by the
        number of corners. gamma = 0 : cross-entropy with positives weighted ``positive_weight``,
        averaged over cells.
    """

    def __init__(self, gamma: float = 2.0, positive_weight: float = POSITIVE_WEIGHT,
                 offset_weight: float = OFFSET_WEIGHT, name: str = "corner_map_loss", **kwargs):
        super().__init__(name=name, **kwargs)
        self.gamma, self.positive_weight, self.offset_weight = float(gamma), float(positive_weight), float(offset_weight)

    def call(self, y_true, y_pred):
        eps = 1e-6
        t, p = y_true[..., 0], ops.clip(y_pred[..., 0], eps, 1.0 - eps)
        l1 = ops.sum(ops.abs(y_true[..., 1:] - y_pred[..., 1:]), axis=-1)
        # divided by the corners of the global batch: under tf.distribute each replica returns its
        # share, the gradients are summed over the replicas, and the loss is the global batch's
        # whatever the replica count (Keras scales only per-sample losses by 1/replicas, not a scalar)
        pos = ops.maximum(_global_sum(ops.sum(t)), 1.0)
        offset = self.offset_weight * ops.sum(t * l1) / pos
        if self.gamma > 0:
            g = self.gamma
            focal = -(t * (1.0 - p) ** g * ops.log(p) + (1.0 - t) * p**g * ops.log(1.0 - p))
            return ops.sum(focal) / pos + offset
        bce = -(self.positive_weight * t * ops.log(p) + (1.0 - t) * ops.log(1.0 - p))
        return ops.mean(bce) + offset

    def get_config(self) -> dict:
        return {"name": self.name, "gamma": self.gamma, "positive_weight": self.positive_weight,
                "offset_weight": self.offset_weight}


def _global_sum(x):
    """``x`` summed over the replicas inside a ``tf.distribute`` replica context of several; else ``x``."""
    if keras.backend.backend() == "tensorflow":
        import tensorflow as tf

        ctx = tf.distribute.get_replica_context()
        if ctx is not None and ctx.num_replicas_in_sync > 1:
            return ctx.all_reduce("SUM", tf.stop_gradient(x))
    return x


def corner_map_loss(y_true, y_pred, gamma: float = 2.0):
    """Functional form of :class:`CornerMapLoss` (one scalar for the batch)."""
    return CornerMapLoss(gamma=gamma).call(y_true, y_pred)


def compile_model(model: keras.Model, learning_rate: float = 2e-3, *, focal_gamma: float = 2.0) -> keras.Model:
    """Attach the optimiser and the loss that suit the model's kind (see :class:`CornerMapLoss`)."""
    opt = keras.optimizers.Adam(learning_rate)
    if model_kind(model) == "map":
        model.compile(optimizer=opt, loss=CornerMapLoss(gamma=focal_gamma))
    else:
        model.compile(optimizer=opt, loss="binary_crossentropy", metrics=["accuracy"])
    return model


def load_keras(path: Path, *, compile: bool = False) -> keras.Model:
    """Load a ``.keras`` corner model with ``safe_mode=True`` (weights and a layer graph, never code).

    Raises ``FileNotFoundError`` for a missing file and ``ValueError`` for a corrupt or incompatible
    one, naming the path.
    """
    if not Path(path).is_file():
        raise FileNotFoundError(f"model file not found: {path}")
    if not zipfile.is_zipfile(path):
        raise ValueError(f"cannot load model {path}: not a Keras 3 .keras archive (corrupt or wrong format)")
    try:
        model = keras.saving.load_model(path, compile=compile, safe_mode=True)
    except Exception as exc:  # Keras raises many types for damaged archives
        raise ValueError(f"cannot load model {path}: {type(exc).__name__}: {exc}") from None
    if not isinstance(model, keras.Model):
        raise ValueError(f"cannot load model {path}: it holds a {type(model).__name__}, not a Keras model")
    try:
        model_kind(model)
    except ValueError as exc:
        raise ValueError(f"incompatible model {path}: {exc}") from None
    model.aicalib_path = str(path)  # where it came from, for reports and hashes
    return model


def save_model(model: keras.Model, path: str | os.PathLike) -> Path:
    """Save ``model`` to ``path`` (.keras) atomically: a temporary file, then a rename."""
    path = Path(path)
    if path.suffix != ".keras":
        raise ValueError(f"model path must end in .keras, got {path}")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.partial-", suffix=".keras", dir=path.parent)
    os.close(fd)
    try:
        model.save(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
