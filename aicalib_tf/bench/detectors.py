"""Per-detection scoring for the benchmark (``aicalib_tf.bench.runner``).

The detectors themselves (``f(uint8 (H, W) image) -> Found``) are :mod:`aicalib_tf.detect.registry`'s,
re-exported here; every one is scored by the same metric functions (:mod:`aicalib_tf.bench.metrics`).
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.bench.metrics import (
    WRONG_PX,
    board_detection_outcome,
    partial_board_stats,
)
from aicalib_tf.detect.registry import DETECTORS, Found, make_detectors

__all__ = ["DETECTORS", "WRONG_PX", "Found", "make_detectors", "score_detection"]


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
