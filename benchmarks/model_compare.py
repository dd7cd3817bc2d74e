"""Corner-point precision and recall of the shipped CNNs, per data_gen condition.

    python benchmarks/model_compare.py [--images 30] [--models default,report,mine=runs/x/model.keras] [--thresholds 0.5,0.4] [--conditions noisy,blur] [--by-spacing] [--refine]

Each model scores whole 640×480 images (the default model decodes its corner map; the report's
patch classifier scores saddle-point candidates). A detection matches a visible true corner
within 1 px. This measures the networks alone, before refinement and grid assembly. It also
times the network step per image.

``--refine`` scores the detector's candidates instead: each model's points refined to the image's
saddle point and merged within 1.5 px (:func:`aicalib_tf.detect.pipeline.refined_points`), as detection
does before grid assembly. Both models' points then get the same classical localisation (the
report's raw points are the saddle detector's whole pixels, the default's the map's offsets).

``--by-spacing`` adds, for each row, the recall of the true corners binned by the distance to
their nearest neighbouring corner on the board (px; tiny and squeezed boards have close corners):
the default model's map has one cell per 4×4 px, the report's candidates are found at every pixel.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")

import numpy as np  # noqa: E402

from aicalib_tf.detect.pipeline import refined_points  # noqa: E402
from aicalib_tf.cnn.inference import corner_points  # noqa: E402
from aicalib_tf.detect.corners.junctions import nearest_spacing  # noqa: E402
from aicalib_tf.cnn.point_metrics import match_points, point_detection_stats  # noqa: E402
from aicalib_tf.cnn.model import load_model  # noqa: E402
from data_gen import make_sample  # noqa: E402

CONDITIONS = ("clean", "noisy", "blur", "distorted", "occluded", "hard")
SPACING_BINS = (0.0, 4.0, 5.0, 6.0, 8.0, np.inf)  # px


def recall_by_spacing(pairs, spacings, max_distance: float = 1.0, bins=SPACING_BINS) -> list[tuple[int, int]]:
    """(matched, true) per spacing bin, over many images.

    pairs : [(pred (N, 2), truth (M, 2)), ...] px, as for ``point_detection_stats``.
    spacings : [(M,), ...] each true corner's distance to its nearest other corner of the board (px).
    bins : edges; bin k holds lo ≤ spacing < hi. Matching is one-to-one within ``max_distance`` px.
    """
    hit, total = np.zeros(len(bins) - 1, int), np.zeros(len(bins) - 1, int)
    for (pred, truth), sp in zip(pairs, spacings):
        k = np.digitize(np.asarray(sp, float), bins) - 1
        matched = np.zeros(len(k), bool)
        matched[match_points(pred, truth, max_distance)[1]] = True
        np.add.at(total, k, 1)
        np.add.at(hit, k[matched], 1)
    return list(zip(hit.tolist(), total.tolist()))


def _spacings(s) -> np.ndarray:
    """Nearest-neighbour distance of each visible corner of a sample, among all the board's corners."""
    if not s.label["has_board"]:
        return np.zeros(0)
    return nearest_spacing(np.asarray(s.corners, float))[s.visible]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--images", type=int, default=30)
    ap.add_argument("--models", default="default,report",
                    help="comma list of shipped names (default, report), .keras paths or LABEL=PATH (default: %(default)s)")
    ap.add_argument("--seed", type=int, default=77)
    ap.add_argument("--thresholds", default="0.5", help="comma list of corner-weight thresholds (default: %(default)s)")
    ap.add_argument("--conditions", default=",".join(CONDITIONS))
    ap.add_argument("--by-spacing", action="store_true", help="also recall by the corners' nearest-neighbour distance")
    ap.add_argument("--refine", action="store_true", help="score the points after the detector's saddle refinement and merging")
    args = ap.parse_args(argv)
    thresholds = [float(t) for t in args.thresholds.split(",")]
    models = {}
    for spec in args.models.split(","):  # a shipped name, a .keras path, or LABEL=PATH
        label, _, path = spec.rpartition("=")
        models[label or spec] = load_model(path)
    points = refined_points if args.refine else corner_points
    rows = []
    print(f"| condition | model | threshold | precision | recall | F1 | loc median px | {'network + refinement' if args.refine else 'network'} ms/image |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for cond in args.conditions.split(","):
        samples = [make_sample(cond, args.seed, i, size=(640, 480)) for i in range(args.images)]
        spacings = [_spacings(s) for s in samples] if args.by_spacing else None
        for name, model in models.items():
            for _ in range(2):  # warm up: the size's own graph is traced on its second use (and the refinement's kernels load)
                points(model, samples[0].image)
            for thr in thresholds:
                pairs, times = [], []
                for s in samples:
                    t = time.perf_counter()
                    pts, _ = points(model, s.image, thr)
                    times.append(time.perf_counter() - t)
                    pairs.append((pts, s.corners[s.visible] if s.label["has_board"] else np.zeros((0, 2))))
                st = point_detection_stats(pairs, 1.0)
                print(f"| {cond} | {name} | {thr:g} | {st['precision']:.3f} | {st['recall']:.3f} | {st['f1']:.3f} | "
                      f"{st['loc_median_px']:.3f} | {1000 * np.median(times):.1f} |", flush=True)
                if args.by_spacing:
                    rows.append((cond, name, thr, recall_by_spacing(pairs, spacings)))
    if args.by_spacing:
        edges = [f"{lo:g}–{hi:g} px" if np.isfinite(hi) else f"≥ {lo:g} px" for lo, hi in zip(SPACING_BINS, SPACING_BINS[1:])]
        print("\nRecall by the distance from each true corner to its nearest neighbour (matched / true):\n")
        print("| condition | model | threshold | " + " | ".join(edges) + " |")
        print("| --- | --- | --- | " + " | ".join("---" for _ in edges) + " |")
        for cond, name, thr, cells in rows:
            print(f"| {cond} | {name} | {thr:g} | " + " | ".join(f"{h}/{t} = {h / t:.3f}" if t else "–" for h, t in cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
