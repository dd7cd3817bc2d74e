"""Timing a detector on one image, and re-timing the slowest images at the end of a run.
"""

from __future__ import annotations

import heapq
import time
from typing import Any, Callable

import numpy as np

__all__ = ["RETIME_RUNS", "RETIME_SLOWEST", "retime_slowest", "time_detector", "keep_slowest"]


def time_detector(fn: Callable, image: np.ndarray) -> tuple[Any, float]:
    """Run one detector on one image; returns (its result, e.g. a Found, and the wall time in ms)."""
    t = time.perf_counter()
    found = fn(image)
    return found, 1000.0 * (time.perf_counter() - t)


RETIME_SLOWEST = 20  # per detector and image size: the slowest images, timed again at the end
RETIME_RUNS = 2  # more runs of each; the least time counts


def keep_slowest(slowest: dict, img_rows: list[dict], image: np.ndarray, k: int = RETIME_SLOWEST) -> None:
    """Remember ``image`` for each of its rows that is among the ``k`` slowest of its (detector, W, H) so far.

    slowest : {(detector, W, H): min-heap of (time_ms, tie-break, row, image)}, changed in place.
    """
    for row in img_rows:
        heap = slowest.setdefault((row["detector"], row["width"], row["height"]), [])
        item = (row["time_ms"], id(row), row, image)
        if len(heap) < k:
            heapq.heappush(heap, item)
        elif item[0] > heap[0][0]:
            heapq.heapreplace(heap, item)


def retime_slowest(slowest: dict, detectors: dict, runs: int = RETIME_RUNS) -> int:
    """Time the images kept by :func:`keep_slowest` ``runs`` more times and keep each row's least time.

    The runs go round robin over all kept images, so (with more than one kept) no run follows a run
    of the same image and finds it still in the CPU's caches. Each row's ``time_runs`` counts its
    timings; its ``time_first_ms``, when present, is left as it was. Returns how many rows were
    timed again.
    """
    items = [(key[0], row, image) for key, heap in slowest.items() for _, _, row, image in heap]
    for _ in range(runs):
        for det, row, image in items:
            _, ms = time_detector(detectors[det], image)
            row["time_ms"] = min(row["time_ms"], ms)
            row["time_runs"] += 1
    return len(items)


