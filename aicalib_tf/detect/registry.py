"""The detectors behind one interface: the CNN pipeline and OpenCV's two chessboard detectors.

Every detector is wrapped as ``f(uint8 (H, W) image) -> Found``, so that calibration, the
benchmark (:mod:`aicalib_tf.bench.runner`, which scores them) and the command lines run the CNN
pipeline and OpenCV's detectors on the same images in the same way.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from aicalib_tf.cnn.spec import DETECTOR_NETWORK

__all__ = ["DETECTORS", "Found", "make_detectors"]

DETECTORS = ("cnn", "report", "opencv", "opencv-sb")


class Found(NamedTuple):
    """One detector's answer on one image.

    corners : (N, 2) float64 (x, y) px (N = 0 when nothing was found).
    ids : (N, 2) int (col, row). complete : a full board (N = cols·rows).
    why : when nothing was found, why, if the detector says (the CNN's ``Detection.reason``).
    relative : the ids are relative to the visible grid (``make_detectors(..., relative=True)``).
    sigmas : (N,) float32 px, each corner's σ (:attr:`aicalib_tf.detect.detection.Detection.sigmas`), or
        None (the OpenCV detectors).
    """

    corners: np.ndarray
    ids: np.ndarray
    complete: bool
    why: str = ""
    relative: bool = False
    sigmas: np.ndarray | None = None


_NOTHING = Found(np.zeros((0, 2)), np.zeros((0, 2), np.int64), False)


def make_detectors(names, pattern: tuple[int, int], model: str = DETECTOR_NETWORK, *,
                   relative: bool = False) -> tuple[dict[str, Callable], dict]:
    """Build the detectors: ``{name: f(uint8 (H, W) image) -> Found}`` and their provenance.

    names : subset of :data:`DETECTORS`. model : the cnn detector's weights (name or .keras path).
    relative : the CNN detectors also return grids with ids relative to them (for calibration;
    :func:`aicalib_tf.detect.pipeline.detect_corners`).
    Returns (detectors, info) where info maps a CNN detector to its model path and sha256.
    Raises ValueError for an unknown name, FileNotFoundError/ValueError for a bad model.
    """
    from aicalib_tf.detect.chessboard.board_order import full_board_ids
    from aicalib_tf.detect.opencv import opencv_classic, opencv_sb

    unknown = [n for n in names if n not in DETECTORS]
    if unknown or not names:
        raise ValueError(f"unknown detector(s) {', '.join(unknown) or '(none given)'}; choose from {', '.join(DETECTORS)}")
    ids_full = full_board_ids(pattern).astype(np.int64)
    dets, info = {}, {}

    def cnn(m):
        from aicalib_tf.detect.pipeline import detect_corners

        def f(img):
            d = detect_corners(img, pattern, model=m, relative=relative)
            if not d.found:
                return _NOTHING._replace(why=d.reason)
            return Found(d.corners.astype(np.float64), d.ids.astype(np.int64), bool(d.complete), relative=d.relative,
                         sigmas=d.sigmas)
        return f

    def cv(fn):
        def f(img):
            ok, c = fn(img, pattern)
            return Found(np.asarray(c, np.float64).reshape(-1, 2), ids_full, True) if ok else _NOTHING
        return f

    for n in names:
        if n in ("cnn", "report"):
            from aicalib_tf.cnn.model import file_sha256, load_model

            m = load_model(model if n == "cnn" else "report")
            info[n] = {"model": str(m.aicalib_path), "sha256": file_sha256(m.aicalib_path)}
            dets[n] = cnn(m)
        elif n == "opencv":
            dets[n] = cv(opencv_classic)
        else:
            dets[n] = cv(opencv_sb)
    return dets, info
