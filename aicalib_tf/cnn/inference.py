"""Run a corner CNN on a whole image: image -> corner points with weights (LiteRT runtime or Keras).

Both model kinds give the same thing, points (N, 2) float32 (x, y) px and weights (N,) in [0, 1]:

* a corner-map model (``default``) runs once on the whole image and its map is decoded
  (:func:`aicalib_tf.cnn.corner_map.decode_map`);
* a patch classifier (``report``) scores 32×32 patches around saddle-point candidates
  (:func:`aicalib_tf.detect.candidates.saddle_points`); its points are those pixel positions.

Precision. On a CPU with native bfloat16 arithmetic (x86 ``avx512_bf16`` or ``amx_bf16``) and
TensorFlow's oneDNN kernels on (the default), the corner map is computed in bfloat16: the model's
layers but the last run under Keras's ``mixed_bfloat16`` policy while its graph is traced (the
weights stay float32 and are read afresh on every call; the output stays float32). On this
project's 2-core CPUs a 640×480 map takes about 2.5–4 ms instead of 4–7 ms; corner weights differ
from float32's by about 0.01 and subpixel offsets by under 0.07 px, before the refinement on the
image, which does not use them. Elsewhere, where a bfloat16 run fails, and with the environment
variable ``AICALIB_PRECISION=float32``, float32 is used (``bfloat16`` asks for it regardless).
"""

from __future__ import annotations

import functools
import os

import cv2
import numpy as np

from aicalib_tf.cnn.corner_map import decode_map, network_input, standardize
from aicalib_tf.cnn.spec import PATCH_SIZE, model_kind
from aicalib_tf.detect.candidates import saddle_points
from aicalib_tf.geometry.points import sq_distances

__all__ = ["corner_map", "corner_points", "weak_corner_points", "patch_weights", "extract_patches", "native_bfloat16", "resolve_precision"]

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


def _onednn_on() -> bool:
    """Whether TensorFlow runs its CPU kernels through oneDNN (on by default on x86 Linux; read as TensorFlow reads it)."""
    return os.environ.get("TF_ENABLE_ONEDNN_OPTS", "1").strip().lower() not in ("0", "false")


def resolve_precision(precision: str | None = None) -> str:
    """``"float32"`` or ``"bfloat16"``: ``precision`` if given, else ``AICALIB_PRECISION``, else
    (``auto``) bfloat16 where the CPU has it natively and oneDNN is on."""
    want = precision if precision is not None else os.environ.get(PRECISION_ENV, "auto")
    want = want.strip().lower() or "auto"
    if want not in ("auto", "float32", "bfloat16"):
        raise ValueError(f"precision ({PRECISION_ENV}) must be auto, float32 or bfloat16, got {want!r}")
    if want == "auto":
        # bfloat16 is only fast through oneDNN; without it TensorFlow's own kernels emulate it
        # (measured: 17 ms a 640x480 map, against 13 ms in float32)
        return "bfloat16" if native_bfloat16() and _onednn_on() else "float32"
    return want


def _is_keras(model) -> bool:
    return hasattr(model, "input_shape")  # a keras.Model; a RuntimeModel has none


def corner_map(model, gray: np.ndarray, *, precision: str | None = None) -> np.ndarray:
    """The corner map of a grey image.

    gray : (H, W) float or uint8. The standardised image is padded (edge-replicated) at the
    bottom and right to multiples of 4. precision (Keras models only; the runtime is float32):
    ``"float32"``, ``"bfloat16"`` or ``"auto"`` (default: ``AICALIB_PRECISION``, else auto; see
    the module docstring). Returns (ceil(H/4), ceil(W/4), 3) float32.
    """
    x = network_input(gray)
    if not _is_keras(model):
        return model(x)[0]
    from aicalib_tf.cnn.keras_inference import run_map

    return run_map(model, x, resolve_precision(precision))


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
    if _is_keras(model):
        from aicalib_tf.cnn.keras_inference import run_patches
    else:
        def run_patches(m, p):
            return m(p)[:, 0]
    out = []
    for start in range(0, len(points), batch_size):
        patches = extract_patches(g, points[start : start + batch_size])
        out.append(run_patches(model, patches[..., None]))
    return np.concatenate(out).astype(np.float32)


def corner_points(model, gray: np.ndarray, threshold: float = 0.5, *, max_candidates: int = 800,
                  precision: str | None = None):
    """Corner points of an image by either model kind.

    gray : (H, W) float or uint8. threshold : minimum corner weight.
    max_candidates : patch classifiers only, how many saddle candidates to score.
    precision : corner-map models only, see :func:`corner_map` (patch classifiers run in float32).
    Returns points (N, 2) float32 (x, y) px and weights (N,) float32, strongest first.
    """
    pts, scores, _ = weak_corner_points(model, gray, threshold, threshold, max_candidates=max_candidates,
                                        precision=precision)
    return pts, scores


def weak_corner_points(model, gray: np.ndarray, threshold: float = 0.5, weak: float = 0.25, *,
                       max_candidates: int = 800, precision: str | None = None):
    """:func:`corner_points` at ``threshold`` and, from the same network run, the weaker points.

    weak : the lower weight; points weighing at least this but under ``threshold`` and not within
    2.5 px of a point at ``threshold`` are the weak ones.
    Returns points (N, 2) float32, weights (N,) float32 (as :func:`corner_points`) and
    ``weak_points() -> (K, 2) float32`` (x, y) px, strongest first, worked out on the first call.
    """
    if model_kind(model) == "map":
        cmap = corner_map(model, gray, precision=precision)
        pts, scores = decode_map(cmap, threshold)

        def lower():
            return decode_map(cmap, min(weak, threshold))
    else:
        cand = saddle_points(gray, max_points=max_candidates)
        w = patch_weights(model, gray, cand)
        order = np.argsort(-w, kind="stable")
        cand, w = cand[order].astype(np.float32), w[order]
        pts, scores = cand[w >= threshold], w[w >= threshold]

        def lower():
            return cand[w >= min(weak, threshold)], w[w >= min(weak, threshold)]
    memo = []

    def weak_points() -> np.ndarray:
        if not memo:
            low, low_scores = lower()
            low = low[low_scores < threshold]
            if len(low) and len(pts):
                d2 = sq_distances(low, pts)
                low = low[d2.min(axis=1) >= 2.5**2]
            memo.append(low.astype(np.float32).reshape(-1, 2))
        return memo[0]
    return pts, scores, weak_points
