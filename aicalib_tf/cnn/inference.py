"""Run a corner CNN on a whole image: image -> corner points with weights (LiteRT runtime or Keras).

Both model kinds give the same thing, points (N, 2) float32 (x, y) px and weights (N,) in [0, 1]:

* a corner-map model (``default``) runs once on the whole image and its map is decoded
  (:func:`aicalib_tf.cnn.corner_map.decode_map`);
* a patch classifier (``report``) scores 32×32 patches around saddle-point candidates
  (:func:`aicalib_tf.detect.corners.candidates.saddle_points`); its points are those pixel positions.

Precision. On a CPU with native bfloat16 arithmetic (x86 ``avx512_bf16`` or ``amx_bf16``) and
TensorFlow's oneDNN kernels on (the default), the corner map is computed in bfloat16: the model's
layers but the last run under Keras's ``mixed_bfloat16`` policy while its graph is traced (the
weights stay float32 and are read afresh on every call; the output stays float32). On this
project's 2-core CPUs a 640×480 map takes about 2.5–4 ms instead of 4–7 ms; corner weights differ
from float32's by about 0.01 and subpixel offsets by under 0.07 px, before the refinement on the
image, which does not use them. Elsewhere, where a bfloat16 run fails, and with the environment
variable ``AICALIB_PRECISION=float32``, float32 is used (``bfloat16`` asks for it regardless).

Memory. A network run holds about 150 bytes of activations per input pixel (the shipped
``default`` on LiteRT: 720 MB at 2048×2048), and the runtime's planner fails beyond a few tens
of megapixels. An image of more than ``MAX_RUN_PIXELS`` is therefore run in windows of at most
``TILE``×``TILE`` px, standardised by the whole image's mean and deviation, each keeping the map
cells at least ``TILE_MARGIN`` px inside it (or on the image's border): the networks see no further
than 16 px, so the map is the one a single run would give, bit for bit (measured on the shipped
networks). The map itself is (H/4, W/4, 3) float32, 0.75 byte per pixel. The weak points are told
from the strong ones through :func:`aicalib_tf.geometry.points.any_within` (a k-d tree for large sets).
"""

from __future__ import annotations

import functools
import os

import cv2
import numpy as np

from aicalib_tf.cnn.corner_map import STRIDE, decode_map, network_input, padded_shape, standardize
from aicalib_tf.cnn.spec import PATCH_SIZE, model_kind
from aicalib_tf.detect.corners.candidates import saddle_points
from aicalib_tf.geometry.points import any_within

__all__ = ["corner_map", "corner_points", "weak_corner_points", "patch_weights", "extract_patches", "native_bfloat16", "resolve_precision"]

PRECISION_ENV = "AICALIB_PRECISION"
MAX_RUN_PIXELS = 2_200_000  # network input pixels in one run (a 1920×1080 image is one); larger images run in tiles
TILE = 1024  # px: the side of a tile's window (a multiple of the map's stride; 1024² runs fastest per pixel)
TILE_MARGIN = 32  # px: context kept on each inner side of a tile (the networks see 16 px at most)


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
    if _is_keras(model):
        from aicalib_tf.cnn.keras_inference import run_map

        want = resolve_precision(precision)

        def run(x):
            return run_map(model, x, want)
    else:
        def run(x):
            return model(x)[0]
    h, w = np.shape(gray)[:2]
    ph, pw = padded_shape(h, w)
    if ph * pw <= MAX_RUN_PIXELS:
        return run(network_input(gray))
    return _tiled_map(run, gray)


def _windows(length: int) -> list[tuple[int, int, int]]:
    """Along one padded axis of ``length`` px: (window start, kept start, kept end) per tile, windows
    ``TILE`` long (or the whole axis), kept parts abutting, ``TILE_MARGIN`` px inside any inner window edge."""
    if length <= TILE:
        return [(0, 0, length)]
    step = TILE - 2 * TILE_MARGIN
    return [(min(max(k - TILE_MARGIN, 0), length - TILE), k, min(k + step, length)) for k in range(0, length, step)]


def _image_stats(g: np.ndarray) -> tuple[float, float]:
    """The whole image's mean and standard deviation, as :func:`standardize` takes them, without a float copy of it."""
    from aicalib_tf.cnn.corner_map_kernels import mean_std

    if g.dtype == np.float32 and g.flags.c_contiguous:
        return mean_std(g)
    rows = max(1, (1 << 22) // max(g.shape[1], 1))  # blocks of about 16 MB as float32
    blocks = range(0, g.shape[0], rows)
    total = sum(float(np.sum(g[y:y + rows], dtype=np.float64)) for y in blocks)
    mean = total / max(g.size, 1)
    sq = sum(float(np.sum((np.asarray(g[y:y + rows], np.float64) - mean) ** 2)) for y in blocks)
    return mean, float(np.sqrt(sq / max(g.size, 1)))


def _tiled_map(run, gray: np.ndarray) -> np.ndarray:
    """The corner map of a large image from windows of it (module docstring): (ceil(H/4), ceil(W/4), 3) float32.

    run : ``run(x (1, h, w, 1) float32) -> (h/4, w/4, 3)``. Only one window's input and activations
    exist at a time.
    """
    g = np.asarray(gray)
    h, w = g.shape
    ph, pw = padded_shape(h, w)
    mean, std = _image_stats(g)
    out = None
    for wy, ky0, ky1 in _windows(ph):
        for wx, kx0, kx1 in _windows(pw):
            sy, sx = min(TILE, ph), min(TILE, pw)
            body = standardize(g[wy:min(wy + sy, h), wx:min(wx + sx, w)], mean, std)
            x = np.pad(body, ((0, sy - body.shape[0]), (0, sx - body.shape[1])), mode="edge")  # as network_input pads
            m = run(x[None, :, :, None])
            if out is None:
                out = np.empty((ph // STRIDE, pw // STRIDE, m.shape[2]), np.float32)
            out[ky0 // STRIDE:ky1 // STRIDE, kx0 // STRIDE:kx1 // STRIDE] = \
                m[(ky0 - wy) // STRIDE:(ky1 - wy) // STRIDE, (kx0 - wx) // STRIDE:(kx1 - wx) // STRIDE]
    return out


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
            if len(low) and len(pts):  # not within 2.5 px of a strong point (any number of points: a k-d tree)
                low = low[~any_within(low, pts, 2.5, strict=True)]
            memo.append(low.astype(np.float32).reshape(-1, 2))
        return memo[0]
    return pts, scores, weak_points
