"""Close-up fisheye boards with an object over their outer ring: full boards and wrong ones, rim completion on and off.

    python benchmarks/occluded_closeups.py [--count 40] [--per 3] [--condition closeup-eq] [--seed S]

Each image of the evaluate condition (``aicalib_tf.bench.conditions``, default ``closeup-eq``) is
drawn again (``data_gen.sample.draw_scene``) with one object in front of it, centred within 0.3
of a square of a visible outer-ring corner (drawn at random, ``--per`` objects per image, one at a
time; ``--seed`` draws other scenes and objects, the condition's seed replaced): a blob
(star-convex polygon) or a bar (4 × 0.7 of its radius), radius 0.4–1.6 of the corner's nearest
step, grey 0.05–0.95, as data_gen's occluders but sized to the rim's corners. The corners under it
or within 2 px of its outline are hidden (``data_gen.occlude.occluded``).

Each render goes through :func:`aicalib_tf.detect_corners` four times: as shipped, with the
object test (:func:`aicalib_tf.detect.chessboard.occlusion.object_in_front`) switched off, with
the interpolation test (:func:`aicalib_tf.detect.chessboard.smooth_grid.without_off_grid`) switched
off, and with the rim completion (:func:`aicalib_tf.detect.chessboard.rim.rim_board`) switched off.
Printed per run: full boards, full boards with a wrong id (a corner over 2 px from its true place;
also by the render's object number, 0 … per − 1, so that object 2 can be held out of tuning), full
boards that claim a hidden corner within 2 px of it, partial boards and those with a wrong id, and
each scene where the runs differ.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import replace

import cv2
import numpy as np

from aicalib_tf.bench.conditions import PATTERN, condition_samples, select_conditions
from aicalib_tf.bench.metrics import partial_board_stats
from data_gen.occlude import occluded
from data_gen.sample import draw_scene


def outer_ring(cols: int, rows: int) -> list[int]:
    """Indices (OpenCV order) of a cols × rows board's outer-ring corners."""
    return [r * cols + c for r in range(rows) for c in range(cols) if r in (0, rows - 1) or c in (0, cols - 1)]


def occluder(rng: np.random.Generator, centre: np.ndarray, step: float) -> np.ndarray:
    """(M, 2) px: a blob or a bar about ``centre`` px, sized by ``step`` px."""
    radius = step * rng.uniform(0.4, 1.6)
    if rng.random() < 0.5:
        n = int(rng.integers(5, 11))
        a = (np.arange(n) + rng.uniform(0, 1, n)) * (2 * math.pi / n)
        r = radius * rng.uniform(0.5, 1.0, n)
        return np.stack([centre[0] + r * np.cos(a), centre[1] + r * np.sin(a)], 1)
    box = ((float(centre[0]), float(centre[1])), (float(radius * 4), float(radius * 0.7)), float(rng.uniform(0, 180)))
    return cv2.boxPoints(box).astype(np.float64)


def scenes(cond, count: int, per: int, seed: int | None = None):
    """Yield ((index, k), image (H, W) uint8, true corners (N, 2) px, visible (N,) bool).

    seed : None draws the objects as the condition's own renders do; a seed draws them anew (with
    ``cond``'s seed replaced by it, so the scenes too)."""
    for index, _ in condition_samples(cond, count):
        scene = draw_scene(cond.preset, cond.seed, index, size=cond.size, pattern=PATTERN)
        rng = np.random.default_rng([index, 99] if seed is None else [index, 99, seed])
        ring = [k for k in outer_ring(*PATTERN) if scene.visible[k]]
        for k in range(per):
            corner = ring[int(rng.integers(len(ring)))]
            d = np.hypot(*(scene.corners - scene.corners[corner]).T)
            d[corner] = np.inf
            step = float(d.min())
            poly = occluder(rng, scene.corners[corner] + rng.normal(0, 0.3 * step, 2), step)
            img = replace(scene, occluders=[poly], occluder_levels=[float(rng.uniform(0.05, 0.95))]).render()
            yield (index, k), img, scene.corners, scene.visible & ~occluded(scene.corners, [poly])


def outcome(det, truth: np.ndarray, visible: np.ndarray) -> str:
    """'full', 'full, wrong', 'full, hidden' (a hidden corner claimed within 2 px), 'partial',
    'partial, wrong' or 'none'."""
    if not det.found:
        return "none"
    st = partial_board_stats(det.corners, det.ids, truth, visible, PATTERN)
    if not det.complete:
        return "partial, wrong" if st["wrong_ids"] else "partial"
    return "full, wrong" if st["wrong_ids"] else ("full, hidden" if st["hidden_found"] else "full")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--condition", default="closeup-eq", help="an evaluate condition name")
    ap.add_argument("--count", type=int, default=40, help="images of the condition")
    ap.add_argument("--per", type=int, default=3, help="objects per image, one per render")
    ap.add_argument("--seed", type=int, default=None, help="data_gen seed in place of the condition's (other scenes)")
    args = ap.parse_args(argv)
    from aicalib_tf import detect_corners
    from aicalib_tf.detect import pipeline

    def never(*_a, **_k):
        return None  # no rim board; no object in front (falsy)

    def as_it_is(det, _reason):
        return det  # no corner off the grid

    runs = {"shipped": {}, "object test off": {"object_in_front": never, "object_in_front_at": never},
            "interpolation test off": {"without_off_grid": as_it_is}, "rim off": {"rim_board": never}}
    shipped = {name: getattr(pipeline, name) for patch in runs.values() for name in patch}
    counts = {name: {"full": 0, "full, wrong": 0, "full, hidden": 0, "partial": 0, "partial, wrong": 0,
                     "wrong by object": [0] * args.per} for name in runs}
    total = 0
    cond = select_conditions(args.condition)[0]
    cond = cond if args.seed is None else replace(cond, seed=args.seed)
    for key, img, truth, visible in scenes(cond, args.count, args.per, args.seed):
        got = {}
        for name, patch in runs.items():
            for attr, value in patch.items():  # the search looks its stages up in its module at each call
                setattr(pipeline, attr, value)
            try:
                got[name] = outcome(detect_corners(img, PATTERN), truth, visible)
            finally:
                for attr, value in shipped.items():
                    setattr(pipeline, attr, value)
            if got[name].startswith("full"):
                counts[name]["full"] += 1
                counts[name][got[name]] += got[name] != "full"
                counts[name]["wrong by object"][key[1]] += got[name] == "full, wrong"
            if got[name].startswith("partial"):
                counts[name]["partial"] += 1
                counts[name]["partial, wrong"] += got[name] != "partial"
        total += 1
        if len(set(got.values())) > 1:
            print(f"  {args.condition} #{key[0]} object {key[1]} ({int((~visible).sum())} hidden): {got}", flush=True)
    for name, c in counts.items():
        print(f"{name}: {total} renders, {c['full']} full boards, {c['full, wrong']} with a wrong id "
              f"(objects 0, 1, ...: {c['wrong by object']}), {c['full, hidden']} claiming a hidden corner; "
              f"{c['partial']} partial boards, {c['partial, wrong']} with a wrong id")
    return 0


if __name__ == "__main__":
    sys.exit(main())
