"""From photos and a robot's poses to saved hand-eye files: read poses, detect, calibrate, report, write.

The command line is :mod:`aicalib_tf.handeye`; its docstring describes the inputs, outputs and exit codes.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aicalib_tf.calib.bundle import CalibrationError
from aicalib_tf.calib.fit import View
from aicalib_tf.calib.handeye.calibrate import DEFAULT_SIGMA_ROT_DEG, DEFAULT_SIGMA_T_MM, SETUPS, HandEyeResult, calibrate_handeye
from aicalib_tf.cnn.spec import DETECTOR_NETWORK

__all__ = ["HandEyeConfig", "run_handeye", "square_in_metres"]

_TO_M = {"mm": 1e-3, "cm": 1e-2, "m": 1.0, "in": 0.0254}


def square_in_metres(square: float, unit: str) -> float:
    """A board square in metres; a unitless square is refused (hand-eye works in metres)."""
    if unit not in _TO_M:
        raise ValueError(f"--square needs a unit for hand-eye calibration (mm, cm, m or in), got {square:g}{unit}")
    return float(square) * _TO_M[unit]


@dataclass(frozen=True)
class HandEyeConfig:
    """Everything one hand-eye run needs (the CLI's options). square in ``square_unit``; sigmas per axis."""

    images: tuple[str, ...]
    poses: str
    setup: str
    pattern: tuple[int, int]
    square: float
    square_unit: str = "mm"
    board: str | None = None
    out: str = "handeye"
    intrinsics: str | None = None
    model: str = "plumb_bob"
    detector: str = "cnn"
    network: str = DETECTOR_NETWORK
    sigma_rot_deg: float = DEFAULT_SIGMA_ROT_DEG
    sigma_t_mm: float = DEFAULT_SIGMA_T_MM
    save_partial: bool = False
    quiet: bool = False
    workers: int | None = None
    seed: int = 0

    def __post_init__(self):
        if self.setup not in SETUPS:
            raise ValueError(f"--setup must be one of {', '.join(SETUPS)}, got {self.setup!r}")
        if not (self.sigma_rot_deg > 0 and self.sigma_t_mm > 0):
            raise ValueError(f"--robot-sigma must be positive, got {self.sigma_rot_deg}°, {self.sigma_t_mm} mm")


def _labels(files: list[str]) -> dict[str, str]:
    from aicalib_tf.io import display_name

    names = [Path(f).name for f in files]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise ValueError(f"two images share the name {sorted(dup)[0]}: robot poses are matched by file name")
    return {f: display_name(Path(f).name) for f in files}


def _views(files, labels, cfg, skipped: dict) -> tuple[list[View], tuple[int, int]]:
    """Detect the boards (calib.workflow's batch detection); drop views a hand-eye fit cannot use."""
    from aicalib_tf.calib.workflow import _apply_size_policy, _detect_all, unreadable_error

    found, more = _detect_all(files, labels, cfg)
    skipped.update(more)
    if not found:
        raise unreadable_error(files, skipped)
    found, size = _apply_size_policy(found, "error", skipped)
    views = []
    for f in found:
        if f.view is None:
            skipped[f.label] = "no board found" + (f": {f.why}" if f.why else "")
        elif f.view.relative:
            skipped[f.label] = "board cut by the frame: its corners' place on the board is unknown"
        else:
            views.append(f.view)
    return views, size


def _camera(cfg, views, size, square_m, rejected):
    """(lens, fitted jointly?) from --intrinsics, else a camera calibration of the views."""
    from aicalib_tf.calib.fit import calibrate_camera

    if cfg.intrinsics:
        from aicalib_tf.calib.files import load_calibration

        cal = load_calibration(cfg.intrinsics)
        if tuple(cal.image_size) != tuple(size):
            raise ValueError(f"{cfg.intrinsics}: the camera is {cal.image_size[0]}x{cal.image_size[1]} but the images "
                             f"are {size[0]}x{size[1]}")
        return cal.lens, False
    if len(views) < 3:
        raise CalibrationError(f"fewer than 3 usable views ({len(views)}); hand-eye needs at least 3 with robot poses")
    cal = calibrate_camera(views, cfg.pattern, square_m, size, model=cfg.model, square_unit="m")
    rejected.update(cal.rejected)
    return cal.lens, True


def _board_info(cfg, square_m) -> dict:
    info = {"pattern_size": list(cfg.pattern), "square_m": square_m}
    return {**info, "charuco": cfg.board} if cfg.board else info


def run_handeye(cfg: HandEyeConfig) -> tuple[HandEyeResult, str]:
    """Read, detect, calibrate, write (module docstring); returns (result, printed report).

    Raises ValueError / CalibrationError / OSError for bad input, before writing anything (with
    ``save_partial``, a failed fit first writes handeye.json marked failed)."""
    from aicalib_tf.calib.handeye.files import write_handeye_files
    from aicalib_tf.calib.handeye.poses import match_poses, read_poses
    from aicalib_tf.calib.workflow import make_detector, _target
    from aicalib_tf.io import expand_images
    from aicalib_tf.outfolder import OutputFolder

    files = expand_images(cfg.images)
    if not files:
        raise ValueError(f"no images match {' '.join(cfg.images)}")
    poses = read_poses(cfg.poses)
    for w in poses.warnings:
        print(f"warning: {w}", file=sys.stderr)
    labels = _labels(files)
    matched, lonely_images, lonely_rows = match_poses(poses, [labels[f] for f in files])
    if len(matched) < 3:
        raise CalibrationError(f"{poses.source}: only {len(matched)} of {len(files)} images have a robot pose (rows are "
                               f"matched by file name; e.g. image {next(iter(labels.values()))!r}, row "
                               f"{poses.names[0]!r})")
    square_m = square_in_metres(cfg.square, cfg.square_unit)
    make_detector(cfg.detector, _target(cfg), cfg.network)  # a bad network or board fails here, before any work
    state = {"skipped": {}, "rejected": {}, "lens": None}
    extra = dict(unmatched_images=lonely_images, unmatched_poses=lonely_rows)
    try:
        with OutputFolder(cfg.out, "hand-eye calibration") as out:
            result, report, figure = _calibrate(cfg, [f for f in files if labels[f] in matched], labels, matched,
                                                square_m, len(files), state, extra)
            write_handeye_files(out.path, result, report, figure, board=_board_info(cfg, square_m),
                                meta={"detector": cfg.detector, "poses": poses.source, "images": len(files)}, **extra)
    except CalibrationError as exc:
        if cfg.save_partial:
            _write_partial(cfg, str(exc), state, extra)
        raise
    return result, report


def _calibrate(cfg, files, labels, matched, square_m, total, state, extra):
    from aicalib_tf.calib.handeye.files import format_report
    from aicalib_tf.calib.handeye.report import report_figure

    skipped, rejected = state["skipped"], state["rejected"]
    views, size = _views(files, labels, cfg, skipped)
    lens, free = _camera(cfg, views, size, square_m, rejected)
    state["lens"] = lens
    used = [v for v in views if v.name not in rejected]
    result = calibrate_handeye(used, matched, cfg.setup, lens, square_m,
                               pattern_size=None if cfg.board else cfg.pattern, free_intrinsics=free,
                               sigma_rot_deg=cfg.sigma_rot_deg, sigma_t_mm=cfg.sigma_t_mm,
                               rng=np.random.default_rng(cfg.seed), rejected=rejected)
    report = format_report(result, total=total, skipped=skipped, **extra)
    grid = ((cfg.pattern[0] - 1) * square_m, (cfg.pattern[1] - 1) * square_m)
    return result, report, report_figure(result, grid)


def _write_partial(cfg, error: str, state: dict, extra: dict) -> None:
    """handeye.json marked failed, in its own output folder (the run then fails with the error)."""
    from aicalib_tf.calib.handeye.files import partial_dict
    from aicalib_tf.io import atomic_write_text
    from aicalib_tf.jsonio import dumps
    from aicalib_tf.outfolder import OutputFolder

    with OutputFolder(cfg.out, "hand-eye calibration (failed)") as out:
        atomic_write_text(out.path / "handeye.json", dumps(partial_dict(
            error, setup=cfg.setup, rejected={**state["skipped"], **state["rejected"]}, lens=state["lens"], **extra)) + "\n")
    print(f"wrote {cfg.out}: handeye.json marked failed (--save-partial)", file=sys.stderr)
