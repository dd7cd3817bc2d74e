"""The benchmark runner: the same images through every detector, scored, timed and calibrated.

The command line is :mod:`aicalib_tf.evaluate`; its docstring says what a run measures and writes.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aicalib_tf.cnn.spec import DETECTOR_NETWORK
from aicalib_tf.bench.conditions import (
    CALIB_CAMERAS,
    FISHEYE_SEQUENCES,
    PATTERN,
    Condition,
    board_tilt_deg,
    calibration_sequences,
    condition_samples,
    is_fisheye,
    select_conditions,
    square_px,
)
from aicalib_tf.bench.detectors import DETECTORS, Found, make_detectors, score_detection
from aicalib_tf.bench.metrics import calibration_errors
from aicalib_tf.bench.timing import keep_slowest, retime_slowest, time_detector
from aicalib_tf.detect.batch import worker_pool
from aicalib_tf.geometry.lens import get_model

__all__ = ["DETECTORS", "EvalConfig", "Found", "make_detectors", "time_detector", "score_detection", "run_synthetic", "calibrate_sequences", "run"]

FULL_COUNTS = {"named": 100, "sweep": 32, "hd": 30, "fisheye": 100, "calib_views": 20, "fisheye_sequences": 1,
               "rigs": 1}
QUICK_COUNTS = {"named": 6, "sweep": 3, "hd": 2, "fisheye": 2, "calib_views": 6, "fisheye_sequences": 0, "rigs": 0}


@dataclass(frozen=True)
class EvalConfig:
    """One evaluation run (the CLI's options)."""

    out: str
    quick: bool = False
    model: str = DETECTOR_NETWORK
    detectors: tuple[str, ...] = DETECTORS
    conditions: str | None = None
    limit: int | None = None
    images: str | None = None
    pattern: tuple[int, int] | None = None
    degrade: bool = False
    seed: int = 0
    quiet: bool = False
    command: str = ""
    workers: int = 1  # processes rendering the synthetic images (detection and timing stay in one process)

    def counts(self) -> dict:
        """Images per named condition, per sweep level, at 1920×1080, per fisheye condition, views per
        calibration sequence, and whether (1) or not (0) the fisheye calibration sequences run."""
        c = dict(QUICK_COUNTS if self.quick else FULL_COUNTS)
        if self.limit is not None:
            c = {k: (max(3, min(v, self.limit)) if k == "calib_views" else min(v, self.limit)) for k, v in c.items()}
        return c


def _difficulty(rows: list[dict]) -> float:
    """How hard an image was: detectors that failed (wrong counts double), then the worst error."""
    bad = sum(2 if r["outcome"] in ("wrong", "false_board") else 1 for r in rows
              if r["outcome"] not in ("hit", "none"))
    return bad + 0.01 * min(99.0, max([r["err_max"] for r in rows if np.isfinite(r["err_max"])] or [0.0]))


def _warm_up(detectors: dict, size: tuple[int, int]) -> None:
    """Run every detector, untimed, on a clean and an occluded board of ``size`` (W, H) px: the first
    call at a new image size traces the network's graph for it (tens of ms), and the first call of
    each compiled refinement loop loads it (:mod:`aicalib_tf.kernels`); no later call pays either."""
    from data_gen import make_sample

    for preset in ("clean", "occluded"):
        img = make_sample(preset, 0, 0, size=tuple(size), pattern=PATTERN).image
        for fn in detectors.values():
            fn(img)


def run_synthetic(conditions: list[Condition], detectors: dict, counts: dict, *, with_calibration: bool = True,
                  progress: bool = True, workers: int = 1) -> dict:
    """Run every detector on every image of ``conditions`` (and the calibration sequences).

    counts : see :meth:`EvalConfig.counts`. Returns {"rows": [dict per image × detector],
    "errors": {(condition, detector): [(K,) px arrays]}, "examples": [hardest images],
    "calibration": [dict per sequence × detector], "render_s": seconds spent rendering}.
    Each detector's slowest images are timed again at the end (:func:`retime_slowest`). workers :
    processes rendering the images (``workers`` conditions at a time, before any of them is timed;
    detection and timing stay in this process, one image at a time).
    """
    from tqdm import tqdm

    def n_for(c: Condition) -> int:
        if is_fisheye(c.preset):
            return counts.get("fisheye", counts["named"])
        return counts["sweep"] if c.sweep else counts["hd"] if c.size[0] > 1000 else counts["named"]

    fisheye_seqs = tuple(FISHEYE_SEQUENCES) if counts.get("fisheye_sequences", 0) else ()
    n_seqs = len(CALIB_CAMERAS) + len(fisheye_seqs)
    total = sum(n_for(c) for c in conditions) + (n_seqs * counts["calib_views"] if with_calibration else 0)
    bar = tqdm(total=total, desc="evaluate", unit="img", disable=not progress)
    rows, errors, hardest = [], {}, {}
    render_s = 0.0
    slowest = {}  # (detector, W, H) -> the slowest images so far, timed again at the end
    warm = set()  # image sizes (W, H) the detectors have been warmed up at
    with worker_pool(_renderer, workers=workers) as render:
        for start in range(0, len(conditions), workers):
            group = conditions[start:start + workers]
            # a condition's images are all rendered before any is timed: rendering between detections
            # (large numpy and OpenCV passes) would leave caches and thread pools cold for the next one;
            # with workers, ``workers`` conditions are rendered at once, one per process, and nothing
            # runs beside the timed detections
            t0 = time.perf_counter()
            rendered = list(render([(c, n_for(c)) for c in group]))
            render_s += time.perf_counter() - t0
            for cond, samples in zip(group, rendered):
                _detect_condition(cond, samples, detectors, warm, rows, errors, slowest, hardest, bar)
    calib = []
    if with_calibration:
        t0 = time.perf_counter()
        seqs = calibration_sequences(counts["calib_views"], fisheye=fisheye_seqs)
        render_s += time.perf_counter() - t0
        for size in {s.image.shape[::-1] for _, views in seqs for s in views} - warm:
            _warm_up(detectors, size)
        calib = calibrate_sequences(seqs, detectors, rows, errors, bar, slowest=slowest)
    bar.close()
    retime_slowest(slowest, detectors)
    examples = sorted(hardest.values(), key=lambda h: -h[0])[:6]
    return {"rows": rows, "errors": errors, "examples": examples, "calibration": calib, "render_s": render_s}


def _renderer():
    """Render one condition's images: ``(condition, count) -> [(index, Sample)]`` (a worker's setup)."""
    return lambda job: list(condition_samples(*job))


def _detect_condition(cond: Condition, samples, detectors: dict, warm: set, rows, errors, slowest, hardest, bar) -> None:
    """Every detector on a condition's rendered images (warmed up first at a new size), kept in the run's records."""
    if tuple(cond.size) not in warm:
        _warm_up(detectors, cond.size)
        warm.add(tuple(cond.size))
    for index, s in samples:
        img_rows, found_by = _detect_sample(cond.name, cond, index, s, detectors, rows, errors)
        keep_slowest(slowest, img_rows, s.image)
        score = _difficulty(img_rows)
        group = cond.sweep or cond.name  # one example per named condition or sweep
        if score > 0 and score > hardest.get(group, (0,))[0]:
            hardest[group] = (score, cond.name, index, s.image, s.corners if cond.has_board else None, found_by)
        bar.update(1)


def _detect_sample(name: str, cond: Condition | None, index: int, s, detectors: dict, rows: list, errors: dict):
    lab = s.label
    has_board = bool(lab.get("has_board", True)) and bool(lab["corners"])
    truth = s.corners if has_board else None
    visible = s.visible if has_board else None
    h, w = s.image.shape
    base = {"condition": name, "sweep": cond.sweep if cond else None, "level": cond.level if cond else np.nan,
            "index": index, "seed": lab["seed"], "camera_id": lab["camera_id"], "width": w, "height": h,
            "has_board": has_board, "tilt_deg": board_tilt_deg(lab), "square_px": square_px(lab),
            "k1": float(lab["dist"][0]), "distortion_model": lab.get("distortion_model", "plumb_bob")}
    img_rows, found_by = [], {}
    for det, fn in detectors.items():
        found, ms = time_detector(fn, s.image)
        row, e = score_detection(found, truth, visible, has_board, PATTERN)
        row = {**base, "detector": det, **row, "time_ms": ms, "time_first_ms": ms, "time_runs": 1}
        rows.append(row)
        img_rows.append(row)
        errors.setdefault((name, det), []).append(e)
        found_by[det] = (found, row["outcome"])
    return img_rows, found_by


def calibrate_sequences(seqs, detectors: dict, rows: list, errors: dict, bar=None, *, slowest: dict | None = None) -> list[dict]:
    """Detect every view of each calibration sequence, calibrate per detector, compare with the truth.

    seqs : [(camera_id, [Sample])] (see :func:`aicalib_tf.bench.conditions.calibration_sequences`).
    Detection rows go into ``rows``/``errors`` under condition ``calib`` (pinhole sequences) or
    the fisheye sequence's name (``calib_fisheye185``). Returns one dict per sequence × detector:
    camera_id, sequence, lens, true_model, model (the calibration's chosen lens model), views,
    views_found (full boards), views_partial, views_used, rejected, rms_px, fx_pct, fy_pct, pp_px,
    the projection error field (unproject with the true lens, project with the estimate; px):
    proj_err_seen_mean_px over the area the boards covered (hull of the sequence's visible true
    corners), proj_err_mean_px / proj_err_max_px over the whole image (a fisheye's image circle),
    proj_err_fail_frac (share of it the estimate cannot project), the undistortion-field
    differences dist_field_* (whole image and _seen_), and status. slowest : see :func:`keep_slowest`.
    """
    from aicalib_tf.calib.workflow import CalibrationError, View, calibrate_camera

    out = []
    for cam, samples in seqs:
        views = {d: [] for d in detectors}
        for s in samples:
            name = s.label["condition"] if _is_fisheye(s.label) else "calib"
            img_rows, found_by = _detect_sample(name, None, s.label["index"], s, detectors, rows, errors)
            if slowest is not None:
                keep_slowest(slowest, img_rows, s.image)
            for d, (found, _) in found_by.items():
                if len(found.corners):
                    views[d].append(View(f"view{s.label['index']:03d}", found.corners, found.ids, sigmas=found.sigmas))
            if bar is not None:
                bar.update(1)
        for d, vs in views.items():
            out.append(_calibrate_one(cam, samples, d, vs, calibrate_camera, CalibrationError))
    return out


def _is_fisheye(lab: dict) -> bool:
    """Whether a label's lens model images past 90° (``IS_FISHEYE``)."""
    return get_model(lab.get("distortion_model", "plumb_bob")).IS_FISHEYE


def _lens_name(lab: dict) -> str:
    """A sequence's lens in words: "fisheye 185°", "strong barrel" or "mild"."""
    if _is_fisheye(lab):
        return f"fisheye {2 * lab['max_theta_deg']:.0f}°" if lab.get("max_theta_deg") else "fisheye"
    return "strong barrel" if lab["dist"][0] < -0.2 else "mild"


def _calibrate_one(cam: int, samples: list, detector: str, vs: list, calibrate_camera, error_type) -> dict:
    """Calibrate one detector's views of one sequence and score it against the truth (one calibration.csv row)."""
    from aicalib_tf.geometry.camera import model_for_dist

    lab = samples[0].label
    K_true, dist_true = np.asarray(lab["K"]), np.asarray(lab["dist"])
    true_model = lab.get("distortion_model", "plumb_bob")
    max_theta = np.radians(lab["max_theta_deg"]) if lab.get("max_theta_deg") else None
    n = PATTERN[0] * PATTERN[1]
    rec = {"camera_id": cam, "sequence": lab["condition"], "lens": _lens_name(lab), "true_model": true_model,
           "k1_true": float(dist_true[0]), "fx_true": float(K_true[0, 0]), "detector": detector,
           "views": len(samples), "views_found": sum(len(v.ids) == n for v in vs),
           "views_partial": sum(len(v.ids) < n for v in vs)}
    try:
        cal = calibrate_camera(vs, PATTERN, float(lab["square_size"]), tuple(lab["image_size"]))
    except error_type as exc:
        rec.update(views_used=0, rejected=len(vs), status=f"failed: {exc}")
        return rec
    model = getattr(cal, "model", None) or model_for_dist(cal.dist)  # calib's model="auto" names its choice
    seen = np.concatenate([s.corners[s.visible] for s in samples])
    err = calibration_errors(cal.K, cal.dist, K_true, dist_true, tuple(lab["image_size"]), model=model,
                             model_true=true_model, max_theta_true=max_theta, seen=seen)
    rec.update(model=model, views_used=len(cal.views), rejected=len(cal.rejected), rms_px=float(cal.rms),
               **{k: err[k] for k in CALIB_ERROR_COLUMNS}, status="ok")
    return rec


CALIB_ERROR_COLUMNS = ("fx_pct", "fy_pct", "pp_px", "proj_err_seen_mean_px", "proj_err_mean_px", "proj_err_max_px",
                       "proj_err_fail_frac", "dist_field_mean_px", "dist_field_max_px", "dist_field_seen_mean_px",
                       "dist_field_seen_max_px")


def _versions() -> dict:
    import platform

    import cv2

    v = {"python": platform.python_version(), "numpy": np.__version__, "opencv": cv2.__version__,
         "platform": platform.platform(), "cpu": _cpu_model(), "cpus": os.cpu_count()}
    from importlib.metadata import PackageNotFoundError, version

    # read from the installed metadata: importing tensorflow for its version costs seconds and memory
    for mod, dists in (("tensorflow", ("tensorflow", "tensorflow-cpu")), ("keras", ("keras",)),
                       ("ai-edge-litert", ("ai-edge-litert",)), ("pandas", ("pandas",)), ("matplotlib", ("matplotlib",))):
        v[mod] = None
        for dist in dists:
            try:
                v[mod] = version(dist)
                break
            except PackageNotFoundError:
                continue
    v.update(_git_state())
    return v


def _cpu_model() -> str | None:
    """The CPU's model name (Linux /proc/cpuinfo), or None: timings differ between machines of one kind."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip() or None
    except OSError:
        pass
    return None


def _git_state() -> dict:
    """The code's commit and its uncommitted source files (empty when not in a git checkout)."""
    import subprocess

    root = Path(__file__).resolve().parents[2]
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True,
                              timeout=10).stdout.strip()
        status = subprocess.run(["git", "status", "--porcelain", "--", "aicalib_tf", "data_gen", "models"], cwd=root,
                                capture_output=True, text=True, timeout=10).stdout.splitlines()
    except (OSError, subprocess.SubprocessError):
        return {}
    return {"git_commit": head or None, "git_uncommitted": [ln[3:] for ln in status]} if head else {}


def _split_calib(spec: str | None) -> tuple[str | None, bool]:
    """(condition spec without ``calib``, whether to run the calibration sequences)."""
    if spec is None or spec.strip() in ("", "all"):
        return None, True
    items = [s.strip() for s in spec.split(",") if s.strip()]
    rest = [s for s in items if s != "calib"]
    return (",".join(rest) if rest else ""), len(rest) < len(items)


def run_rigs(seeds: int, model: str = DETECTOR_NETWORK, *, progress: bool = True) -> list[dict]:
    """Every rig of :data:`aicalib_tf.bench.rigs.RIGS` for ``seeds`` seeds, scored against the truth (rigs.csv rows)."""
    from tqdm import tqdm

    from aicalib_tf.bench.rigs import RIG_PAIRS, RIGS, evaluate_rig

    detectors, _ = make_detectors(["cnn", "opencv"], PATTERN, model, relative=True)
    rows = []
    for name, seed in tqdm([(n, s) for n in RIGS for s in range(seeds)], desc="rigs", unit="rig", disable=not progress):
        rows += evaluate_rig(name, seed, RIG_PAIRS, detectors)
    return rows


def run(cfg: EvalConfig, detectors: dict | None = None, info: dict | None = None, *,
        started: float | None = None) -> Path:
    """Run the evaluation described by ``cfg``; returns the output folder.

    detectors, info : from :func:`make_detectors` (built from ``cfg`` when None).
    started : time.perf_counter() at the start of the command, for the reported wall time.
    """
    from aicalib_tf.bench import report

    out = Path(cfg.out)
    t0 = time.perf_counter() if started is None else started
    if detectors is None:
        detectors, info = make_detectors(cfg.detectors, cfg.pattern or PATTERN, cfg.model)
    if cfg.images is not None:
        from aicalib_tf.bench.photos import run_photos

        result = run_photos(Path(cfg.images), cfg.pattern, detectors, degrade=cfg.degrade, seed=cfg.seed,
                            progress=not cfg.quiet)
        result["wall_s"] = time.perf_counter() - t0
        report.write_photo_report(out, cfg, result, info, _versions())
        return out
    spec, with_calib = _split_calib(cfg.conditions)
    conds = select_conditions(spec) if spec != "" else []
    result = run_synthetic(conds, detectors, cfg.counts(), with_calibration=with_calib, progress=not cfg.quiet,
                           workers=cfg.workers)
    if with_calib and cfg.counts().get("rigs") and {"cnn", "opencv"} <= set(detectors):
        result["rigs"] = run_rigs(cfg.counts()["rigs"], cfg.model, progress=not cfg.quiet)
    result["wall_s"] = time.perf_counter() - t0
    report.write_report(out, cfg, conds, result, info, _versions())
    return out
