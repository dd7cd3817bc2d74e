"""Detector adapters and per-detection scoring for the benchmark (``aicalib_tf.bench.runner``).

Every detector is wrapped as ``f(uint8 (H, W) image) -> Found`` so that the CNN pipeline and
OpenCV's two detectors run on the same images, are timed the same way and are scored by the
same metric functions (:mod:`aicalib_tf.bench.metrics`).
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

from aicalib_tf.cnn.spec import DETECTOR_NETWORK
from aicalib_tf.bench.metrics import (
    WRONG_PX,
    board_detection_outcome,
    partial_board_stats,
)
from aicalib_tf.detect.board_order import full_board_ids

__all__ = ["DETECTORS", "WRONG_PX", "Found", "make_detectors", "score_detection"]

DETECTORS = ("cnn", "report", "opencv", "opencv-sb")


class Found(NamedTuple):
    """One detector's answer on one image.

    corners : (N, 2) float64 (x, y) px (N = 0 when nothing was found).
    ids : (N, 2) int (col, row). complete : a full board (N = cols·rows).
    why : when nothing was found, why, if the detector says (the CNN's ``Detection.reason``).
    relative : the ids are relative to the visible grid (``make_detectors(..., relative=True)``).
    sigmas : (N,) float32 px, each corner's σ (:attr:`aicalib_tf.detect.pipeline.Detection.sigmas`), or
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


def score_detection(found: Found, truth: np.ndarray | None, visible: np.ndarray | None, has_board: bool,
                    pattern: tuple[int, int]) -> tuple[dict, np.ndarray]:
    """Score one detection against the truth (metrics module); returns (row fields, hit errors).

    truth : (cols·rows, 2) px; visible : (cols·rows,) bool (both ignored without a board).
    outcome: hit / wrong / partial / miss on board images, false_board / false_partial / none
    on board-free ones. The returned errors (px) are those counted in the error statistics:
    all corners of a hit, the correct corners of a partial board, none otherwise.
    """
    n = len(found.corners)
    row = {"found": n > 0, "complete": bool(found.complete), "n_corners": n, "outcome": "none",
           "err_median": np.nan, "err_max": np.nan, "visible": 0, "correct": 0, "wrong_ids": 0,
           "hidden_found": 0, "recall": np.nan}
    if not has_board:
        row["outcome"] = "false_board" if found.complete else "false_partial" if n else "none"
        row["wrong_ids"] = n
        return row, np.zeros(0)
    st = partial_board_stats(found.corners, found.ids, truth, visible, pattern, WRONG_PX)
    row.update(visible=st["visible"], correct=st["correct"], wrong_ids=st["wrong_ids"],
               hidden_found=st["hidden_found"], recall=st["recall"])
    errors = np.zeros(0)
    if found.complete:
        outcome, e = board_detection_outcome(found.corners, truth, pattern, WRONG_PX)
        row.update(outcome=outcome, err_median=float(np.median(e)), err_max=float(e.max()))
        if outcome == "hit":
            errors = e
    elif n:
        row["outcome"] = "partial"
        errors = st["errors"]
        if errors.size:
            row.update(err_median=float(np.median(errors)), err_max=float(errors.max()))
    else:
        row["outcome"] = "miss"
    return row, errors
