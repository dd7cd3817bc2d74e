"""Ceiling on id recall: how many visible corners of a benchmark image the image itself can name.

    python benchmarks/partial_ambiguity.py [--condition partial|occluded] [--images 100]
        [--tol 2] [--results reports/DATE/results.csv] [--csv OUT]

A detector that must never return a wrong id can only name a visible corner when the image rules
out every other way the board could lie. This script measures, on the evaluate benchmark's images
(``aicalib_tf.bench.conditions``: the same preset, seed, size and indices), the recall such a detector
could reach at best, and compares it with the CNN detector's recall in an evaluate results.csv.

Method, for each image:

1. The scene is drawn again with ``data_gen.draw_scene`` (camera, board, pose, background,
   occluders, degradations and the noise's generator state); rendering it gives back the
   benchmark image byte for byte (checked).
2. Rival placements: the board moved within its own plane by a symmetry of the square lattice,
   g(q) = A·q + b with A a turn by 0/90/180/270° (handedness kept: the printed side faces the
   camera) and b a shift by whole squares, such that every visible corner (c, r) lands on an inner
   corner of the 9×6 pattern. In the moved scene the board point g(q) lies where q lay: pose
   R' = R·A⁻¹, t' = t − R'·b (same camera and lens, same board: squares, grey levels, paper margin).
3. Each rival is rendered with data_gen's own renderer over the same background, the same
   occluders are drawn with the same random state, and the same degradations are applied with the
   same noise realisation; the result is compared with the original image pixel by pixel. A rival is
   indistinguishable (a tie) when no pixel differs by more than ``--tol`` grey levels (default 2: the
   read noise σ; with the noise identical, real differences are whole squares, paper or background
   and run to tens of grey levels, while equal scenes differ by rounding only: on ``partial`` and
   ``occluded`` (seed 21, 100 images each) every tie differs by at most 1 grey level and every
   other rival by 73 or more at some pixel, so any --tol from 1 to 72 gives the same result).
   Every rival is rendered (about 30 ms each).
4. Determination: a visible corner's id is determined when every tie gives it the same id. As in
   the evaluation (``metrics.partial_board_stats``), ids equal up to the pattern's 180° symmetry
   count as the same reading. If any tie reads the board differently, the image counts 0 determined
   corners (a detector cannot know which of its ids to trust); the ``subset`` column says how many
   corners every tie would still name alike (fixed points of the rival maps).

Output: a per-image table (visible corners and their id range, rivals tried, ties and their maps
``rotDEG+(bx,by)``, determined, subset, the evidence against the closest rejected rival, the
detector's correct and wrong ids, headroom), then the totals: the ceiling
recall = determined / visible, the detector's recall, and the images where the detector misses
corners that the ceiling says are determined (real headroom).

Caveats: the rivals are lattice symmetries of the same physical board; a detector that knows the
board's margin width, grey levels and the background exactly is assumed, so the ceiling is an
upper bound (a real detector also meets rivals the truth would rule out only with a few pixels of
evidence, listed as ``evidence``: the number of pixels that differ by more than 8 grey levels, 4σ,
for the closest rejected rival).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import cv2
import numpy as np
import pandas as pd

from aicalib_tf.bench.conditions import PATTERN, Condition, condition_samples, select_conditions
from data_gen import draw_scene

EVIDENCE_GREY = 8  # grey levels (4σ of the read noise) a pixel must differ by to count as evidence

_TURNS = {0: np.array([[1, 0], [0, 1]]), 90: np.array([[0, -1], [1, 0]]),
          180: np.array([[-1, 0], [0, -1]]), 270: np.array([[0, 1], [-1, 0]])}


def rivals(ids: np.ndarray, pattern=PATTERN):
    """Lattice maps (turn, A, b) other than the identity that keep every id of ``ids`` (N, 2) on the pattern."""
    cols, rows = pattern
    out = []
    for deg, A in _TURNS.items():
        m = ids @ A.T
        for bx in range(-int(m[:, 0].min()), cols - int(m[:, 0].max())):
            for by in range(-int(m[:, 1].min()), rows - int(m[:, 1].max())):
                if deg == 0 and bx == 0 and by == 0:
                    continue
                out.append((deg, A, np.array([bx, by])))
    return out


def moved_pose(rvec, tvec, A: np.ndarray, b: np.ndarray, square: float):
    """Pose of the board moved by g(q) = A·q + b (squares): board point g(q) where q was."""
    R, _ = cv2.Rodrigues(np.asarray(rvec, float).reshape(3, 1))
    A3 = np.eye(3)
    A3[:2, :2] = A
    R2 = R @ np.linalg.inv(A3)
    t2 = np.asarray(tvec, float) - R2 @ np.array([b[0] * square, b[1] * square, 0.0])
    return cv2.Rodrigues(R2)[0].ravel(), t2


def _same_reading(a: np.ndarray, b: np.ndarray, pattern=PATTERN) -> bool:
    """Ids (N, 2) equal, or equal after the pattern's 180° symmetry (the evaluation's single reading)."""
    cols, rows = pattern
    return bool(np.array_equal(a, b) or np.array_equal(a, np.stack([cols - 1 - b[:, 0], rows - 1 - b[:, 1]], 1)))


def analyse(cond: Condition, index: int, image: np.ndarray, tol: float) -> dict:
    """One image: its visible corners, the rivals, which of them tie, and how many ids are determined."""
    sc = draw_scene(cond.preset, cond.seed, index, size=cond.size, pattern=PATTERN)
    if not np.array_equal(sc.render(), image):
        raise RuntimeError(f"{cond.name} #{index}: the rebuilt scene does not reproduce the benchmark image")
    cols, rows = PATTERN
    s = sc.board.square_size
    vis = np.flatnonzero(sc.visible)
    ids = np.stack([vis % cols, vis // cols], 1)
    img = image.astype(np.int16)
    cands = rivals(ids)
    ties, tie_max, rival_max, evidence = [], 0, None, None
    for deg, A, b in cands:
        d = np.abs(sc.render(*moved_pose(sc.rvec, sc.tvec, A, b, s)).astype(np.int16) - img)
        if int(d.max()) <= tol:
            ties.append((deg, A, b))
            tie_max = max(tie_max, int(d.max()))
        else:
            ev = int(np.count_nonzero(d > EVIDENCE_GREY))
            if evidence is None or ev < evidence:
                evidence, rival_max = ev, int(d.max())
    readings = [ids] + [ids @ A.T + b for _, A, b in ties]
    unique = all(_same_reading(r, ids) for r in readings[1:])
    fixed = np.all([np.all(r == ids, axis=1) for r in readings], axis=0)
    return {
        "index": index, "visible": len(vis),
        "ids": f"c{ids[:, 0].min()}-{ids[:, 0].max()} r{ids[:, 1].min()}-{ids[:, 1].max()}" if len(vis) else "-",
        "rivals": len(cands), "ties": len(ties),
        "tie_maps": "; ".join(f"rot{deg}+({b[0]},{b[1]})" for deg, _, b in ties),
        "tie_maxdiff": tie_max if ties else -1,
        "unique": unique, "determined": len(vis) if unique else 0,
        "subset": len(vis) if unique else int(fixed.sum()),
        "evidence": evidence if evidence is not None else -1,
        "ev_maxdiff": rival_max if rival_max is not None else -1,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--condition", default="partial", choices=("partial", "occluded"))
    ap.add_argument("--images", type=int, default=100)
    ap.add_argument("--tol", type=float, default=2.0, help="largest per-pixel grey difference of a tie (0-255)")
    ap.add_argument("--results", default=None, help="an evaluate results.csv to compare the CNN detector with")
    ap.add_argument("--csv", default=None, help="write the per-image table here")
    args = ap.parse_args(argv)

    cond = select_conditions(args.condition)[0]
    t0 = time.time()
    rows = [analyse(cond, i, s.image, args.tol) for i, s in condition_samples(cond, args.images)]
    df = pd.DataFrame(rows)
    if args.results is not None:
        if not os.path.isfile(args.results):
            raise SystemExit(f"--results {args.results}: no such file")
        res = pd.read_csv(args.results)
        res = res[(res.condition == cond.name) & (res.detector == "cnn")]
        res = res[["index", "visible", "correct", "wrong_ids"]].rename(columns={"visible": "det_visible"})
        df = df.merge(res, on="index", how="left")
        if (df.det_visible.notna() & (df.det_visible != df.visible)).any():
            raise RuntimeError("results.csv counts other visible corners than the rebuilt scenes")
        df["headroom"] = (df.determined - df.correct).clip(lower=0)
    pd.set_option("display.width", 250)
    pd.set_option("display.max_rows", None)
    pd.set_option("display.max_colwidth", 60)
    print(df.to_string(index=False))
    v, d = int(df.visible.sum()), int(df.determined.sum())
    print(f"\n{cond.name}: {len(df)} images, {v} visible corners, {time.time() - t0:.0f} s")
    print(f"unique placement: {int(df.unique.sum())} images; ambiguous: {int((~df.unique).sum())} images "
          f"({int(df.visible[~df.unique].sum())} visible corners, "
          f"{int(df.subset[~df.unique].sum())} of them named alike by every tie)")
    print(f"ceiling recall (determined / visible): {d}/{v} = {100 * d / v:.2f}%")
    print(f"ceiling counting tie-invariant subsets: {int(df.subset.sum())}/{v} = {100 * df.subset.sum() / v:.2f}%")
    if "correct" in df:
        c = int(df.correct.sum())
        print(f"detector (cnn, {args.results}): {c}/{v} = {100 * c / v:.2f}%, wrong ids {int(df.wrong_ids.sum())}")
        print(f"detector correct on ambiguous images: {int(df.correct[~df.unique].sum())}")
        head = df[df.headroom > 0]
        print(f"headroom (determined but missed): {int(head.headroom.sum())} corners in {len(head)} images: "
              + ", ".join(f"#{r.index} ({r.headroom})" for r in head.itertuples()))
        print(f"detector recall on the determined corners: {int(np.minimum(df.correct, df.determined).sum())}/{d} = "
              f"{100 * np.minimum(df.correct, df.determined).sum() / max(d, 1):.2f}%")
    thin = df[df.unique & (df.evidence >= 0) & (df.evidence < 50)]
    print(f"unique images where the closest rival is ruled out by < 50 px of evidence (> {EVIDENCE_GREY} grey levels): "
          + ", ".join(f"#{r.index} ({r.evidence} px)" for r in thin.itertuples()))
    for n in (50, 100, 500):
        weak = df.unique & (df.evidence >= 0) & (df.evidence < n)
        print(f"ceiling if a rival ruled out by < {n} px of evidence counted as a tie: "
              f"{100 * (d - df.visible[weak].sum()) / v:.2f}% ({int(weak.sum())} more images ambiguous)")
    if args.csv:
        df.to_csv(args.csv, index=False)
    return 0


if __name__ == "__main__":
    sys.exit(main())
