"""The Keras side of :mod:`aicalib_tf.cnn.inference`: a ``keras.Model`` run through TensorFlow.

Used only for a model loaded from a ``.keras`` file (training, export checks, tests, or a user's
``--model x.keras``); the shipped models run on :mod:`aicalib_tf.cnn.runtime` without TensorFlow.
See :mod:`aicalib_tf.cnn.inference` for the bfloat16 precision that this path can use.
"""

from __future__ import annotations

import threading

import keras
import numpy as np
import tensorflow as tf

__all__ = ["run_map", "run_patches"]

_FN_ATTR = "_aicalib_predict_fn"
_MAP_FNS_ATTR = "_aicalib_map_fns"
MAX_MAP_SHAPES = 16  # concrete corner-map functions kept per model, one per input size


def _predict_fn(model):
    """A traced inference function kept on the model (one trace serves every image size)."""
    fn = getattr(model, _FN_ATTR, None)
    if fn is None:
        fn = tf.function(lambda x: model(x, training=False), reduce_retracing=True)
        setattr(model, _FN_ATTR, fn)
    return fn


_TRACE_LOCK = threading.Lock()  # a bfloat16 trace changes the model's layer policies for a moment


def _trace(model, dims, precision: str):
    """A concrete function of ``model`` for (1, *dims, 1) float32 input, computing in ``precision``.

    For bfloat16, every layer but the last is switched to Keras's ``mixed_bfloat16`` policy
    (bfloat16 arithmetic on float32 weights) while the function is traced, then switched back:
    the graph reads the model's own weights, so it follows any later change to them, and the
    model itself is left as it was. The last layer keeps its policy, so the output stays float32.
    """
    traced = tf.function(lambda x: model(x, training=False))
    spec = tf.TensorSpec((1, *dims, 1), tf.float32)
    if precision == "float32":
        return traced.get_concrete_function(spec)
    with _TRACE_LOCK:
        layers = [layer for layer in model.layers[:-1] if hasattr(layer, "dtype_policy")]
        saved = [layer.dtype_policy for layer in layers]
        try:
            for layer in layers:
                layer.dtype_policy = keras.DTypePolicy("mixed_bfloat16")
            return traced.get_concrete_function(spec)
        finally:
            for layer, policy in zip(layers, saved):
                layer.dtype_policy = policy


class _MapFns:
    """What a model keeps for corner maps: concrete functions by (precision, (H, W)), or
    (precision, (None, None)) for any size; the (precision, (H, W)) asked for once so far; and
    whether bfloat16 failed to run (float32 then)."""

    def __init__(self):
        self.fns: dict = {}
        self.asked: set = set()
        self.no_bfloat16 = False


def _holder(model) -> _MapFns:
    holder = getattr(model, _MAP_FNS_ATTR, None)
    if holder is None:  # not a dict or a layer: Keras would track it as part of the model
        holder = _MapFns()
        setattr(model, _MAP_FNS_ATTR, holder)
    return holder


def _map_fn(model, shape: tuple[int, int], precision: str):
    """The model (at ``precision``) as a concrete function for one (1, H, W, 1) float32 input size, kept on the model.

    Calling a concrete function skips ``tf.function``'s per-call dispatch (about 0.5 ms), and a
    graph traced for a fixed size runs up to 5% faster than one for any size once both have
    seen that size (measured: 4.14 against 4.15 ms at 640×480, 3.11 against 3.25 ms at
    552×432); either pays 2–3 ms more on its first call at a size, while oneDNN sets up its
    kernels. A trace costs about 40 ms, so a size gets its own function on its second use: a
    folder of photos of one size is traced once, and the one-off sizes of enlarged regions
    (:mod:`aicalib_tf.detect.chessboard.zoom`) share the function for any size. Beyond ``MAX_MAP_SHAPES`` sizes per
    precision, that function serves the rest too (its outputs are the same).
    """
    holder = _holder(model)
    fns = holder.fns
    fn = fns.get((precision, shape))
    if fn is None:
        again = (precision, shape) in holder.asked
        holder.asked.add((precision, shape))
        sized = sum(1 for p, d in fns if p == precision and d != (None, None))
        dims = shape if again and sized < MAX_MAP_SHAPES else (None, None)
        fn = fns.get((precision, dims))
        if fn is None:
            fn = _trace(model, dims, precision)
            fns[(precision, dims)] = fn
    return fn


def _run_map(model, x, shape: tuple[int, int], precision: str):
    """The map of standardised input ``x``; a bfloat16 run that fails (oneDNN limited to an ISA
    without bfloat16, say) falls back to float32 for this model from then on."""
    holder = _holder(model)
    if precision == "bfloat16" and not holder.no_bfloat16:
        try:
            return _map_fn(model, shape, "bfloat16")(x)
        except (tf.errors.OpError, ValueError, TypeError):
            holder.no_bfloat16 = True
    return _map_fn(model, shape, "float32")(x)




def run_map(model, x: np.ndarray, precision: str) -> np.ndarray:
    """(h, w, 3) float32: the corner map of network input ``x`` (1, H, W, 1), in ``precision``."""
    return _run_map(model, tf.constant(x), tuple(x.shape[1:3]), precision).numpy()[0]


def run_patches(model, patches: np.ndarray) -> np.ndarray:
    """(N,) corner weights of standardised patches (N, 32, 32, 1)."""
    return np.asarray(_predict_fn(model)(tf.constant(patches)))[:, 0]
