"""Corner-point precision and recall: predicted points matched one-to-one to the true ones.

Used by training's validation and by the benchmark. Points are (N, 2) float (x, y) px.
"""

from __future__ import annotations

import numpy as np

__all__ = ["match_points", "point_detection_stats"]

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


