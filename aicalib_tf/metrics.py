"""Pure metric functions on arrays (no file access, no TensorFlow).

Corner arrays are (N, 2) float (x, y) px in OpenCV order (index = r·cols + c).
"""

from __future__ import annotations

import numpy as np

__all__ = ["board_symmetries", "align_to_truth", "corner_error_stats", "match_points", "point_detection_stats"]


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


def match_points(pred: np.ndarray, truth: np.ndarray, max_distance: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One-to-one matching of predicted points to true points, closest pairs first.

    pred : (N, 2) px. truth : (M, 2) px. A pair matches when closer than ``max_distance`` px.
    Returns (i_pred, i_truth, distance): three (K,) arrays, each index used at most once.
    """
    p = np.asarray(pred, dtype=np.float64).reshape(-1, 2)
    t = np.asarray(truth, dtype=np.float64).reshape(-1, 2)
    if len(p) == 0 or len(t) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    d = np.sqrt(((p[:, None, :] - t[None, :, :]) ** 2).sum(-1))
    ip, it = np.nonzero(d < max_distance)
    order = np.argsort(d[ip, it], kind="stable")
    used_p, used_t, keep = set(), set(), []
    for k in order:
        a, b = int(ip[k]), int(it[k])
        if a not in used_p and b not in used_t:
            used_p.add(a)
            used_t.add(b)
            keep.append(k)
    keep = np.asarray(keep, dtype=np.int64)
    return ip[keep], it[keep], d[ip[keep], it[keep]]


def point_detection_stats(pairs: list[tuple[np.ndarray, np.ndarray]], max_distance: float = 1.0) -> dict:
    """Corner precision, recall and localisation error over many images.

    pairs : [(pred (N, 2), truth (M, 2)), ...] px, one per image.
    Returns precision, recall (matches within ``max_distance`` px), f1, and the median and p95
    distance (px) of the matches, plus the counts.
    """
    tp = n_pred = n_true = 0
    dists = []
    for pred, truth in pairs:
        _, _, d = match_points(pred, truth, max_distance)
        tp += len(d)
        n_pred += len(np.asarray(pred).reshape(-1, 2))
        n_true += len(np.asarray(truth).reshape(-1, 2))
        dists.append(d)
    d = np.concatenate(dists) if dists else np.zeros(0)
    precision = tp / n_pred if n_pred else float("nan")
    recall = tp / n_true if n_true else float("nan")
    f1 = 2 * precision * recall / (precision + recall) if tp else 0.0
    return {
        "precision": float(precision),
        "recall": float(recall),
        "f1": float(f1),
        "loc_median_px": float(np.median(d)) if d.size else float("nan"),
        "loc_p95_px": float(np.percentile(d, 95)) if d.size else float("nan"),
        "matched": int(tp),
        "predicted": int(n_pred),
        "true": int(n_true),
    }
