"""Where the CNN pipeline's time goes: ms per stage over evaluate --quick's images.

Every stage function the pipeline calls is wrapped by a timer that counts its *own* time (a
stage's time less that of the stages it calls, so the zoom's second search is not counted twice),
and the images of ``evaluate --quick`` (its named conditions, sweep levels and 1920x1080 images,
rendered once, fixed seeds) are detected ``--repeat`` times after a warm-up; each image keeps its
least total. OpenCV's classic detector is timed on the same images in the same process.

    python benchmarks/stage_profile.py [--repeat 2] [--limit N] [--conditions LIST] [--model default_int8]

Stages: gate (the image gate, and converting the image or a region of it to float), network (the interpreter call), input (standardise and pad the
image for the network), decode (corner map -> points), smoothing (Gaussian blurs), refinement
(saddle fits), candidates (merging, spacing, the typical ring amplitude), proposals (corners the grid predicts,
fitted during assembly), assembly (grid growth), ordering (full-board order), partial (partial
boards), pyramid (the reduced scales and the full-size refinement of a coarse scale's corners), zoom
(the enlarged region, its own part), other (the rest of detect_corners).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aicalib_tf.bench.conditions import PATTERN, condition_samples, select_conditions  # noqa: E402
from aicalib_tf.bench.runner import QUICK_COUNTS  # noqa: E402

STAGES = ("gate", "input", "network", "decode", "smoothing", "refinement", "candidates", "proposals", "assembly",
          "ordering", "partial", "pyramid", "zoom", "other")


class StageClock:
    """Own time per stage: a stack of running stages, each charged its time less its children's."""

    def __init__(self):
        self.own = defaultdict(float)
        self._stack: list[list] = []  # [stage, start, child seconds]

    def wrap(self, stage: str, fn):
        def timed(*args, **kwargs):
            self._stack.append([stage, time.perf_counter(), 0.0])
            try:
                return fn(*args, **kwargs)
            finally:
                name, t0, child = self._stack.pop()
                dt = time.perf_counter() - t0
                self.own[name] += dt - child
                if self._stack:
                    self._stack[-1][2] += dt
        return timed


def instrument(clock: StageClock) -> None:
    """Wrap the pipeline's stage functions (module attributes, looked up at call time) by ``clock``."""
    from aicalib_tf.cnn import inference, runtime
    from aicalib_tf.detect import pipeline, pyramid
    from aicalib_tf.detect.corners import refine

    targets = [
        (pipeline, "read_image", "gate"), (pyramid, "as_gray_float", "gate"), (inference, "network_input", "input"), (inference, "decode_map", "decode"),
        (refine, "gaussian", "smoothing"), (pipeline, "refine_candidates", "refinement"),
        (pipeline, "dedupe", "candidates"), (pipeline, "nearest_spacing", "candidates"),
        (pipeline, "typical_amplitude", "candidates"), (pipeline, "assemble_grids", "assembly"),
        (pipeline, "full_board", "ordering"), (pipeline, "partial_board", "partial"),
        (pipeline, "relative_board", "partial"), (pipeline.Frame, "reduced", "pyramid"),
        (pipeline, "refine_full", "pyramid"), (pipeline, "_zoomed", "zoom"), (pipeline, "detect_corners", "other"),
    ]
    for module, name, stage in targets:
        setattr(module, name, clock.wrap(stage, getattr(module, name)))
    runtime.RuntimeModel.__call__ = clock.wrap("network", runtime.RuntimeModel.__call__)
    make_proposer = pipeline.proposer

    def proposer(*args, **kwargs):  # the proposer and its tight and bent variants, each timed
        propose = make_proposer(*args, **kwargs)
        timed = clock.wrap("proposals", propose)
        timed.tight, timed.bent = clock.wrap("proposals", propose.tight), clock.wrap("proposals", propose.bent)
        return timed
    pipeline.proposer = proposer


def quick_images(spec: str | None, limit: int | None) -> list[tuple[str, np.ndarray]]:
    """(condition, uint8 image) of evaluate --quick's conditions (no calibration sequences)."""
    out = []
    for cond in select_conditions(spec):
        n = QUICK_COUNTS["sweep"] if cond.sweep else QUICK_COUNTS["hd"] if cond.size[0] > 1000 else QUICK_COUNTS["named"]
        n = min(n, limit) if limit else n
        out += [(cond.name, s.image) for _, s in condition_samples(cond, n)]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--limit", type=int, default=None)
    ap.add_argument("--conditions", default=None)
    ap.add_argument("--model", default="default", help="default, default_int8, quick, quick_int8 or a .tflite path")
    a = ap.parse_args(argv)
    from aicalib_tf.cnn.model import load_model
    from aicalib_tf.detect import pipeline
    from aicalib_tf.detect.opencv import opencv_classic

    images = quick_images(a.conditions, a.limit)
    model = load_model(a.model)
    for _, img in images[:3] + [i for i in images if i[1].shape[1] > 1000][:1]:  # warm-up: kernels, sizes
        pipeline.detect_corners(img, PATTERN, model=model)
    clock = StageClock()
    instrument(clock)
    per_size = defaultdict(lambda: {"cnn": [], "opencv": [], "stages": defaultdict(list)})
    for _, img in images:
        best, best_own = None, None
        for _ in range(a.repeat):
            clock.own.clear()
            t0 = time.perf_counter()
            pipeline.detect_corners(img, PATTERN, model=model)
            dt = time.perf_counter() - t0
            if best is None or dt < best:
                best, best_own = dt, dict(clock.own)
        cv = min(_timed(opencv_classic, img) for _ in range(a.repeat))
        rec = per_size[img.shape[::-1]]
        rec["cnn"].append(1e3 * best)
        rec["opencv"].append(1e3 * cv)
        for s in STAGES:
            rec["stages"][s].append(1e3 * best_own.get(s, 0.0))
    for size, rec in sorted(per_size.items()):
        n = len(rec["cnn"])
        total = sum(np.mean(v) for v in rec["stages"].values())
        print(f"\n{size[0]}x{size[1]}: {n} images; cnn median {np.median(rec['cnn']):.2f} ms (mean {np.mean(rec['cnn']):.2f}), "
              f"opencv classic median {np.median(rec['opencv']):.2f} ms, ratio {np.median(rec['cnn']) / np.median(rec['opencv']):.2f}")
        print("| stage | mean ms | median ms | share |\n| --- | ---: | ---: | ---: |")
        for s in STAGES:
            v = rec["stages"][s]
            print(f"| {s} | {np.mean(v):.2f} | {np.median(v):.2f} | {100 * np.mean(v) / total:.1f}% |")
        print(f"| total | {total:.2f} | | 100% |")
    return 0


def _timed(fn, img) -> float:
    t0 = time.perf_counter()
    fn(img, PATTERN)
    return time.perf_counter() - t0


if __name__ == "__main__":
    sys.exit(main())
