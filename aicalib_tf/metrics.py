"""Pure metric functions on arrays (no file access, no TensorFlow).

Corner arrays are (N, 2) float (x, y) px in OpenCV order (index = r·cols + c).
"""

from __future__ import annotations

import numpy as np

__all__ = ["board_symmetries", "align_to_truth", "corner_error_stats"]


def board_symmetries(pattern_size: tuple[int, int]) -> list[np.ndarray]:
    """Index permutations that map a board onto itself: identity and 180° (and 90°/270° if square).

    Returns a list of (cols·rows,) int arrays ``perm`` such that ``corners[perm]`` is the same
    physical board read in another admissible order.
    """
    cols, rows = (int(v) for v in pattern_size)
    idx = np.arange(cols * rows).reshape(rows, cols)
    perms = [idx.ravel(), idx[::-1, ::-1].ravel()]
    if cols == rows:
        perms += [np.rot90(idx, 1).ravel(), np.rot90(idx, 3).ravel()]
    return perms


def align_to_truth(detected: np.ndarray, truth: np.ndarray, pattern_size: tuple[int, int]) -> np.ndarray:
    """Reorder a full detection by the board symmetry that best matches the truth.

    detected, truth : (cols·rows, 2) px. Returns the reordered (cols·rows, 2) detection.
    Raises ``ValueError`` if the sizes disagree with ``pattern_size``.
    """
    det = np.asarray(detected, dtype=np.float64).reshape(-1, 2)
    gt = np.asarray(truth, dtype=np.float64).reshape(-1, 2)
    n = int(pattern_size[0]) * int(pattern_size[1])
    if det.shape[0] != n or gt.shape[0] != n:
        raise ValueError(f"need {n} corners for pattern {tuple(pattern_size)}, got {det.shape[0]} and {gt.shape[0]}")
    best = min(board_symmetries(pattern_size), key=lambda p: float(np.sum((det[p] - gt) ** 2)))
    return det[best]


def corner_error_stats(errors: np.ndarray) -> dict:
    """Summary of per-corner errors (px): count, median, RMSE, p95, p99, max."""
    e = np.asarray(errors, dtype=np.float64).ravel()
    if e.size == 0:
        return {"count": 0, "median": float("nan"), "rmse": float("nan"), "p95": float("nan"), "p99": float("nan"), "max": float("nan")}
    return {
        "count": int(e.size),
        "median": float(np.median(e)),
        "rmse": float(np.sqrt(np.mean(e * e))),
        "p95": float(np.percentile(e, 95)),
        "p99": float(np.percentile(e, 99)),
        "max": float(np.max(e)),
    }
