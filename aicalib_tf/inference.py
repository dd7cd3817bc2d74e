"""Run a corner CNN on a whole image: image -> corner points with weights (Keras).

Both model kinds give the same thing, points (N, 2) float32 (x, y) px and weights (N,) in [0, 1]:

* a corner-map model (``default``) runs once on the whole image and its map is decoded
  (:func:`aicalib_tf.corner_map.decode_map`);
* a patch classifier (``report``) scores 32×32 patches around saddle-point candidates
  (:func:`aicalib_tf.candidates.saddle_points`); its points are those pixel positions.
"""

from __future__ import annotations

import cv2
import numpy as np
import tensorflow as tf

from .candidates import saddle_points
from .corner_map import decode_map, padded_shape, standardize
from .model import PATCH_SIZE, model_kind

__all__ = ["corner_map", "corner_points", "patch_weights", "extract_patches"]

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


class _MapFns:
    """Concrete corner-map functions by input size (H, W), or (None, None) for any size."""

    def __init__(self):
        self.fns: dict = {}


def _map_fn(model, shape: tuple[int, int]):
    """The model as a concrete function for one (1, H, W, 1) float32 input size, kept on the model.

    Calling a concrete function skips ``tf.function``'s per-call dispatch (about 0.5 ms), and a
    graph traced for a fixed size runs a little faster than one for any size. Beyond
    ``MAX_MAP_SHAPES`` sizes, one function for any size serves the rest (its outputs are the same).
    """
    holder = getattr(model, _MAP_FNS_ATTR, None)
    if holder is None:  # not a dict: Keras would wrap one in a tracked copy
        holder = _MapFns()
        setattr(model, _MAP_FNS_ATTR, holder)
    fns = holder.fns
    fn = fns.get(shape)
    if fn is None:
        dims = shape if len(fns) < MAX_MAP_SHAPES else (None, None)
        fn = fns.get(dims)
        if fn is None:
            traced = tf.function(lambda x: model(x, training=False))
            fn = traced.get_concrete_function(tf.TensorSpec((1, *dims, 1), tf.float32))
            fns[dims] = fn
    return fn


def corner_map(model, gray: np.ndarray) -> np.ndarray:
    """The corner map of a grey image.

    gray : (H, W) float or uint8. The standardised image is padded (edge-replicated) at the
    bottom and right to multiples of 4. Returns (ceil(H/4), ceil(W/4), 3) float32.
    """
    g = standardize(gray)
    h, w = g.shape
    ph, pw = padded_shape(h, w)
    if (ph, pw) != (h, w):
        g = np.pad(g, ((0, ph - h), (0, pw - w)), mode="edge")
    out = _map_fn(model, (ph, pw))(tf.constant(g[None, :, :, None]))
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


def corner_points(model, gray: np.ndarray, threshold: float = 0.5, *, max_candidates: int = 800):
    """Corner points of an image by either model kind.

    gray : (H, W) float or uint8. threshold : minimum corner weight.
    max_candidates : patch classifiers only, how many saddle candidates to score.
    Returns points (N, 2) float32 (x, y) px and weights (N,) float32, strongest first.
    """
    if model_kind(model) == "map":
        return decode_map(corner_map(model, gray), threshold)
    cand = saddle_points(gray, max_points=max_candidates)
    w = patch_weights(model, gray, cand)
    keep = w >= threshold
    order = np.argsort(-w[keep], kind="stable")
    return cand[keep][order].astype(np.float32), w[keep][order]
