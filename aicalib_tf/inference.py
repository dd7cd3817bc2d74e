"""Run a corner CNN on a whole image: image -> corner points with weights (Keras).

Both model kinds give the same thing, points (N, 2) float32 (x, y) px and weights (N,) in [0, 1]:

* a corner-map model (``default``) runs once on the whole image and its map is decoded
  (:func:`aicalib_tf.corner_map.decode_map`);
* a patch classifier (``report``) scores 32×32 patches around saddle-point candidates
  (:func:`aicalib_tf.candidates.saddle_points`); its points are those pixel positions.

Precision. On a CPU with native bfloat16 arithmetic (x86 ``avx512_bf16`` or ``amx_bf16``), a
corner map is computed by a bfloat16 twin of the model (:func:`inference_model`: the same
weights, every layer but the last computing in bfloat16; the output stays float32). On this
project's 2-core CPU that runs a 640×480 image in about 2.5 ms instead of 4 ms; its corner
weights differ from float32's by about 0.01 and its subpixel offsets by under 0.07 px, before
the refinement on the image, which does not use them. Elsewhere (also with oneDNN turned off by
``TF_ENABLE_ONEDNN_OPTS=0``, where bfloat16 is emulated and slower) and with the environment
variable ``AICALIB_PRECISION=float32``, float32 is used (``bfloat16`` forces the twin, for tests).
"""

from __future__ import annotations

import functools
import os

import cv2
import keras
import numpy as np
import tensorflow as tf

from .candidates import saddle_points
from .corner_map import decode_map, padded_shape, standardize
from .model import PATCH_SIZE, model_kind

__all__ = ["corner_map", "corner_points", "patch_weights", "extract_patches", "inference_model", "native_bfloat16",
           "resolve_precision"]

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


PRECISION_ENV = "AICALIB_PRECISION"


@functools.lru_cache(maxsize=1)
def native_bfloat16() -> bool:
    """Whether this CPU has native bfloat16 arithmetic (Linux x86: ``avx512_bf16`` or ``amx_bf16`` in /proc/cpuinfo)."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("flags"):
                    flags = set(line.split(":", 1)[1].split())
                    return bool(flags & {"avx512_bf16", "amx_bf16"})
    except OSError:
        pass
    return False


def resolve_precision(precision: str | None = None) -> str:
    """``"float32"`` or ``"bfloat16"``: ``precision`` if given, else ``AICALIB_PRECISION``, else
    (``auto``) bfloat16 where the CPU has it natively."""
    want = precision if precision is not None else os.environ.get(PRECISION_ENV, "auto")
    want = want.strip().lower() or "auto"
    if want not in ("auto", "float32", "bfloat16"):
        raise ValueError(f"precision ({PRECISION_ENV}) must be auto, float32 or bfloat16, got {want!r}")
    if want == "auto":
        # bfloat16 is only fast through oneDNN (TensorFlow's default on x86 Linux); without it,
        # TensorFlow's own kernels emulate it (measured: 17 ms a 640x480 map, against 13 in float32)
        onednn = os.environ.get("TF_ENABLE_ONEDNN_OPTS", "1").strip() not in ("0", "false", "False")
        return "bfloat16" if native_bfloat16() and onednn else "float32"
    return want


def inference_model(model, precision: str | None = None):
    """The model that computes corner maps: ``model`` itself, or its bfloat16 twin (module docstring).

    precision : see :func:`resolve_precision`. The twin is rebuilt from ``model``'s config with
    every layer but the last set to Keras's ``mixed_bfloat16`` policy (float32 weights, bfloat16
    arithmetic) and given ``model``'s weights when first asked for; it is kept on ``model`` and
    does not follow later changes to its weights (training validates in float32). A model that
    cannot be rebuilt so is used as it is.
    """
    if resolve_precision(precision) == "float32" or not isinstance(model, keras.Sequential):
        return model
    holder = _holder(model)
    if holder.twin is None:
        cfg = model.get_config()
        layers = cfg["layers"]
        for layer in layers[:-1]:
            if layer.get("class_name") != "InputLayer" and "dtype" in layer.get("config", {}):
                layer["config"]["dtype"] = "mixed_bfloat16"
        try:
            twin = keras.Sequential.from_config(cfg)
            twin.set_weights(model.get_weights())
        except Exception:  # any layer Keras cannot rebuild so: the model as it is, in float32
            twin = model
        holder.twin = twin
    return holder.twin


class _MapFns:
    """What a model keeps for corner maps: concrete functions by input size (H, W), or (None,
    None) for any size, and the model that computes them (:func:`inference_model`)."""

    def __init__(self):
        self.fns: dict = {}
        self.twin = None


def _holder(model) -> _MapFns:
    holder = getattr(model, _MAP_FNS_ATTR, None)
    if holder is None:  # not a dict or a layer: Keras would track it as part of the model
        holder = _MapFns()
        setattr(model, _MAP_FNS_ATTR, holder)
    return holder


def _map_fn(model, shape: tuple[int, int], precision: str):
    """The model (at ``precision``) as a concrete function for one (1, H, W, 1) float32 input size, kept on the model.

    Calling a concrete function skips ``tf.function``'s per-call dispatch (about 0.5 ms), and a
    graph traced for a fixed size runs a little faster than one for any size. Beyond
    ``MAX_MAP_SHAPES`` sizes, one function for any size serves the rest (its outputs are the same).
    """
    fns = _holder(model).fns
    fn = fns.get((precision, shape))
    if fn is None:
        dims = shape if len(fns) < MAX_MAP_SHAPES else (None, None)
        fn = fns.get((precision, dims))
        if fn is None:
            net = inference_model(model, precision)
            traced = tf.function(lambda x: net(x, training=False))
            fn = traced.get_concrete_function(tf.TensorSpec((1, *dims, 1), tf.float32))
            fns[(precision, dims)] = fn
    return fn


def corner_map(model, gray: np.ndarray, *, precision: str | None = None) -> np.ndarray:
    """The corner map of a grey image.

    gray : (H, W) float or uint8. The standardised image is padded (edge-replicated) at the
    bottom and right to multiples of 4. precision : ``"float32"``, ``"bfloat16"`` or ``"auto"``
    (default: ``AICALIB_PRECISION``, else auto; see the module docstring).
    Returns (ceil(H/4), ceil(W/4), 3) float32.
    """
    g = standardize(gray)
    h, w = g.shape
    ph, pw = padded_shape(h, w)
    if (ph, pw) != (h, w):
        g = np.pad(g, ((0, ph - h), (0, pw - w)), mode="edge")
    out = _map_fn(model, (ph, pw), resolve_precision(precision))(tf.constant(g[None, :, :, None]))
    return out.numpy()[0]


def extract_patches(image: np.ndarray, points: np.ndarray) -> np.ndarray:
    """32×32 patches with pixel ``(x, y)`` at patch index (16, 16); outside the image reads as edge.

    image : (H, W) float32 or uint8. points : (N, 2) int (x, y). Returns (N, 32, 32) of image's dtype.
    """
    pts = np.asarray(points, dtype=np.int64).reshape(-1, 2)
    out = np.empty((len(pts), PATCH_SIZE, PATCH_SIZE), image.dtype)
    size = (PATCH_SIZE, PATCH_SIZE)
    for k, (x, y) in enumerate(pts):
        # patch pixel i reads source x − 16 + i: centre (x − 0.5) is exact, so no interpolation happens
        out[k] = cv2.getRectSubPix(image, size, (float(x) - 0.5, float(y) - 0.5))
    return out


def patch_weights(model, gray: np.ndarray, points: np.ndarray, batch_size: int = 1024) -> np.ndarray:
    """Corner weights (N,) float32 of a patch classifier at pixel ``points`` (N, 2) int (x, y)."""
    g = standardize(gray)
    if len(points) == 0:
        return np.zeros(0, np.float32)
    fn = _predict_fn(model)
    out = []
    for start in range(0, len(points), batch_size):
        patches = extract_patches(g, points[start : start + batch_size])
        out.append(np.asarray(fn(tf.constant(patches[..., None])))[:, 0])
    return np.concatenate(out).astype(np.float32)


def corner_points(model, gray: np.ndarray, threshold: float = 0.5, *, max_candidates: int = 800,
                  precision: str | None = None):
    """Corner points of an image by either model kind.

    gray : (H, W) float or uint8. threshold : minimum corner weight.
    max_candidates : patch classifiers only, how many saddle candidates to score.
    precision : corner-map models only, see :func:`corner_map` (patch classifiers run in float32).
    Returns points (N, 2) float32 (x, y) px and weights (N,) float32, strongest first.
    """
    if model_kind(model) == "map":
        return decode_map(corner_map(model, gray, precision=precision), threshold)
    cand = saddle_points(gray, max_points=max_candidates)
    w = patch_weights(model, gray, cand)
    keep = w >= threshold
    order = np.argsort(-w[keep], kind="stable")
    return cand[keep][order].astype(np.float32), w[keep][order]
