"""How noisy one split's halves difference is: many random half-splits of each real set, every tool.

    .venv/bin/python benchmarks/real_split_noise.py [--sets opencv_left ...] [--splits 200] [--flex-splits 24]
        [--modes auto shape] [--shape-terms 7] [--shape-shrink-from 0.5] [--skip-mrcal] [--json noise.json]
        [--weighting view] [--per-split [COLUMN]] [--from-json noise.json]
    .venv/bin/python benchmarks/real_split_noise.py --synthetic 16 --splits 40 [--synthetic-ratio 0.8 0.6]

``benchmarks/real_repeatability.py`` scores two fixed splits of each set (even/odd, first/second). One
split is one draw: here each set's photos (as that benchmark reads them) are split at random into
halves (⌈n/2⌉ and ⌊n/2⌋ photos, seeds 0..N-1, the same splits for every tool) and every split is
scored as there (rotation-fitted projection difference, median over the covered cells):

- aicalib_tf, in process on the photos' detections (the calibrate command's CNN detector, each photo
  once), with the lens model ``auto`` chooses on all the photos held for every half:
  flat (``flex="off"``), "auto" (the default, ``flex="auto"``: the board's shape kept only where it moves
  the lens by more than its leave-one-view-out noise, :mod:`aicalib_tf.calib.flex_check`), "sag"
  (``flex="sag"``: each half's sag shrunk towards flat by its leave-one-view-out noise), "flex" (the sag as
  solved in both halves, its σ rule only) and "shape" (``flex="shape"``: the board's 7-term shape, each term
  shrunk by its leave-one-view-out noise, :mod:`aicalib_tf.calib.board_shape`; ``--shape-terms`` solves its
  first N terms, ``--shape-shrink-from`` sets the t up to which a term is 0); ``--modes`` runs a subset;
  and, for the flat halves, what their covariances predict for the difference
  (:func:`aicalib_tf.calib.quality.predicted_half_difference`: the mean and the 10-90% band of one draw);
- the crossed column "flat, classic corners": the flat default's fit on OpenCV's classic corners (equal
  weights), which tells the corners' share of a difference from the fit's;
- OpenCV 5-coefficient, rational and fisheye on classic corners, and mrcal OPENCV8 (one solve a half,
  board flex and outlier rejection; ``--skip-mrcal`` leaves it out), as in real_repeatability.py.

The flat, crossed and OpenCV columns run on every split; the flex and shape columns and mrcal, which refit per
view or start a process per half, on the first ``--flex-splits``. Splits of one set share its photos,
so a set's 24 splits are a noisy sample of its many possible splits: on opencv_left the flat default's
median over seeds 0-23 was 0.27 px against OpenCV 5-coef's 0.21, over seeds 0-299 0.19 against 0.23
(a random 24 of those 300 put it behind the best OpenCV column 24% of the time).

Printed per set: each column's median and quartiles over its splits; for each anchor, how often the
flat default is at or below it on the same split, and the difference of the two medians with its 90%
interval over the splits (both columns resampled by split, 1000 draws): an interval that holds 0 does
not rank the two; the same gap for the flex and shape columns against flat and against the best anchor
of each split, and each one's geometric mean over the splits of its difference ÷ flat's (90% interval,
splits resampled).

``--per-split`` adds, per set, on how many splits the default ("auto"; flat when the run has none) is at or
below each anchor and the best anchor of that same split (Wilson's 90% interval), and what that share
says of a target met on every fixed split: were each fixed split a random one, both of every set pass
with chance Π share². ``--from-json`` prints these from a saved run. ``--synthetic SETS`` is the
control with a known camera: on each set's views the same corners err by σ px for the anchors (OpenCV
5-coef and rational) and by ratio·σ for "ours" (OpenCV 5-coef too), an estimator better by
construction; it prints ours ÷ the best anchor (true error and halves difference, geometric means) and
how often ours is at or below the best anchor on one random split, on both fixed splits of a set, and on
all six fixed splits of three sets.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

import real_repeatability as rr  # noqa: E402

from aicalib_tf.calib import board_shape, weights  # noqa: E402

OURS = ("flat", "auto", "sag", "flex", "shape")
FLEX_COLUMNS = ("auto", "sag", "flex", "shape")
FLEX_OPTION = {"flat": "off", "auto": "auto", "sag": "sag", "shape": "shape"}  # calibrate_camera's flex for a column
CROSSED = ("flat_classic", "flat, classic corners")
ANCHORS = (("cv_plumb_bob", "OpenCV 5-coef"), ("cv_rational", "OpenCV rational"), ("cv_fisheye", "OpenCV fisheye"),
           ("mrcal_opencv8", "mrcal OPENCV8"))


def detections(files, pattern):
    """(views, image circle or None): each photo through the calibrate command's detector."""
    from aicalib_tf.calib.fit import View
    from aicalib_tf.calib.workflow import make_detector
    from aicalib_tf.cnn.spec import DETECTOR_NETWORK
    from aicalib_tf.geometry.image_circle import find_image_circle, thumbnail
    from aicalib_tf.io import load_image

    detect = make_detector("cnn", tuple(pattern), DETECTOR_NETWORK)
    views, thumbs, size = [], [], None
    for f in files:
        gray = load_image(str(f))
        size = gray.shape[::-1]
        hit = detect(gray)
        thumbs.append(np.clip(thumbnail(gray), 0.0, 1.0))
        views.append(None if hit is None else View(f.name, *hit, relative=detect.relative, sigmas=detect.sigmas))
    return views, find_image_circle(np.mean(thumbs, axis=0), size)[0]


def random_split(n: int, seed: int) -> tuple[list[int], list[int]]:
    p = np.random.default_rng(seed).permutation(n)
    k = (n + 1) // 2
    return sorted(p[:k].tolist()), sorted(p[k:].tolist())


def _ours(views, halves, cfg, size, circle, model, modes=OURS) -> dict:
    """The aicalib_tf columns ``modes`` (views: None for a photo without a board) and, with "flat", the flat
    halves' predicted difference for one split."""
    from aicalib_tf.calib import fit as F
    from aicalib_tf.calib.diff import board_coverage
    from aicalib_tf.calib.quality import predicted_half_difference
    from aicalib_tf.calib.robust import SolveOptions

    pattern, square = cfg[0], 1.0
    out = {}
    for mode in modes:
        cals = []
        for idx in halves:
            vs = [views[i] for i in idx if views[i] is not None]
            if mode == "flex":  # the flex as the solve keeps it (its σ rule), no test against its noise
                fit = F._fit_model(model, vs, 1.0, size, None, False, False, SolveOptions(pattern, "sag", True))
                cals.append(F._calibration(fit, vs, pattern, square, size, {}, "", None, (), circle))
            else:
                cals.append(F.calibrate_camera(vs, pattern, square, size, model=model, image_circle=circle,
                                               flex=FLEX_OPTION[mode]))
        covered = np.zeros(rr.GRID[0] * rr.GRID[1], bool)
        for c in cals:
            covered |= board_coverage(c.lens, c.pattern_size, c.square_size, c.rvecs, c.tvecs, rr.GRID)
        out[mode] = rr._diff_entry(cals[0].lens, cals[1].lens, np.flatnonzero(covered), size)
        out[mode]["flex_kept"] = [c.flex is not None for c in cals]
        out[mode]["flex_terms"] = [0 if c.flex is None else int(np.count_nonzero(c.flex)) for c in cals]
        out[mode]["fx"] = float(cals[0].K[0, 0])
        if mode == "flat":
            out["predicted"] = predicted_half_difference(cals[0], cals[1], covered, grid=rr.GRID)
    return out


def run_set(name, folder, n_splits, venv, tmp: Path, flex_splits: int = 24, ours=OURS, first_seed: int = 0) -> dict:
    from aicalib_tf.calib.fit import View, calibrate_camera
    from aicalib_tf.geometry.pattern import pattern_ids

    cfg = rr.SETS[name]
    files, size, _ = rr.photos(folder)
    views, circle = detections(files, cfg[0])
    model = calibrate_camera([v for v in views if v is not None], cfg[0], 1.0, size, image_circle=circle).model
    classic = [rr.classic_corners(p, cfg[0]) for p in files]
    ids = pattern_ids(tuple(cfg[0]))
    classic_views = [None if c is None else View(f.name, c, ids) for f, c in zip(files, classic)]
    rows = []
    for seed in range(first_seed, first_seed + n_splits):
        halves = random_split(len(files), seed)
        modes = tuple(m for m in ours if seed - first_seed < flex_splits or m not in FLEX_COLUMNS)
        row = {"seed": seed, **_ours(views, halves, cfg, size, circle, model, modes)}
        row[CROSSED[0]] = rr._attempt(lambda: _ours(classic_views, halves, cfg, size, circle, model, ("flat",))["flat"])
        cv = rr._opencv_split([[classic[i] for i in h] for h in halves], cfg[0], size)
        row.update(cv_plumb_bob=cv["plumb_bob"], cv_rational=cv["rational_polynomial"], cv_fisheye=cv["equidistant"])
        if venv is not None and seed - first_seed < flex_splits:
            rr.MRCAL_MODELS = ("opencv8",)
            work = tmp / f"{name}_{seed}"
            work.mkdir(parents=True)
            names = [[f"frame{i:03d}.jpg" for i in h] for h in halves]
            m = rr._mrcal_split(venv, names, [[classic[i] for i in h] for h in halves], cfg, size,
                                [(row["flat"]["fx"], 90.0)] * 2, None, work, repeats=1)
            row["mrcal_opencv8"] = m.get("opencv8", m)
        rows.append(row)
        print(f"{name} seed {seed}: " + ", ".join(f"{k} {rr._cell(row.get(k))}" for k in (*OURS, CROSSED[0],
                                                                                          *dict(ANCHORS)) if k in row),
              flush=True)
    return {"set": name, "photos": len(files), "model": model, "splits": rows}


def median_gap(a: np.ndarray, b: np.ndarray, draws: int = 1000, seed: int = 0) -> tuple[float, float, float]:
    """(median(a) − median(b), its 5% and 95% points) over the splits both hold, px: a and b (S,) per split
    (NaN: missing), resampled together by split (``draws`` draws)."""
    ok = ~(np.isnan(a) | np.isnan(b))
    a, b = a[ok], b[ok]
    if not len(a):
        return float("nan"), float("nan"), float("nan")
    j = np.random.default_rng(seed).integers(0, len(a), (draws, len(a)))
    gaps = np.median(a[j], axis=1) - np.median(b[j], axis=1)
    return float(np.median(a) - np.median(b)), float(np.percentile(gaps, 5)), float(np.percentile(gaps, 95))


def _stats(v: np.ndarray) -> str:
    n = int(np.sum(~np.isnan(v)))
    return (f"median {np.nanmedian(v):.3g} px (quartiles {np.nanpercentile(v, 25):.3g}-{np.nanpercentile(v, 75):.3g}, "
            f"{n} splits)") if n else "no split"


def summary(res: dict) -> list[str]:
    """Lines: every column's median (quartiles) over its splits; the flat default against each anchor: how
    often it is at or below it on a split, and the gap of their medians with its 90% interval."""
    rows = res["splits"]
    med = lambda k: np.array([np.nan if rr._median(r.get(k)) is None else rr._median(r.get(k)) for r in rows])  # noqa: E731
    lines = [f"{res['set']} ({res['photos']} photos, {len(rows)} random splits, model {res['model']}):"]
    for k, title in (*((m, f"aicalib_tf {m}") for m in OURS), CROSSED):
        lines.append(f"  {title:22s} {_stats(med(k))}")
    pred = np.array([r["predicted"]["median_covered"] for r in rows])
    band = np.array([[r["predicted"]["p10_covered"], r["predicted"]["p90_covered"]] for r in rows])
    flat = med("flat")
    inside = np.mean((flat >= band[:, 0]) & (flat <= band[:, 1]))
    lines.append(f"  predicted (flat)       mean {np.mean(pred):.3g} px, one split's 10-90% {np.median(band[:, 0]):.3g}-"
                 f"{np.median(band[:, 1]):.3g}; measured inside it on {inside:.0%} of the splits")
    best = np.full(len(rows), np.inf)
    for k, title in (CROSSED, *ANCHORS):
        v = med(k)
        if np.all(np.isnan(v)):
            continue
        if k != CROSSED[0]:
            best = np.fmin(best, np.where(np.isnan(v), np.inf, v))
        ok = ~np.isnan(v)
        gap, lo, hi = median_gap(flat, v)
        lines.append(f"  flat against {title:22s} ≤ it on {np.sum(flat[ok] <= v[ok])} of {ok.sum()}; medians' gap "
                     f"{gap:+.3g} px (90%: {lo:+.3g} to {hi:+.3g})")
    best = np.where(np.isinf(best), np.nan, best)
    for m in OURS:
        v = med(m)
        ok = ~np.isnan(v) & ~np.isnan(best)
        if not ok.any():
            continue
        lines.append(f"  {m} ≤ the best anchor on {np.sum(v[ok] <= best[ok])} of {ok.sum()} splits")
        gaps = [(title, *median_gap(v, ref)) for title, ref in (("flat", flat), ("the best anchor", best))
                if m != "flat" or title != "flat"]
        lines.append(f"  {m}: medians' gap " + "; ".join(f"to {t} {g:+.3g} px (90%: {lo:+.3g} to {hi:+.3g})"
                                                         for t, g, lo, hi in gaps))
        if m != "flat":
            g, lo, hi, n = ratio_to_flat(v, flat)
            lines.append(f"  {m} ÷ flat, geometric mean {g:.3g} (90%: {lo:.3g}-{hi:.3g}, {n} splits); the board's shape "
                         f"kept in {kept_share(rows, m):.0%} of the halves")
    return lines


def ratio_to_flat(v: np.ndarray, flat: np.ndarray, draws: int = 2000, seed: int = 0) -> tuple[float, float, float, int]:
    """(geometric mean of v ÷ flat over the splits both hold, its 5% and 95% points with the splits resampled,
    the splits): v and flat (S,) px per split (NaN: missing)."""
    ok = ~(np.isnan(v) | np.isnan(flat)) & (v > 0) & (flat > 0)
    r = np.log(v[ok] / flat[ok])
    if not len(r):
        return float("nan"), float("nan"), float("nan"), 0
    b = np.exp(r[np.random.default_rng(seed).integers(0, len(r), (draws, len(r)))].mean(axis=1))
    return float(np.exp(r.mean())), float(np.percentile(b, 5)), float(np.percentile(b, 95)), int(len(r))


def kept_share(rows, mode: str) -> float:
    """The share of halves whose ``mode`` calibration kept a board flex or shape (0 when it never ran)."""
    kept = [k for r in rows if isinstance(r.get(mode), dict) for k in r[mode].get("flex_kept", [])]
    return float(np.mean(kept)) if kept else 0.0


def win_share(v: np.ndarray, ref: np.ndarray, z: float = 1.645) -> tuple[int, int, float, float]:
    """(k, n, lo, hi): on k of the n splits both hold (NaN: missing) v ≤ ref; Wilson's 90% interval of k / n.
    Splits of one set share its photos, so the interval is that of independent draws (too narrow if anything)."""
    ok = ~(np.isnan(v) | np.isnan(ref))
    n, k = int(ok.sum()), int(np.sum(v[ok] <= ref[ok]))
    return (k, n, *wilson(k, n, z))


def wilson(k: int, n: int, z: float = 1.645) -> tuple[float, float]:
    """Wilson's score interval of the share k / n (z 1.645: 90%); (NaN, NaN) for n = 0."""
    if not n:
        return float("nan"), float("nan")
    p, c = k / n, z * z / n
    mid, half = (p + c / 2) / (1 + c), z / (1 + c) * np.sqrt(p * (1 - p) / n + c / (4 * n))
    return float(max(0.0, mid - half)), float(min(1.0, mid + half))


def per_split(res: dict, column: str = "auto") -> tuple[list[str], float]:
    """Lines: on how many splits ``column`` (the flat one when the run has none) is at or below each anchor and
    the best anchor of the split, with Wilson's 90% interval; and the share against the best anchor (NaN: none)."""
    rows = res["splits"]
    med = lambda k: np.array([np.nan if rr._median(r.get(k)) is None else rr._median(r.get(k)) for r in rows])  # noqa: E731
    v = med(column)
    if np.all(np.isnan(v)):
        column, v = "flat", med("flat")
    best, lines = np.full(len(rows), np.nan), [f"{res['set']}: {column} per split"]
    for k, title in ANCHORS:
        a = med(k)
        if np.all(np.isnan(a)):
            continue
        best = np.fmin(best, a)
        lines.append("  ≤ {:16s} on {} of {} ({:.0%}, 90%: {:.0%}-{:.0%})".format(title, *_share(v, a)))
    k, n, lo, hi = win_share(v, best)
    lines.append(f"  ≤ the best anchor   on {k} of {n} ({k / max(n, 1):.0%}, 90%: {lo:.0%}-{hi:.0%}; anchors on "
                 f"{np.sum(~np.isnan(best))} splits, mrcal where it ran)")
    return lines, (k / n if n else float("nan"))


def _share(v, a):
    k, n, lo, hi = win_share(v, a)
    return k, n, k / max(n, 1), lo, hi


def synthetic_control(n_sets: int, n_splits: int, ratio: float, noise: float = 0.1, n_views: int = 14) -> dict:
    """A known camera (640x480 barrel plumb_bob), ``n_sets`` sets of ``n_views`` full-board views (the real sets'
    13-18 photos), each seen with two corner noises: "ours" σ = ratio·noise px, the anchors σ = noise px
    (OpenCV 5-coef and rational). Each set's random splits (seeds 0..n_splits-1) and its even/odd and
    first/second splits are scored as the real ones (rotation-fitted halves difference over the covered cells);
    "true" is each estimator's error against the camera (its halves' mean, same cells). A set of rows per set."""
    from aicalib_tf.calib.diff import split_views
    from aicalib_tf.geometry import lens as L
    from tests.calib.synthetic import synthetic_views

    truth = L.Lens("plumb_bob", [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]], [-0.25, 0.08, 0.001, -0.0005, 0.0],
                   (640, 480))
    size, pattern, out = truth.image_size, (9, 6), []
    for s in range(n_sets):
        clean = [v.corners for v in synthetic_views(truth, n_views, 0.0, seed=1000 + s, min_corners=54)]
        rng = np.random.default_rng(2000 + s)
        corners = {"ours": [c + ratio * noise * rng.standard_normal(c.shape) for c in clean]}
        corners["anchors"] = [c + noise * rng.standard_normal(c.shape) for c in clean]
        cells = rr._covered_cells(clean, size)
        splits = [(seed, random_split(n_views, seed)) for seed in range(n_splits)]
        splits += [(name, split_views(range(n_views), name)) for name in ("evenodd", "halves")]
        rows = []
        for seed, halves in splits:
            row = {"seed": seed}
            for key, kind, src in (("ours", "plumb_bob", "ours"), ("cv_plumb_bob", "plumb_bob", "anchors"),
                                   ("cv_rational", "rational_polynomial", "anchors")):
                fits = [rr.opencv_lens(kind, [corners[src][i] for i in h], pattern, size)[0] for h in halves]
                row[key] = rr._diff_entry(fits[0], fits[1], cells, size)
                row[key]["true"] = float(np.mean([rr._diff_entry(f, truth, cells, size)["median"] for f in fits]))
            rows.append(row)
        out.append({"set": f"synthetic {s}", "photos": n_views, "model": "plumb_bob", "splits": rows})
    return {"ratio": ratio, "noise": noise, "sets": out}


def synthetic_summary(syn: dict) -> list[str]:
    """Lines: the better estimator's true error and halves difference ÷ the best anchor's (geometric means),
    how often it is at or below the best anchor on one random split, on both fixed splits of a set, and on
    all six fixed splits of three sets (measured over the sets' triples, and as the per-split share to the 6th)."""
    get = lambda rows, k, f="median": np.array([r[k][f] for r in rows])  # noqa: E731
    true_r, diff_r, wins, both = [], [], [], []
    for res in syn["sets"]:
        rnd = [r for r in res["splits"] if isinstance(r["seed"], int)]
        fixed = [r for r in res["splits"] if not isinstance(r["seed"], int)]
        for rows, store in ((rnd, wins), (fixed, both)):
            best = np.fmin(get(rows, "cv_plumb_bob"), get(rows, "cv_rational"))
            store.append(get(rows, "ours") <= best)
        bt = np.fmin(get(rnd, "cv_plumb_bob", "true"), get(rnd, "cv_rational", "true"))
        true_r.append(np.log(get(rnd, "ours", "true") / bt))
        diff_r.append(np.log(get(rnd, "ours") / np.fmin(get(rnd, "cv_plumb_bob"), get(rnd, "cv_rational"))))
    w = np.concatenate(wins)
    k, n = int(w.sum()), len(w)
    lo, hi = wilson(k, n)
    pair = np.array([b.all() for b in both])
    n_sets = len(pair)
    return [f"synthetic control ({n_sets} sets of {syn['sets'][0]['photos']} views, corner noise: ours "
            f"{syn['ratio'] * syn['noise']:.3g} px, anchors {syn['noise']:.3g} px; "
            f"{len(wins[0])} random splits a set):",
            f"  ours ÷ the best anchor, geometric mean: true error {np.exp(np.mean(np.concatenate(true_r))):.3g}, "
            f"halves difference {np.exp(np.mean(np.concatenate(diff_r))):.3g}",
            f"  ours ≤ the best anchor on {k} of {n} random splits ({k / n:.0%}, 90%: {lo:.0%}-{hi:.0%}); on both fixed "
            f"splits of {pair.sum()} of {n_sets} sets; all six of three sets: {pair.mean() ** 3:.0%} "
            f"(the random-split share to the 6th: {(k / n) ** 6:.0%})"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sets", nargs="+", default=list(rr.SETS), choices=list(rr.SETS))
    ap.add_argument("--splits", type=int, default=200, help="random half-splits per set (default: 200)")
    ap.add_argument("--first-seed", type=int, default=0,
                    help="the first split's seed (default: 0; two runs with seeds apart make one longer sample)")
    ap.add_argument("--flex-splits", type=int, default=24,
                    help="the first this many splits also run the flex columns and mrcal (default: 24)")
    ap.add_argument("--modes", nargs="+", default=list(OURS), choices=list(OURS),
                    help="the aicalib_tf columns to run (flat always runs; default: all)")
    ap.add_argument("--shape-terms", type=int, default=board_shape.N_SHAPE_TERMS, choices=range(3, 8),
                    help=f"the shape column's terms (geometry.board_shape's first N; default: {board_shape.N_SHAPE_TERMS})")
    ap.add_argument("--shape-shrink-from", type=float, default=board_shape.SHAPE_SHRINK_FROM,
                    help=f"the shape column: a term within this many standard errors of 0 is 0 "
                         f"(default: {board_shape.SHAPE_SHRINK_FROM})")
    ap.add_argument("--mrcal-venv", default="/work/scratch/mrcal-venv")
    ap.add_argument("--skip-mrcal", action="store_true")
    ap.add_argument("--data", default=str(rr.SHARED))
    ap.add_argument("--json", default=None)
    ap.add_argument("--weighting", choices=weights.WEIGHTINGS, default=weights.WEIGHTING,
                    help=f"the corners' weighting rule in every aicalib_tf fit (default: {weights.WEIGHTING}; aicalib_tf.calib.weights)")
    ap.add_argument("--per-split", nargs="?", const="auto", default=None, metavar="COLUMN",
                    help="also print how often COLUMN (default: auto; flat when the run has none) is at or below each "
                         "anchor and the best anchor on the same split, and the chance that all fixed splits pass")
    ap.add_argument("--from-json", default=None, help="summarise a run's --json file instead of running")
    ap.add_argument("--synthetic", type=int, default=0, metavar="SETS",
                    help="run the synthetic control instead: SETS known-camera sets, --splits random splits each")
    ap.add_argument("--synthetic-ratio", type=float, nargs="+", default=[0.8],
                    help="the control's corner noise of ours ÷ the anchors' (default: 0.8)")
    args = ap.parse_args(argv)
    if args.synthetic:
        for ratio in args.synthetic_ratio:
            print("\n".join(synthetic_summary(synthetic_control(args.synthetic, args.splits, ratio))), flush=True)
        return 0
    if args.from_json:
        return _report(json.loads(Path(args.from_json).read_text()), args.per_split)
    weights.WEIGHTING = args.weighting
    board_shape.N_SHAPE_TERMS, board_shape.SHAPE_SHRINK_FROM = args.shape_terms, args.shape_shrink_from
    venv = None if args.skip_mrcal else Path(args.mrcal_venv)
    if venv is not None and not (venv / "bin" / "mrcal-calibrate-cameras").exists():
        print(f"mrcal not found in {venv}: its column is skipped")
        venv = None
    results = []
    with tempfile.TemporaryDirectory(prefix="real_split_noise_") as tmp:
        for name, folder in rr.find_sets(args.sets, Path(args.data)):
            ours = tuple(m for m in OURS if m == "flat" or m in args.modes)
            results.append(run_set(name, folder, args.splits, venv, Path(tmp), args.flex_splits, ours, args.first_seed))
            if args.json:
                Path(args.json).write_text(json.dumps(results, indent=1, default=float) + "\n")
    print()
    return _report(results, args.per_split)


def _report(results: list[dict], column: str | None) -> int:
    """Print every set's summary and, with ``column``, its per-split lines and the chance, if each fixed split
    passes as often as a random one, that both fixed splits of every set pass (Π share²)."""
    shares = []
    for res in results:
        print("\n".join(summary(res)))
        if column:
            lines, p = per_split(res, column)
            print("\n".join(lines))
            shares.append(p)
    if shares:
        print(f"all {2 * len(shares)} fixed splits at or below the best anchor, were each a random split: "
              f"{np.prod(np.square(shares)):.1%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
