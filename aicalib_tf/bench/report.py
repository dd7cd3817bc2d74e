"""Tables and report.md for ``python -m aicalib_tf.evaluate`` (pandas); the figures the page links are
drawn by :mod:`aicalib_tf.bench.figures`.

Every file is written atomically (aicalib_tf.io): CSVs are rendered to a string first, figures
to PNG bytes in memory.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from aicalib_tf.bench.figures import SWEEP_AXES, error_histogram, example_figure, sweep_figure, time_figure
from aicalib_tf.bench.metrics import corner_error_stats
from aicalib_tf.bench.targets import check_targets
from aicalib_tf.io import atomic_write_text
from aicalib_tf.jsonio import dumps

__all__ = ["summarize", "write_report", "write_photo_report", "SUMMARY_COLUMNS", "RESULT_COLUMNS"]

RESULT_COLUMNS = ["condition", "sweep", "level", "index", "seed", "camera_id", "width", "height", "has_board",
                  "tilt_deg", "square_px", "k1", "detector", "found", "complete", "n_corners", "outcome",
                  "err_median", "err_max", "visible", "correct", "wrong_ids", "hidden_found", "recall", "time_ms", "time_first_ms", "time_runs"]
SUMMARY_COLUMNS = ["condition", "sweep", "level", "severity", "width", "height", "detector", "images", "boards",
                   "hits", "wrong", "wrong_worst_px", "partial", "misses", "detection_rate", "err_median", "err_rmse", "err_p95",
                   "err_max", "recall", "wrong_ids", "false_boards", "false_partial", "time_median_ms", "time_max_ms"]


def _strings_for_objects(x):
    """Nested dicts/lists with anything JSON cannot hold (paths, dataclasses) as its str()."""
    if isinstance(x, dict):
        return {str(k): _strings_for_objects(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_strings_for_objects(v) for v in x]
    return x if x is None or isinstance(x, (bool, int, float, str, np.generic, np.ndarray)) else str(x)


def _csv(df: pd.DataFrame, path: Path) -> None:
    atomic_write_text(path, df.to_csv(index=False, float_format="%.6g"))


def summarize(results: pd.DataFrame, errors: dict) -> pd.DataFrame:
    """One row per condition × detector (columns :data:`SUMMARY_COLUMNS`).

    results : the per image × detector table. errors : {(condition, detector): [px arrays]}
    of the corners counted in error statistics (hits' corners, partial boards' correct corners).
    detection_rate = hits / images with a board; recall = correct / visible corners, pooled;
    wrong_worst_px = median over wrong detections of their worst corner's error (a board 2.1 px off
    at one corner and a misplaced board are both "wrong"; this tells them apart).
    """
    out = []
    for (cond, det), g in results.groupby(["condition", "detector"], sort=False):
        boards = int(g["has_board"].sum())
        hits = int((g["outcome"] == "hit").sum())
        hit_err = [e for e, o in zip(errors.get((cond, det), []), g["outcome"]) if o == "hit"]
        st = corner_error_stats(np.concatenate(hit_err) if hit_err else np.zeros(0))
        vis = int(g["visible"].sum())
        sev = g["tilt_deg"] if g["sweep"].iloc[0] == "tilt" else g["k1"] if g["sweep"].iloc[0] == "distortion" else None
        out.append({
            "condition": cond, "sweep": g["sweep"].iloc[0], "level": g["level"].iloc[0],
            "severity": float(np.nanmedian(sev)) if sev is not None and len(sev) else g["level"].iloc[0],
            "width": int(g["width"].iloc[0]), "height": int(g["height"].iloc[0]), "detector": det,
            "images": len(g), "boards": boards, "hits": hits, "wrong": int((g["outcome"] == "wrong").sum()),
            "wrong_worst_px": float(g.loc[g["outcome"] == "wrong", "err_max"].median()) if (g["outcome"] == "wrong").any()
            else np.nan,
            "partial": int((g["outcome"] == "partial").sum()), "misses": int((g["outcome"] == "miss").sum()),
            "detection_rate": hits / boards if boards else np.nan,
            "err_median": st["median"], "err_rmse": st["rmse"], "err_p95": st["p95"], "err_max": st["max"],
            "recall": int(g["correct"].sum()) / vis if vis else np.nan,
            "wrong_ids": int(g.loc[g["has_board"], "wrong_ids"].sum()),
            "false_boards": int((g["outcome"] == "false_board").sum()),
            "false_partial": int((g["outcome"] == "false_partial").sum()),
            "time_median_ms": float(g["time_ms"].median()), "time_max_ms": float(g["time_ms"].max()),
        })
    return pd.DataFrame(out, columns=SUMMARY_COLUMNS)


# --- markdown -------------------------------------------------------------------------------

def _fmt(v, spec=".3g") -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "–"
    return format(v, spec) if isinstance(v, (float, np.floating)) else str(v)


def _md_table(df: pd.DataFrame, formats: dict | None = None) -> str:
    formats = formats or {}
    lines = ["| " + " | ".join(df.columns) + " |", "|" + "---|" * len(df.columns)]
    for _, r in df.iterrows():
        lines.append("| " + " | ".join(_fmt(r[c], formats.get(c, ".3g")) for c in df.columns) + " |")
    return "\n".join(lines)


def _headline(summary: pd.DataFrame, conds) -> str:
    """Rows: named conditions; one column per detector: hits/boards (wrong), or recall, or false boards."""
    dets = list(dict.fromkeys(summary["detector"]))
    lines = ["| condition | " + " | ".join(dets) + " |", "|---|" + "---|" * len(dets)]
    for c in conds:
        if c.sweep:
            continue
        g = summary[summary["condition"] == c.name].set_index("detector")
        cells = []
        for d in dets:
            if d not in g.index:
                cells.append("–")
                continue
            r = g.loc[d]
            if not c.has_board:
                cells.append(f"{int(r['false_boards'])} false / {int(r['images'])}")
            elif c.name in ("occluded", "partial"):
                cells.append(f"recall {100 * r['recall']:.1f}%, {int(r['wrong_ids'])} wrong ids")
            else:
                cell = f"{int(r['hits'])}/{int(r['boards'])}"
                if r["wrong"]:
                    cell += f" ({int(r['wrong'])} wrong)"
                if np.isfinite(r["err_median"]):
                    cell += f", {r['err_median']:.3f} px"
                cells.append(cell)
        lines.append(f"| {c.name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _targets_section(summary: pd.DataFrame, results: pd.DataFrame) -> list[str]:
    """The issue-4 targets this run checks for the cnn detector (:mod:`aicalib_tf.bench.targets`), if it ran."""
    t = check_targets(summary, results)
    if not len(t):
        return []
    t = t.assign(met=np.where(t["met"], "yes", "**no**"))
    return ["\n## Targets (cnn)\n",
            f"{int((t['met'] == 'yes').sum())} of {len(t)} met in this run. Real photos are checked by "
            "`evaluate --images` and `calibrate`; times are this run's, on this machine.\n", _md_table(t)]


def _headline_times(results: pd.DataFrame) -> str:
    """Two extra headline rows: median / max ms per image at each image size."""
    dets = list(dict.fromkeys(results["detector"]))
    lines = []
    for (w, h), g in results.groupby(["width", "height"]):
        t = g.groupby("detector")["time_ms"]
        med, mx = t.median(), t.max()
        lines.append(f"| time {w}×{h}, median / max ms | "
                     + " | ".join(f"{med[d]:.1f} / {mx[d]:.0f}" if d in med else "–" for d in dets) + " |")
    return "\n".join(lines)


def _timing_table(results: pd.DataFrame) -> pd.DataFrame:
    rows = []
    dets = list(dict.fromkeys(results["detector"]))
    for (w, h, det), g in sorted(results.groupby(["width", "height", "detector"]),
                                 key=lambda kv: (kv[0][0] * kv[0][1], dets.index(kv[0][2]))):
        t = g["time_ms"]
        rows.append({"size": f"{w}×{h}", "detector": det, "images": len(g), "median ms": t.median(),
                     "p95 ms": t.quantile(0.95), "max ms": t.max(), "max / median": t.max() / t.median(),
                     "first-run max ms": g["time_first_ms"].max()})  # before the slowest were re-timed
    return pd.DataFrame(rows)


def _uncommitted(versions: dict) -> str:
    files = versions.get("git_uncommitted")
    return f"  \nUncommitted source files at run time: {', '.join(files)}." if files else ""


def _config(cfg, versions: dict, info: dict, extra: dict) -> dict:
    return {"command": cfg.command, "out": str(cfg.out), "quick": cfg.quick, "limit": cfg.limit,
            "detectors": list(cfg.detectors), "models": info, "versions": versions, **extra}


def _rig_section(rows: list[dict], out: Path) -> list[str]:
    """rigs.csv and the report's rig section (:mod:`aicalib_tf.bench.rigs`), or nothing without rig rows."""
    if not rows:
        return []
    rigs = pd.DataFrame(rows)
    _csv(rigs, out / "rigs.csv")
    cols = ["rig", "pair", "pipeline", "lenses", "baseline_mm", "baseline_err_pct", "rot_err_deg", "dy_in_px",
            "dy_held_px", "frames", "t_detect_s", "t_calib_s", "note"]
    return ["\n## Camera rigs against the truth\n",
            "data_gen rigs (20 pairs, 1280×960, noise σ 2): ours (CNN, lens model per camera, one joint fit) against "
            "OpenCV (classic corners, calibrateCamera / fisheye.calibrate, stereoCalibrate with CALIB_FIX_INTRINSIC). "
            "Baseline error in % of the true baseline, rotation error in degrees, rectified |Δy| RMS in px in-sample "
            "and on held-out pairs (5-fold leave-pairs-out). Targets: ≤ 0.1 %, ≤ 0.01°, held-out ≤ 0.05 px.\n",
            _md_table(rigs[[c for c in cols if c in rigs.columns]],
                      {"baseline_mm": ".1f", "baseline_err_pct": ".4f", "rot_err_deg": ".4f", "dy_in_px": ".3f",
                       "dy_held_px": ".3f", "t_detect_s": ".1f", "t_calib_s": ".1f"})]


def write_report(out: Path, cfg, conds, result: dict, info: dict, versions: dict) -> None:
    """Write results.csv, summary.csv, calibration.csv, figures/, report.md and config.json."""


    # size: the page section by section, in reading order; each section is a few lines of markdown.
    from aicalib_tf.bench.conditions import CALIB_CAMERAS, CALIB_SEED, FISHEYE_SEQUENCES
    from aicalib_tf.bench.timing import RETIME_RUNS, RETIME_SLOWEST

    out = Path(out)
    fig_dir = out / "figures"
    results = pd.DataFrame(result["rows"], columns=RESULT_COLUMNS)
    summary = summarize(results, result["errors"])
    calib = pd.DataFrame(result["calibration"])
    _csv(results, out / "results.csv")
    _csv(summary, out / "summary.csv")
    _csv(calib, out / "calibration.csv")

    figures = []
    for sweep in dict.fromkeys(c.sweep for c in conds if c.sweep):
        p = fig_dir / f"sweep_{sweep}.png"
        sweep_figure(summary, sweep, p)
        figures.append((f"Sweep: {sweep}", p))
    named = {c.name for c in conds if not c.sweep} | {"calib"} | {f"calib_{f}" for f in FISHEYE_SEQUENCES}
    if len(results):
        error_histogram(result["errors"], named, fig_dir / "error_histogram.png")
        figures.append(("Corner error histogram", fig_dir / "error_histogram.png"))
        time_figure(results, fig_dir / "time.png")
        figures.append(("Time per image", fig_dir / "time.png"))
    for k, (score, cname, index, image, truth, found_by) in enumerate(result["examples"]):
        p = fig_dir / f"example_{k}_{cname}.png"
        example_figure(f"{cname} #{index}", image, truth, found_by, p)
        figures.append((f"Hard example: {cname} image {index}", p))

    cond_table = pd.DataFrame([{"condition": c.name, "sweep": c.sweep or "", "size": f"{c.size[0]}×{c.size[1]}",
                                "seed": c.seed, "images": int((results["condition"] == c.name).sum() // max(1, len(cfg.detectors))),
                                "description": c.description} for c in conds])
    named_sum = summary[summary["sweep"].isna() | (summary["sweep"] == "")]
    cols = ["condition", "detector", "images", "hits", "wrong", "wrong_worst_px", "partial", "misses", "detection_rate", "err_median",
            "err_rmse", "err_p95", "recall", "wrong_ids", "false_boards", "false_partial", "time_median_ms", "time_max_ms"]
    md = ["# Chessboard detection benchmark: CNN against OpenCV\n",
          f"Command: `{cfg.command}`  \nWall time: {result['wall_s']:.0f} s (rendering {result['render_s']:.0f} s); "
          f"{len(results)} detections on {len(results) // max(1, len(cfg.detectors))} images. "
          f"Machine: {versions.get('platform')}, {versions.get('cpus')} CPUs ({versions.get('cpu') or 'CPU model unknown'}).  ",
          "Versions: " + ", ".join(f"{k} {v}" for k, v in versions.items()
                                   if k not in ("platform", "cpu", "cpus", "git_uncommitted")) + ".  ",
          "Models: " + "; ".join(f"{d}: `{Path(m['model']).name}` sha256 `{m['sha256'][:16]}…`" for d, m in info.items())
          + ("." if info else "none.") + _uncommitted(versions),
          "\n## Headline\n",
          "Hits / images (wrong detections), median corner error of hits; occluded and partial: corner recall and wrong ids; "
          "clutter: full boards reported on board-free images.\n",
          _headline(summary, conds) + ("\n" + _headline_times(results) if len(results) else ""),
          *_targets_section(summary, results),
          "\n## Detection by condition\n",
          "A hit: a full board with every corner within 2 px of the truth (board symmetries allowed); wrong: a full board "
          "with any corner further off (wrong_worst_px: the median over wrong boards of their worst corner's error); "
          "partial: an incomplete board. Errors in px over hit corners; recall over visible corners; times per image in "
          "this one process, each image through every detector in turn, a condition's images rendered before any "
          f"is timed; each detector's {RETIME_SLOWEST} slowest images per size timed {RETIME_RUNS} more times at the end, "
          "keeping the least time.\n",
          _md_table(named_sum[cols], {"detection_rate": ".0%", "recall": ".1%", "wrong_worst_px": ".2f",
                                       "err_median": ".4f", "err_rmse": ".4f", "err_p95": ".4f",
                                       "time_median_ms": ".1f", "time_max_ms": ".0f"})]
    sweeps = summary[summary["sweep"].notna() & (summary["sweep"] != "")]
    if len(sweeps):
        md += ["\n## Severity sweeps\n", "Detection rate (median error of hits, px) per level; each level shows the same scenes.\n"]
        for sweep, g in sweeps.groupby("sweep", sort=False):
            piv = g.assign(cell=[f"{r:.0%} ({e:.3f})" if np.isfinite(e) else f"{r:.0%}" for r, e in
                                 zip(g["detection_rate"], g["err_median"])])
            piv = piv.pivot_table(index="severity", columns="detector", values="cell", aggfunc="first", sort=False)
            piv = piv.reset_index().rename(columns={"severity": SWEEP_AXES.get(sweep, (sweep,))[0]})
            md += [f"\n### {sweep}\n", _md_table(piv, {piv.columns[0]: ".3g"}), f"\n![{sweep}](figures/sweep_{sweep}.png)\n"]
    if len(calib):
        md += ["\n## Calibration against the true camera\n",
               f"{len(calib['camera_id'].unique())} sequences (data_gen `calib`, 640×480, seed {CALIB_SEED}, cameras "
               f"{', '.join(map(str, CALIB_CAMERAS))}: mild and strong barrel; `calib_fisheye` 185° and 150°, 1280×960, σ 2, "
               f"in full runs), {int(calib['views'].iloc[0])} views each. Each detector's boards (partial ones too) go through "
               "`calibrate_camera` (outlier views rejected; model: the lens model it chose). fx %: signed focal error; pp: "
               "principal point error; proj err: the projection error field (unproject a pixel grid with the true lens, project "
               "with the estimate), px, over the area the boards covered (seen: hull of all true corners) and over the whole "
               "image or image circle (mean, max; fail: share of it the estimate cannot project); dist field: the same "
               "comparison of the undistortion fields (pinhole-plane, so only rays in front of 90°).\n"]
        ccols = [c for c in ["camera_id", "lens", "detector", "model", "views", "views_found", "views_partial", "views_used",
                             "rejected", "rms_px", "fx_pct", "pp_px", "proj_err_seen_mean_px", "proj_err_mean_px",
                             "proj_err_max_px", "proj_err_fail_frac", "dist_field_mean_px", "dist_field_seen_mean_px",
                             "status"] if c in calib.columns]
        md.append(_md_table(calib[ccols], {"rms_px": ".3f", "fx_pct": "+.3f", "pp_px": ".2f", "proj_err_seen_mean_px": ".3f",
                                            "proj_err_mean_px": ".3f", "proj_err_max_px": ".2f", "proj_err_fail_frac": ".0%",
                                            "dist_field_mean_px": ".3f", "dist_field_seen_mean_px": ".3f"}))
        if "fx_pct" in calib.columns:
            agg = calib[calib["status"] == "ok"].assign(abs_fx=lambda d: d["fx_pct"].abs()).groupby("detector", sort=False).agg(
                sequences=("camera_id", "count"), mean_abs_fx_pct=("abs_fx", "mean"), mean_pp_px=("pp_px", "mean"),
                mean_proj_err_seen_px=("proj_err_seen_mean_px", "mean"), mean_proj_err_px=("proj_err_mean_px", "mean"),
                mean_dist_field_px=("dist_field_mean_px", "mean"), mean_dist_field_seen_px=("dist_field_seen_mean_px", "mean"),
                mean_rms_px=("rms_px", "mean")).reset_index()
            md += ["\nPer detector, over the calibrated sequences:\n", _md_table(agg, {"mean_abs_fx_pct": ".3f"})]
    if len(results):
        md += ["\n## Time per image\n",
               "max ms is after the slowest images were timed again; first-run max ms is the slowest first timing.\n",
               _md_table(_timing_table(results), {"median ms": ".1f", "p95 ms": ".1f", "max ms": ".0f",
                                                  "max / median": ".1f", "first-run max ms": ".0f"})]
    md += ["\n## Figures\n"] + [f"- [{t}](figures/{p.name})" for t, p in figures]
    md += [f"\n![{t}](figures/{p.name})" for t, p in figures if not p.name.startswith("sweep_")]
    md += ["\n## Conditions\n", _md_table(cond_table)]
    md += _rig_section(result.get("rigs") or [], out)
    md += ["\n## Files\n", "results.csv (one row per image × detector), summary.csv (per condition × detector), "
           "calibration.csv, " + ("rigs.csv, " if result.get("rigs") else "") + "config.json, figures/."]
    atomic_write_text(out / "report.md", "\n".join(md) + "\n")
    extra = {"conditions": [{"name": c.name, "sweep": c.sweep, "level": None if math.isnan(c.level) else c.level,
                             "seed": c.seed, "size": list(c.size), "min_tilt_deg": c.min_tilt_deg,
                             "preset": c.preset.to_dict()} for c in conds],
             "counts": cfg.counts(), "image_counts": {c.name: int(n) for c, n in zip(
                 conds, [(results["condition"] == c.name).sum() // max(1, len(cfg.detectors)) for c in conds])},
             "calibration": {"preset": "calib", "seed": CALIB_SEED, "cameras": list(CALIB_CAMERAS),
                             "views": cfg.counts()["calib_views"]},
             "wall_s": result["wall_s"], "render_s": result["render_s"]}
    atomic_write_text(out / "config.json", dumps(_strings_for_objects(_config(cfg, versions, info, extra))) + "\n")


def write_photo_report(out: Path, cfg, result: dict, info: dict, versions: dict) -> None:
    """The --images report: photos.csv, agreement.csv, calibration.csv, degrade.csv, figures, report.md, config.json."""


    # size: the photo page section by section, in reading order.
    from aicalib_tf.bench.photos import AGREE_PX, PHOTO_DEGRADATIONS

    out = Path(out)
    fig_dir = out / "figures"
    rows = pd.DataFrame(result["rows"])
    agree = pd.DataFrame(result["agreement"])
    calib = pd.DataFrame(result["calibration"])
    refs = pd.DataFrame(result["references"])
    _csv(rows, out / "results.csv")
    _csv(agree, out / "agreement.csv")
    _csv(calib, out / "calibration.csv")
    _csv(refs, out / "references.csv")
    clean = rows[rows["degradation"] == "clean"] if len(rows) else rows
    md = ["# Chessboard detection on real photos: CNN against OpenCV\n",
          f"Command: `{cfg.command}`  \nPhotos: {result['files']} in `{cfg.images}`, pattern {cfg.pattern[0]}×{cfg.pattern[1]}; "
          f"{len(result['skipped'])} unreadable. Wall time {result['wall_s']:.0f} s.  ",
          "Versions: " + ", ".join(f"{k} {v}" for k, v in versions.items() if k not in ("platform", "cpus", "git_uncommitted")) + ".  ",
          "Models: " + "; ".join(f"{d}: `{Path(m['model']).name}` sha256 `{m['sha256'][:16]}…`" for d, m in info.items()) + "."
          + _uncommitted(versions)]
    for name, why in result["skipped"].items():
        md.append(f"- skipped {name}: {why}")
    figures = []
    if len(clean):
        per = clean.groupby("detector", sort=False).agg(photos=("file", "count"), full_boards=("complete", "sum"),
                                                        partial=("found", "sum"), time_median_ms=("time_ms", "median"),
                                                        time_max_ms=("time_ms", "max")).reset_index()
        per["partial"] = per["partial"] - per["full_boards"]
        md += ["\n## Detections on the photos\n", _md_table(per, {"time_median_ms": ".1f", "time_max_ms": ".0f"})]
        time_figure(clean, fig_dir / "time.png")
        figures.append(("Time per photo", fig_dir / "time.png"))
    if len(agree):
        both = agree[agree["both_found"]]
        if len(both):
            ag = both.groupby("pair", sort=False).agg(photos=("file", "count"), median_px=("median_px", "median"),
                                                      worst_max_px=("max_px", "max")).reset_index()
            md += ["\n## Agreement between detectors (full boards on the same photo, board symmetries allowed)\n",
                   _md_table(ag, {"median_px": ".3f", "worst_max_px": ".3f"})]
    if len(calib):
        md += ["\n## Calibration each detector gives (square size 1, so only intrinsics matter)\n",
               _md_table(calib, {"rms_px": ".3f", "fx": ".1f", "fy": ".1f", "cx": ".1f", "cy": ".1f", "k1": ".4f",
                                 "k2": ".4f", "p1": ".5f", "p2": ".5f", "k3": ".4f"})]
    if len(refs):
        md += ["\n## Reference boards\n", f"Rule (aicalib_tf.bench.photos): the largest group of detectors agreeing within "
               f"{AGREE_PX:g} px on the clean photo (their mean board; cnn and report share one corner refinement and count as "
               "one vote), or the one detector that finds a full board. "
               + ", ".join(f"{k}: {v}" for k, v in refs["rule"].value_counts().items()) + "."]
    if cfg.degrade and len(rows):
        scored = rows[rows["reference"]]
        deg = []
        for (var, det), g in scored.groupby(["degradation", "detector"], sort=False):
            hits = g[g["outcome"] == "hit"]
            deg.append({"degradation": var, "detector": det, "photos": len(g), "full_board_rate": len(hits) / len(g),
                        "wrong": int((g["outcome"] == "wrong").sum()), "partial": int((g["outcome"] == "partial").sum()),
                        "dev_median_px": float(hits["dev_median_px"].median()) if len(hits) else np.nan,
                        "dev_max_px": float(hits["dev_max_px"].max()) if len(hits) else np.nan,
                        "time_median_ms": float(g["time_ms"].median())})
        deg = pd.DataFrame(deg)
        _csv(deg, out / "degrade.csv")
        piv = deg.assign(cell=[f"{r:.0%}" + (f" ({d:.2f} px)" if np.isfinite(d) else "") + (f", {w} wrong" if w else "")
                               for r, d, w in zip(deg["full_board_rate"], deg["dev_median_px"], deg["wrong"])])
        piv = piv.pivot_table(index="degradation", columns="detector", values="cell", aggfunc="first", sort=False).reset_index()
        piv.insert(1, "what", [PHOTO_DEGRADATIONS[v][0] for v in piv["degradation"]])
        md += ["\n## Degraded photos against the clean reference\n",
               "Full boards within 2 px of the reference (median deviation of those, px), and wrong boards.\n",
               _md_table(piv), "\nFull table: degrade.csv.\n"]
        for k, (title, img, ref, outcomes) in enumerate(result["examples"]):
            p = fig_dir / f"example_{k}.png"
            example_figure(title, img, ref, outcomes, p)
            figures.append((f"Hard example: {title}", p))
    md += ["\n## Figures\n"] + [f"- [{t}](figures/{p.name})" for t, p in figures]
    md += [f"\n![{t}](figures/{p.name})" for t, p in figures]
    md += ["\n## Files\n", "results.csv (photo × degradation × detector), agreement.csv, references.csv, calibration.csv"
           + (", degrade.csv" if cfg.degrade else "") + ", config.json, figures/."]
    atomic_write_text(out / "report.md", "\n".join(md) + "\n")
    extra = {"images": str(cfg.images), "pattern": list(cfg.pattern), "degrade": cfg.degrade, "seed": cfg.seed,
             "degradations": {k: v[0] for k, v in PHOTO_DEGRADATIONS.items()} if cfg.degrade else {},
             "photos": result["files"], "skipped": result["skipped"], "wall_s": result["wall_s"]}
    atomic_write_text(out / "config.json", dumps(_strings_for_objects(_config(cfg, versions, info, extra))) + "\n")
