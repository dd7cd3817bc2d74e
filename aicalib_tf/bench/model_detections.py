"""Do two corner models detect the same boards? Per condition, in one process (the int8 check).

:func:`compare_models` runs the detection pipeline with each model on the same images of the
benchmark's named conditions (:func:`aicalib_tf.bench.conditions.named_conditions`, fixed seeds)
and scores every detection with the benchmark's metrics. :func:`int8_verdict` applies the int8
rule for a quantised model: per condition within one image of the float32 model's hits (and wrong
boards, and boards found on partial/occluded images), and the median corner error within
5%. ``python -m aicalib_tf.export`` writes the result into the model card;
``benchmarks/int8_detection.py`` runs it on more images.
"""

from __future__ import annotations

import time

import numpy as np

from aicalib_tf.bench.conditions import PATTERN, condition_samples, named_conditions
from aicalib_tf.bench.detectors import make_detectors, score_detection

__all__ = ["compare_models", "int8_verdict", "verdict_line", "MAX_IMAGE_DIFF", "MAX_ERROR_CHANGE"]

MAX_IMAGE_DIFF = 1  # images per condition by which a quantised model's counts may differ
MAX_ERROR_CHANGE = 0.05  # relative change of the median corner error allowed


def compare_models(models: dict[str, str], per_condition: int, *, conditions=None) -> dict:
    """Detect each named condition's first ``per_condition`` images with every model.

    models : {label: model name or path for :func:`aicalib_tf.cnn.model.load_model`}.
    conditions : Condition list (default: every named condition).
    Returns {condition: {label: {"hits", "wrong", "found" (any board), "corners" (found corners),
    "errors" (K,) px of the corners scored (all of a hit, the correct ones of a partial board),
    "ms" (median ms per image)}}}.
    """
    detectors = {label: make_detectors(("cnn",), PATTERN, name)[0]["cnn"] for label, name in models.items()}
    out = {}
    for cond in conditions if conditions is not None else named_conditions():
        samples = [s for _, s in condition_samples(cond, per_condition)]
        out[cond.name] = {label: _run(fn, samples) for label, fn in detectors.items()}
    return out


def _run(fn, samples) -> dict:
    rec = {"hits": 0, "wrong": 0, "found": 0, "corners": 0, "errors": [], "ms": []}
    for s in samples:
        has_board = bool(s.label.get("has_board", True)) and bool(s.label["corners"])  # as the runner reads it
        t0 = time.perf_counter()
        found = fn(s.image)
        rec["ms"].append(1e3 * (time.perf_counter() - t0))
        row, errors = score_detection(found, s.corners if has_board else None, s.visible if has_board else None,
                                      has_board, PATTERN)
        rec["hits"] += row["outcome"] == "hit"
        rec["wrong"] += row["outcome"] in ("wrong", "false_board")
        rec["found"] += bool(row["found"])
        rec["corners"] += int(row["n_corners"])
        rec["errors"].append(errors)
    rec["errors"] = np.concatenate(rec["errors"]) if rec["errors"] else np.zeros(0)
    rec["ms"] = float(np.median(rec["ms"]))
    return rec


def int8_verdict(result: dict, base: str, other: str) -> tuple[bool, list[str], float]:
    """The int8 rule for ``other`` against ``base`` over :func:`compare_models`' result.

    Returns (passed, the conditions that break it with why, relative change of the median corner
    error over all hits).
    """
    broken = []
    for cond, rec in result.items():
        a, b = rec[base], rec[other]
        for key in ("hits", "wrong", "found"):
            if abs(a[key] - b[key]) > MAX_IMAGE_DIFF:
                broken.append(f"{cond}: {key} {a[key]} -> {b[key]}")
    ea = np.concatenate([r[base]["errors"] for r in result.values()])
    eb = np.concatenate([r[other]["errors"] for r in result.values()])
    change = float(np.median(eb) / np.median(ea) - 1.0) if ea.size and eb.size else float("nan")
    if not abs(change) <= MAX_ERROR_CHANGE:
        broken.append(f"median corner error {np.median(ea):.4f} -> {np.median(eb):.4f} px ({100 * change:+.1f}%)")
    return not broken, broken, change


def verdict_line(result: dict, base: str, other: str, per_condition: int) -> str:
    """One sentence: the rule's outcome, the totals and the speed, for the model card."""
    ok, broken, change = int8_verdict(result, base, other)
    tot = {m: {k: sum(r[m][k] for r in result.values()) for k in ("hits", "wrong", "found", "corners")}
           for m in (base, other)}
    ms = {m: float(np.median([r[m]["ms"] for r in result.values()])) for m in (base, other)}
    head = (f"on {per_condition} images of each of {len(result)} named conditions, {other} against {base}: hits "
            f"{tot[other]['hits']} vs {tot[base]['hits']}, wrong boards {tot[other]['wrong']} vs {tot[base]['wrong']}, "
            f"corners found {tot[other]['corners']} vs {tot[base]['corners']}, median corner error "
            f"{100 * change:+.1f}%, median detection {ms[other]:.1f} vs {ms[base]:.1f} ms")
    return head + ("; within one image per condition and 5% in corner error" if ok else "; MISSES the rule: " + "; ".join(broken))
