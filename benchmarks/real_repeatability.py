"""Real-photo repeatability: two calibrations from disjoint halves of the same photos, beside OpenCV and mrcal.

    .venv/bin/python benchmarks/real_repeatability.py [--sets opencv_left ocam_fisheye] [--mrcal-venv DIR]
        [--json results.json] [--skip-mrcal]

For every real set in ``../shared/data`` (opencv_left, udacity_lane_cal, ocam_fisheye; the photos are
read in place, never copied) and ``tests/data/opencv_left`` (the same 13 photos as the shared copy:
counted once), the photos (natural order, the most common image size only) are split two ways,
even/odd and first/second half, and each half is calibrated by:

- aicalib_tf: ``python -m aicalib_tf.calibrate HALF --model auto`` (its own detector, everything the
  command line does), the halves' camera.json read back; once with the default solve (``--flex auto``:
  each half keeps the board's shape only where it moves the lens by more than its leave-one-view-out
  noise) and once with ``--flex-column MODE`` (default off: a flat board; ``--no-flex-column`` skips it);
- OpenCV: ``calibrateCamera`` with 5 coefficients and with the rational model, and
  ``cv2.fisheye.calibrate``, on OpenCV's classic corners (``findChessboardCorners`` with adaptive
  threshold and normalisation, ``cornerSubPix`` 5x5, 30 iterations / 1e-3);
- mrcal (a yardstick, never a dependency: run as a subprocess in its own Python, ``--mrcal-venv``,
  default /work/scratch/mrcal-venv; skipped with a message when absent):
  ``mrcal-calibrate-cameras`` with LENSMODEL_OPENCV8 and with
  LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx=10_Ny=(10·H/W)_fov_x_deg=(the aicalib_tf half's
  horizontal field of view; --spline-nx: 10 knots across suit halves of 6-10 photos better than
  16 or 24), on the same classic corners, with its board flex and outlier
  rejection (its defaults), seeded with the aicalib_tf half's fx. Its solves of one half do not
  always reach the same minimum, so each is run --mrcal-repeats times (default 3): the table gives
  the repeat with the median difference, and the range over the repeats where it exceeds 20%.

The number per split is the halves' projection difference, rotation fitted out, median over the
area the boards covered (a 32x24 grid of cells; a cell is covered when a corner of a view of either
half falls in it or its centre lies inside a view's convex hull, :func:`aicalib_tf.calib.diff.view_coverage`:
the classic corners for OpenCV and mrcal, the aicalib_tf halves' boards at their fitted poses for
aicalib_tf, whose files keep poses, not corners). aicalib_tf's and OpenCV's
numbers come from :func:`aicalib_tf.calib.diff.projection_diff` (what ``python -m
aicalib_tf.compare`` and calibrate's half-vs-half line use); mrcal's from ``mrcal.projection_diff``
on the same grid cells, its rotation fitted over the covered cells by
``mrcal.implied_Rt10__from_unprojections``. The two are cross-checked on the same pairs of
models (mrcal's OPENCV8 halves through projection_diff; OpenCV's rational halves through mrcal).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
GRID = (32, 24)
# folder name -> (pattern (cols, rows), square size in metres or 1.0 unitless, calibrate's --square)
SETS = {"opencv_left": ((9, 6), 1.0, "1"), "udacity_lane_cal": ((9, 6), 1.0, "1"),
        "ocam_fisheye": ((8, 6), 0.0325, "32.5mm")}
SPLITS = ("evenodd", "halves")
MRCAL_MODELS = ("opencv8", "splined")
COLUMNS = (("aicalib_tf", "aicalib_tf default"), ("aicalib_tf_flex", "aicalib_tf --flex off"), ("cv_plumb_bob", "OpenCV 5-coef"), ("cv_rational", "OpenCV rational"),
           ("cv_fisheye", "OpenCV fisheye"), ("mrcal_opencv8", "mrcal OPENCV8"), ("mrcal_splined", "mrcal splined"))


# ---------------------------------------------------------------- mrcal side (runs in mrcal's own Python)

def _cells(q, size, grid):
    """(M,) int: the index of the grid cell each pixel q (M, 2) lies in (row-major)."""
    import numpy as np

    w, h = size
    gx, gy = grid
    cx = np.clip(np.floor((q[:, 0] + 0.5) * gx / w), 0, gx - 1).astype(int)
    cy = np.clip(np.floor((q[:, 1] + 0.5) * gy / h), 0, gy - 1).astype(int)
    return cy * gx + cx


def _pixel_rotation(model1, v0, q0):
    """The rotation r (3,) minimising Σ |project_1(R(r)·v0) − q0|² px² (Gauss-Newton from 0 with
    mrcal's own project and rotate_point_r gradients): the objective aicalib_tf's projection_diff uses."""
    import mrcal
    import numpy as np

    r = np.zeros(3)
    for _ in range(30):
        p, dp_dr, _ = mrcal.rotate_point_r(r, v0, get_gradients=True)
        q, dq_dp, _ = mrcal.project(p, *model1.intrinsics(), get_gradients=True)
        J = np.einsum("nij,njk->nik", dq_dp, dp_dr).reshape(-1, 3)
        e = (q - q0).ravel()
        ok = np.isfinite(e) & np.all(np.isfinite(J), axis=1)
        step = np.linalg.lstsq(J[ok], -e[ok], rcond=None)[0]
        r = r + step
        if np.linalg.norm(step) < 1e-13:
            break
    return r


def _mrcal_diff(models, covered_cells, size, grid):
    """mrcal.projection_diff of two models on mrcal's gx x gy grid (mrcal.sample_imager), the rotation
    fitted over the covered cells two ways: by pixel least squares (:func:`_pixel_rotation`, as
    aicalib_tf does; "median", "p95", "rotation_deg") and by mrcal's own
    implied_Rt10__from_unprojections ("mrcal_fit": {"median", "p95", "rotation_deg"}); over the covered cells."""
    import mrcal
    import numpy as np

    gx, gy = grid
    v, q0 = mrcal.sample_imager_unproject(gx, gy, *size, [m.intrinsics()[0] for m in models],
                                          [m.intrinsics()[1] for m in models], normalize=True)
    cov = np.isin(_cells(q0.reshape(-1, 2), size, grid), covered_cells).reshape(gy, gx)
    cov &= np.all(np.isfinite(v[0]), axis=-1) & np.all(np.isfinite(v[1]), axis=-1)  # pixels both lenses unproject
    r = _pixel_rotation(models[1], v[0][cov], q0[cov])
    fits = {"pixel": mrcal.Rt_from_rt(np.concatenate([r, np.zeros(3)])),
            "mrcal": mrcal.implied_Rt10__from_unprojections(q0[cov], v[0][cov], v[1][cov])}
    out = {}
    for name, Rt10 in fits.items():
        difflen = mrcal.projection_diff(models, implied_Rt10=Rt10, gridn_width=gx, gridn_height=gy,
                                        use_uncertainties=False)[0]
        d = difflen[cov]
        d = d[np.isfinite(d)]
        out[name] = {"median": float(np.median(d)), "p95": float(np.percentile(d, 95)),
                     "rotation_deg": float(np.degrees(np.linalg.norm(mrcal.r_from_R(Rt10[:3])))), "cells": int(d.size)}
    return {**out["pixel"], "mrcal_fit": out["mrcal"]}


def _mrcal_solve(job, half, model, workdir):
    """Run mrcal-calibrate-cameras on one half's corners; returns (cameramodel, summary dict)."""
    import mrcal

    w, h = job["size"]
    if model == "opencv8":
        lensmodel = "LENSMODEL_OPENCV8"
    else:
        nx = int(job.get("spline_nx", 10))
        ny = max(4, round(nx * h / w))
        lensmodel = f"LENSMODEL_SPLINED_STEREOGRAPHIC_order=3_Nx={nx}_Ny={ny}_fov_x_deg={job['fov_deg'][half]:.0f}"
    out = Path(workdir) / f"{half}_{model}"
    out.mkdir(parents=True, exist_ok=True)
    cmd = [str(Path(sys.executable).parent / "mrcal-calibrate-cameras"), "--corners-cache", job["vnl"][half],
           "--lensmodel", lensmodel, "--focal", f"{job['focal'][half]:.3f}", "--imagersize", str(w), str(h),
           "--object-spacing", str(job["spacing"]), "--object-width-n", str(job["pattern"][0]),
           "--object-height-n", str(job["pattern"][1]), "--outdir", str(out), "--jobs", "1", "frame*.jpg"]
    run = subprocess.run(cmd, capture_output=True, text=True, cwd=workdir, timeout=1800)
    files = sorted(out.glob("*.cameramodel"))
    if run.returncode or not files:
        tail = (run.stderr or run.stdout).strip().splitlines()[-1:] or ["no output"]
        raise RuntimeError(f"mrcal-calibrate-cameras failed: {tail[0][:200]}")
    text = run.stdout + run.stderr
    rms = re.search(r"RMS reprojection error: ([0-9.]+)", text)
    nout = re.search(r"Noutliers: (\d+) out of (\d+)", text)
    m = mrcal.cameramodel(str(files[0]))
    oi = m.optimization_inputs()
    warp = oi.get("calobject_warp") if oi else None
    return m, {"rms": float(rms.group(1)) if rms else None,
               "outliers": f"{nout.group(1)}/{nout.group(2)}" if nout else None,
               "warp": None if warp is None else [float(x) for x in warp], "lensmodel": m.intrinsics()[0],
               "intrinsics": [float(x) for x in m.intrinsics()[1]]}


def mrcal_worker(job_path: str) -> int:
    """Read a job (JSON), solve both halves with each mrcal model ``job["repeats"]`` times, diff them;
    print the result as JSON: per model the repeat with the median difference, and the spread.

    mrcal's solves of one half do not always land on the same minimum (OPENCV8 on the 185° fisheye:
    k1 from -3.8 to +0.5 between runs on the same corners), hence the repeats."""
    import mrcal
    import numpy as np

    job = json.loads(Path(job_path).read_text())
    size, grid, cells = tuple(job["size"]), tuple(job["grid"]), np.asarray(job["covered_cells"], int)
    out = {}
    for model in job.get("models", MRCAL_MODELS):
        runs, errors = [], []
        for k in range(int(job.get("repeats", 1))):
            try:
                solved = [_mrcal_solve(job, half, model, Path(job["workdir"]) / f"r{k}") for half in (0, 1)]
                runs.append({"diff": _mrcal_diff([s[0] for s in solved], cells, size, grid),
                             "halves": [s[1] for s in solved]})
            except Exception as exc:  # noqa: BLE001 - a failed solve is a table entry, not the end of the run
                errors.append(f"{type(exc).__name__}: {exc}")
        if not runs:
            out[model] = {"error": errors[0]}
            continue
        runs.sort(key=lambda r: r["diff"]["median"])
        out[model] = {**runs[(len(runs) - 1) // 2], "spread": [runs[0]["diff"]["median"], runs[-1]["diff"]["median"]],
                      "repeats": len(runs), "failed": len(errors)}
    if job.get("cross"):  # OpenCV's rational halves, diffed by mrcal
        models = [mrcal.cameramodel(intrinsics=("LENSMODEL_OPENCV8", np.asarray(p, float)), imagersize=size)
                  for p in job["cross"]["params"]]
        out["cross"] = _mrcal_diff(models, np.asarray(job["cross"]["covered_cells"], int), size, grid)
    print(json.dumps(out))
    return 0


# ---------------------------------------------------------------- aicalib_tf side

def natural_key(path: Path):
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", path.name)]


def photos(folder: Path) -> tuple[list[Path], tuple[int, int], int]:
    """(the folder's photos of the most common size in natural order, that size, how many were left out)."""
    import cv2
    from collections import Counter

    files = sorted((p for p in folder.iterdir() if p.suffix.lower() in (".jpg", ".jpeg", ".png")), key=natural_key)
    sizes = {}
    for p in files:
        img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        sizes[p] = (img.shape[1], img.shape[0])
    size = Counter(sizes.values()).most_common(1)[0][0]
    keep = [p for p in files if sizes[p] == size]
    return keep, size, len(files) - len(keep)


def classic_corners(path: Path, pattern):
    """OpenCV's classic corners of one photo, (N, 2) float64 px, or None."""
    import cv2
    import numpy as np

    gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    ok, c = cv2.findChessboardCorners(gray, tuple(pattern), flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not ok:
        return None
    c = cv2.cornerSubPix(gray, c, (5, 5), (-1, -1), (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3))
    return c.reshape(-1, 2).astype(np.float64)


def opencv_lens(kind: str, corners: list, pattern, size):
    """An OpenCV calibration of one half as a Lens (plumb_bob, rational_polynomial or equidistant)."""
    import cv2
    import numpy as np

    from aicalib_tf.bench.opencv_calib import fisheye_calibrate
    from aicalib_tf.geometry import lens as L
    from aicalib_tf.geometry.pattern import board_points, pattern_ids

    obj = board_points(pattern_ids(pattern), 1.0).astype(np.float32)
    objs, imgs = [obj] * len(corners), [c.astype(np.float32).reshape(-1, 1, 2) for c in corners]
    if kind == "equidistant":  # OpenCV's own start first; when it raises, a start from f = min(w, h) / π
        o64 = [o.astype(np.float64).reshape(1, -1, 3) for o in objs]
        i64 = [c.astype(np.float64).reshape(1, -1, 2) for c in corners]
        rms, K, D, _ = fisheye_calibrate(o64, i64, size)
    else:
        flags = cv2.CALIB_RATIONAL_MODEL if kind == "rational_polynomial" else 0
        rms, K, D, _, _ = cv2.calibrateCamera(objs, imgs, size, None, None, flags=flags)
    return L.Lens(kind, K, np.ravel(D)[:L.N_COEFFS[kind]], size), float(rms)


def project_half(files, pattern_text, square_text, folder: Path, flex: str | None = None):
    """Calibrate one half with the command line (``--flex flex`` when given); the Calibration read back
    from its camera.json."""
    from aicalib_tf.calib.files import load_calibration

    cmd = [sys.executable, "-m", "aicalib_tf.calibrate", *map(str, files), "--pattern", pattern_text, "--square",
           square_text, "--model", "auto", "--out", str(folder), "--workers", "1", "--quiet",
           *(["--flex", flex] if flex else [])]
    run = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env={**os.environ, "TF_CPP_MIN_LOG_LEVEL": "3"})
    if run.returncode:
        raise RuntimeError((run.stderr.strip().splitlines() or ["calibrate failed"])[-1])
    return load_calibration(folder / "camera.json")


def horizontal_fov_deg(lens) -> float:
    """The angle between the rays of the middle row's first and last pixels (200° when either has none)."""
    import numpy as np

    w, h = lens.image_size
    v = lens.unproject(np.array([[0.0, (h - 1) / 2], [w - 1.0, (h - 1) / 2]]))
    if not np.all(np.isfinite(v)):
        return 200.0
    v = v / np.linalg.norm(v, axis=1, keepdims=True)
    return float(np.clip(np.degrees(np.arccos(np.clip(v[0] @ v[1], -1, 1))), 30.0, 250.0))


def write_vnl(path: Path, names: list[str], corners: list) -> None:
    """mrcal's corners file: one line per corner (filename x y level), '- -' for a photo without a board."""
    lines = ["# filename x y level"]
    for name, c in zip(names, corners):
        if c is None:
            lines.append(f"{name} - - -")
        else:
            lines.extend(f"{name} {x:.4f} {y:.4f} 0" for x, y in c)
    path.write_text("\n".join(lines) + "\n")


def _covered_cells(corner_sets, size) -> "list[int]":
    """The covered cells of the views' corners (:func:`aicalib_tf.calib.diff.view_coverage`: corner cells and hulls)."""
    import numpy as np

    from aicalib_tf.calib.diff import view_coverage

    return np.flatnonzero(view_coverage(corner_sets, size, GRID)).tolist()


def _diff_entry(lens_a, lens_b, covered_cells, size) -> dict:
    """projection_diff of two lenses, rotation fitted over the covered cells; its median and p95 there."""
    import numpy as np

    from aicalib_tf.calib.diff import projection_diff

    covered = np.zeros(GRID[0] * GRID[1], bool)
    covered[covered_cells] = True
    d = projection_diff(lens_a, lens_b, grid=GRID, covered=covered)
    return {"median": d["covered_stats"]["median"], "p95": d["covered_stats"]["p95"], "rotation_deg": d["rotation_deg"],
            "cells": d["covered_stats"]["cells"]}


def _attempt(fn, *args) -> dict:
    try:
        return fn(*args)
    except Exception as exc:  # noqa: BLE001 - one failed tool is a table entry
        return {"error": f"{type(exc).__name__}: {' '.join(str(exc).split())[:160]}"}


def _project_split(halves, set_cfg, work: Path, size, flex: str | None = None) -> tuple[dict, list]:
    """aicalib_tf on both halves (``--flex flex`` when given); (table entry, the two Calibrations or Nones)."""
    import numpy as np

    from aicalib_tf.calib.diff import board_coverage

    pattern, _, square_text = set_cfg
    cals = []
    for k, files in enumerate(halves):
        try:
            cals.append(project_half(files, f"{pattern[0]}x{pattern[1]}", square_text,
                                     work / f"project_{k}{'_' + flex if flex else ''}", flex))
        except Exception as exc:  # noqa: BLE001
            return {"error": f"half {k}: {exc}"}, [None, None]
    covered = np.zeros(GRID[0] * GRID[1], bool)
    for c in cals:
        covered |= board_coverage(c.lens, c.pattern_size, c.square_size, c.rvecs, c.tvecs, GRID)
    entry = _diff_entry(cals[0].lens, cals[1].lens, np.flatnonzero(covered), size)
    entry["models"] = [c.lens.model for c in cals]
    entry["fov_deg"] = [horizontal_fov_deg(c.lens) for c in cals]
    entry["flex_kept"] = [c.flex is not None for c in cals]
    return entry, cals


def _opencv_split(corners_halves, pattern, size) -> dict:
    import numpy as np

    found = [[c for c in half if c is not None] for half in corners_halves]
    if min(len(f) for f in found) < 3:
        return {k: {"error": "fewer than 3 classic boards in a half"} for k in ("plumb_bob", "rational_polynomial",
                                                                                 "equidistant")}
    cells = _covered_cells([c for f in found for c in f], size)
    out = {}
    for kind in ("plumb_bob", "rational_polynomial", "equidistant"):
        def one(kind=kind):
            fits = [opencv_lens(kind, f, pattern, size) for f in found]
            e = _diff_entry(fits[0][0], fits[1][0], cells, size)
            e["rms"] = [r for _, r in fits]
            if kind == "rational_polynomial":
                e["params"] = [np.concatenate([[L.K[0, 0], L.K[1, 1], L.K[0, 2], L.K[1, 2]], L.dist]).tolist()
                               for L, _ in fits]
            return e
        out[kind] = _attempt(one)
    out["covered_cells"] = cells
    return out


def _mrcal_split(venv: Path, names_halves, corners_halves, set_cfg, size, seeds, cross, work: Path,
                 repeats: int = 3, spline_nx: int = 10) -> dict:
    """mrcal on both halves (a subprocess in its own Python); its results plus the cross-check."""
    import numpy as np

    from aicalib_tf.geometry import lens as L

    pattern, spacing, _ = set_cfg
    vnl = []
    for k, (names, corners) in enumerate(zip(names_halves, corners_halves)):
        vnl.append(str(work / f"corners_{k}.vnl"))
        write_vnl(Path(vnl[-1]), names, corners)
    found = [c for half in corners_halves for c in half if c is not None]
    job = {"size": list(size), "grid": list(GRID), "pattern": list(pattern), "spacing": spacing, "vnl": vnl,
           "focal": [s[0] for s in seeds], "fov_deg": [s[1] for s in seeds], "workdir": str(work),
           "covered_cells": _covered_cells(found, size), "cross": cross, "repeats": repeats,
           "spline_nx": spline_nx, "models": list(MRCAL_MODELS)}
    (work / "job.json").write_text(json.dumps(job))
    run = subprocess.run([str(venv / "bin" / "python"), __file__, "--mrcal-worker", str(work / "job.json")],
                         capture_output=True, text=True, timeout=3600)
    if run.returncode:
        return {"error": (run.stderr.strip().splitlines() or ["mrcal worker failed"])[-1]}
    res = json.loads(run.stdout.strip().splitlines()[-1])
    o8 = res.get("opencv8", {})
    if "halves" in o8:  # cross-check: mrcal's OPENCV8 halves through aicalib_tf's projection_diff
        lenses = []
        for h in o8["halves"]:
            p = np.asarray(h["intrinsics"])
            lenses.append(L.Lens("rational_polynomial", [[p[0], 0, p[2]], [0, p[1], p[3]], [0, 0, 1]], p[4:12], size))
        o8["ours"] = _diff_entry(lenses[0], lenses[1], job["covered_cells"], size)
    return res


def run_set(name: str, folder: Path, venv: Path | None, tmp: Path, repeats: int = 3, spline_nx: int = 10,
            flex_column: str | None = "off") -> dict:
    """Every split of one set through every tool; {"set", "photos", "size", "left_out", "splits": {...}}."""
    from aicalib_tf.calib.diff import split_views

    cfg = SETS[name]
    files, size, left_out = photos(folder)
    corners = {p: classic_corners(p, cfg[0]) for p in files}
    out = {"set": name, "photos": len(files), "size": list(size), "left_out": left_out,
           "classic_boards": sum(c is not None for c in corners.values()), "flex_column": flex_column, "splits": {}}
    for split in SPLITS:
        work = tmp / f"{name}_{split}"
        work.mkdir(parents=True, exist_ok=True)
        halves = split_views(files, split)
        row = {}
        row["aicalib_tf"], cals = _project_split(halves, cfg, work, size)
        if flex_column:
            row["aicalib_tf_flex"] = _project_split(halves, cfg, work, size, flex_column)[0]
        cv = _opencv_split([[corners[p] for p in h] for h in halves], cfg[0], size)
        row.update({"cv_plumb_bob": cv["plumb_bob"], "cv_rational": cv["rational_polynomial"],
                    "cv_fisheye": cv["equidistant"]})
        if venv is not None:
            names = [[f"frame{files.index(p):03d}.jpg" for p in h] for h in halves]
            seeds = [(c.fx, horizontal_fov_deg(c.lens)) if c is not None else (0.5 * size[0], 90.0) for c in cals]
            cross = ({"params": cv["rational_polynomial"]["params"], "covered_cells": cv["covered_cells"]}
                     if "params" in cv.get("rational_polynomial", {}) else None)
            m = _mrcal_split(venv, names, [[corners[p] for p in h] for h in halves], cfg, size, seeds, cross, work,
                             repeats, spline_nx)
            row["mrcal_opencv8"] = m.get("opencv8", m) if "error" not in m else m
            row["mrcal_splined"] = m.get("splined", m) if "error" not in m else m
            row["cross"] = {"mrcal_opencv8_by_aicalib": row["mrcal_opencv8"].get("ours"),
                            "mrcal_opencv8_by_mrcal": row["mrcal_opencv8"].get("diff"),
                            "cv_rational_by_mrcal": m.get("cross"), "cv_rational_by_aicalib": cv["rational_polynomial"]}
        out["splits"][split] = row
        print(f"{name} {split}: " + ", ".join(f"{k} {_cell(row.get(k))}" for k, _ in COLUMNS), flush=True)
    return out


def _median(entry) -> float | None:
    if not entry or "error" in entry:
        return None
    return (entry.get("diff") or entry).get("median")


def _cell(entry) -> str:
    """The median (px); for mrcal, the range over its repeats when they differ by more than 20%."""
    m = _median(entry)
    if m is None:
        return "failed"
    lo, hi = entry.get("spread") or (m, m)
    return f"{m:.3g} ({lo:.3g}-{hi:.3g})" if hi > 1.2 * lo else f"{m:.3g}"


def _columns(results) -> tuple:
    """COLUMNS with the second aicalib_tf column titled by the --flex it ran."""
    flex = next((r.get("flex_column") for r in results if r.get("flex_column")), "off")
    return tuple((k, f"aicalib_tf --flex {flex}" if k == "aicalib_tf_flex" else t) for k, t in COLUMNS)


def table(results: list[dict]) -> str:
    """The markdown table: each set and split, every tool's halves difference (px), the best anchor."""
    columns = _columns(results)
    head = "| set | split | " + " | ".join(t for _, t in columns) + " | best anchor | aicalib_tf ≤ best |"
    lines = [head, "|" + "---|" * (len(columns) + 4)]
    for r in results:
        for split, row in r["splits"].items():
            cells = [_cell(row.get(k)) for k, _ in columns]
            if row.get("aicalib_tf", {}).get("models"):
                cells[0] += f" ({'/'.join(sorted(set(row['aicalib_tf']['models'])))})"
            for i, key in enumerate(("aicalib_tf", "aicalib_tf_flex")):
                if any(row.get(key, {}).get("flex_kept", [])):
                    cells[i] += f" (shape {'/'.join('kept' if k else 'flat' for k in row[key]['flex_kept'])})"
            anchors = [(_median(row.get(k)), t) for k, t in columns[2:] if _median(row.get(k)) is not None]
            best = min(anchors) if anchors else None
            ours = _median(row.get("aicalib_tf"))
            lead = "-" if best is None or ours is None else ("yes" if ours <= best[0] else "no")
            lines.append(f"| {r['set']} ({r['photos']} photos) | {split} | " + " | ".join(cells)
                         + f" | {'-' if best is None else f'{best[0]:.3g} ({best[1]})'} | {lead} |")
    return "\n".join(lines)


def cross_table(results: list[dict]) -> str:
    """The same pairs of models diffed both ways (median over the covered cells, px): mrcal.projection_diff
    with the rotation fitted by pixel least squares / aicalib_tf's projection_diff / mrcal.projection_diff
    with mrcal's own implied_Rt10__from_unprojections rotation; in brackets the covered cells each could
    unproject."""
    f = lambda e: "-" if not e or e.get("median") is None else f"{e['median']:.3g} ({e.get('cells', '?')})"  # noqa: E731
    lines = ["| set | split | mrcal OPENCV8 halves: mrcal / aicalib_tf / mrcal's own rotation fit "
             "| OpenCV rational halves: mrcal / aicalib_tf / mrcal's own rotation fit |", "|---|---|---|---|"]
    for r in results:
        for split, row in r["splits"].items():
            c = row.get("cross")
            if not c:
                continue
            m8, cr = c["mrcal_opencv8_by_mrcal"] or {}, c["cv_rational_by_mrcal"] or {}
            lines.append(f"| {r['set']} | {split} | {f(m8)} / {f(c['mrcal_opencv8_by_aicalib'])} / {f(m8.get('mrcal_fit'))}"
                         f" | {f(cr)} / {f(c['cv_rational_by_aicalib'])} / {f(cr.get('mrcal_fit'))} |")
    return "\n".join(lines)


def find_sets(names, data: Path = SHARED) -> list[tuple[str, Path]]:
    """(name, folder) of each known set present; tests/data/opencv_left joins only if its photos differ
    from the shared copy's."""
    import hashlib

    out = []
    for name in names:
        folder = data / name
        if folder.is_dir():
            out.append((name, folder))
        else:
            print(f"{name}: not in {data}; skipped")
    local = ROOT / "tests" / "data" / "opencv_left"
    if "opencv_left" in names and local.is_dir():
        digest = lambda d: sorted(hashlib.sha256(p.read_bytes()).hexdigest() for p in d.glob("*.jpg"))  # noqa: E731
        shared = data / "opencv_left"
        if not shared.is_dir() or digest(shared) != digest(local):
            out.append(("opencv_left", local))
        else:
            print("tests/data/opencv_left: the same photos as the shared opencv_left; counted once")
    return out


def main(argv=None) -> int:
    if argv is None and len(sys.argv) > 2 and sys.argv[1] == "--mrcal-worker":
        return mrcal_worker(sys.argv[2])
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sets", nargs="+", default=list(SETS), choices=list(SETS))
    ap.add_argument("--mrcal-venv", default="/work/scratch/mrcal-venv", help="mrcal's own Python environment")
    ap.add_argument("--skip-mrcal", action="store_true")
    ap.add_argument("--mrcal-repeats", type=int, default=3, help="mrcal solves per half and model (default: 3)")
    ap.add_argument("--spline-nx", type=int, default=10, help="mrcal splined model's knots across (default: 10)")
    ap.add_argument("--flex-column", default="off", choices=("off", "sag", "shape"),
                    help="the second aicalib_tf column's --flex (default: off, a flat board)")
    ap.add_argument("--no-flex-column", action="store_true", help="skip the second aicalib_tf column")
    ap.add_argument("--json", default=None, help="write every figure as JSON here")
    ap.add_argument("--data", default=str(SHARED), help="the real sets' folder (default: ../shared/data)")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    venv = None if args.skip_mrcal else Path(args.mrcal_venv)
    if venv is not None and not (venv / "bin" / "mrcal-calibrate-cameras").exists():
        print(f"mrcal not found in {venv} (python -m venv {venv}; {venv}/bin/pip install --no-deps mrcal after numpy, "
              "scipy, numpysane, gnuplotlib, pyyaml): its columns are skipped")
        venv = None
    results = []
    with tempfile.TemporaryDirectory(prefix="real_repeatability_") as tmp:
        for name, folder in find_sets(args.sets, Path(args.data)):
            results.append(run_set(name, folder, venv, Path(tmp), args.mrcal_repeats, args.spline_nx,
                                   None if args.no_flex_column else args.flex_column))
    print()
    print(table(results))
    if venv is not None:
        print()
        print(cross_table(results))
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1, default=float) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
