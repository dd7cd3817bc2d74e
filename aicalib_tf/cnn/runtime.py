"""The shipped corner CNNs on the LiteRT interpreter: detection without TensorFlow.

``python -m aicalib_tf.export`` writes ``models/default.tflite`` (the corner-map model, float32,
any H×W input) and ``models/report.tflite`` (the patch classifier), each with its sha256 in
``models/<name>.tflite.sha256``. :class:`RuntimeModel` runs one of them with
``ai_edge_litert.interpreter.Interpreter`` (XNNPACK, float32): it matches the Keras model to
about 1e-6 in corner weight and gives the same detections (measured in models/MODEL_CARD.md).

One interpreter per input shape, the ``MAX_SHAPES`` most recently used kept (at most
``MAX_PIXELS`` input values together, the newest always): re-planning an
interpreter for a new size (``resize_tensor_input`` and ``allocate_tensors``, which re-applies the
XNNPACK delegate) costs 10–30 ms at 640×480 on this project's 2-core CPU, more than the 8 ms call
itself, while a new interpreter costs about 0.5 ms. A stream of one image size alternating with
zoomed regions (:mod:`aicalib_tf.detect.chessboard.zoom`) or a pyramid's scales then never re-plans the
image size's interpreter.
Threads: ``AICALIB_THREADS`` if set, else 2 where the machine has two or more cores (measured on
this project's 2-core CPU: 640×480 11.4 ms on 2 threads against 17.8 ms on 1; 1920×1080 62 against
119 ms). A process pool of detection workers sets it to 1 per worker.

Nothing here imports TensorFlow or Keras.
"""

from __future__ import annotations

import os
import threading
from collections import OrderedDict
from pathlib import Path

import numpy as np

from aicalib_tf.cnn.spec import check_model_file, expected_sha256

__all__ = ["RuntimeModel", "load_runtime", "expected_sha256", "default_threads", "THREADS_ENV"]

THREADS_ENV = "AICALIB_THREADS"
MAX_SHAPES = 4  # interpreters kept per model, one per input shape, least recently used dropped first
MAX_PIXELS = 4_000_000  # and together planned for at most this many input values (each holds its activations)


def default_threads() -> int:
    """Interpreter threads: ``AICALIB_THREADS``, else min(2, cores)."""
    env = os.environ.get(THREADS_ENV, "").strip()
    if env:
        return max(1, int(env))
    return max(1, min(2, os.cpu_count() or 1))


class RuntimeModel:
    """A corner model on the LiteRT interpreter.

    kind : ``"map"`` (corner map, (1, H, W, 1) -> (1, H/4, W/4, 3)) or ``"patch"``
    ((B, 32, 32, 1) -> (B, 1)); aicalib_path : the .tflite file it came from. quick : None, or the
    smaller network the detector's quick passes run instead of this one
    (:func:`aicalib_tf.cnn.model.load_model` sets it for the shipped detector networks).
    """

    def __init__(self, path: str | os.PathLike, *, num_threads: int | None = None):
        from ai_edge_litert.interpreter import Interpreter

        self.aicalib_path = str(path)
        self.quick: RuntimeModel | None = None
        self.num_threads = num_threads or default_threads()
        self._new = lambda: Interpreter(model_path=str(path), num_threads=self.num_threads)
        try:
            first = self._new()
        except ValueError as exc:  # LiteRT's message names no file
            raise ValueError(f"{path}: not a readable .tflite model ({exc})") from None
        self._lock = threading.Lock()  # an interpreter runs one call at a time
        inp = first.get_input_details()[0]
        out = first.get_output_details()[0]
        self._in, self._out = inp["index"], out["index"]
        sig = tuple(int(v) for v in inp.get("shape_signature", inp["shape"]))
        if len(sig) == 4 and sig[3] == 1 and sig[1] == -1 and len(out["shape"]) == 4 and out["shape"][3] == 3:
            self.kind = "map"
        elif len(sig) == 4 and tuple(sig[1:]) == (32, 32, 1) and len(out["shape"]) == 2:
            self.kind = "patch"
        else:
            raise ValueError(f"incompatible model {path}: input {sig}, output {tuple(out['shape'])}")
        self._by_shape: OrderedDict[tuple, object] = OrderedDict()  # input shape -> interpreter planned for it
        self._spare = first  # not planned yet: serves the first shape
        self.name = Path(path).stem

    def __repr__(self) -> str:
        return f"RuntimeModel({self.aicalib_path!r}, kind={self.kind!r}, threads={self.num_threads})"

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """The raw network on a float32 batch ``x`` (standardised input); returns a fresh array."""
        x = np.ascontiguousarray(x, dtype=np.float32)
        with self._lock:
            interp = self._interpreter(x.shape)
            interp.set_tensor(self._in, x)
            interp.invoke()
            return interp.get_tensor(self._out).copy()

    def _interpreter(self, shape: tuple):
        """The interpreter planned for input ``shape`` (made and planned on first use; LRU of ``MAX_SHAPES``)."""
        interp = self._by_shape.pop(shape, None)
        if interp is None:
            interp, self._spare = self._spare or self._new(), None
            interp.resize_tensor_input(self._in, list(shape), strict=False)
            interp.allocate_tensors()
        self._by_shape[shape] = interp
        while len(self._by_shape) > 1 and (len(self._by_shape) > MAX_SHAPES or sum(
                int(np.prod(k)) for k in self._by_shape) > MAX_PIXELS):
            self._by_shape.popitem(last=False)
        return interp

    def planned_shapes(self) -> list[tuple]:
        """The input shapes with a planned interpreter kept, least recently used first."""
        return list(self._by_shape)


def load_runtime(path: str | os.PathLike, *, check_sha256: bool = True, num_threads: int | None = None) -> RuntimeModel:
    """Load a .tflite corner model, checking its sha256 against ``<file>.sha256`` when there is one.

    Raises FileNotFoundError / ValueError with one line naming the file and the expected sha256.
    """
    path = Path(path)
    want = check_model_file(path, check_sha256=check_sha256)
    expect = f" (expected sha256 {want})" if want else ""
    try:
        return RuntimeModel(path, num_threads=num_threads)
    except ValueError:
        raise
    except Exception as exc:  # the interpreter raises RuntimeError/ValueError for a bad flatbuffer
        raise ValueError(f"cannot load model {path}{expect}: {type(exc).__name__}: {exc}") from None
