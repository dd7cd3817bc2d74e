"""From a video, an image sequence, a camera or a stream to a saved calibration, through the guided loop.

The command line is :mod:`aicalib_tf.calibrate` (a video file, ``--camera N`` or a stream URL);
it writes the files of the photo path (camera.yaml, camera.json, camera_info.yaml, report.png,
report.txt), with the kept frames' indices and the loop's counts in camera.json's ``meta``. A
run stopped before its end (Ctrl-C, or a live stream that stops) writes nothing unless
``save_partial``: then the calibration so far, marked ``"partial": true`` in ``meta``.

The board is a chessboard (``pattern``, ``square``) or a ChArUco board (``board``, a
``charuco:...`` description; :mod:`aicalib_tf.geometry.charuco`): a marker board's partial views
name their corners by the markers beside them, so a board cut by the frame is a view as a whole
one is.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

from aicalib_tf.calib.fit import Calibration, CalibrationError
from aicalib_tf.calib.run_options import RunOptions
from aicalib_tf.guided.session import GuidedCalibration, GuidedConfig, check_max_views

__all__ = ["GuidedRunConfig", "run_guided", "progress_line", "summary_lines", "guided_source", "parse_target",
           "board_target", "board_name"]


@dataclass(frozen=True, kw_only=True)
class GuidedRunConfig(RunOptions):
    """A guided run: ``source`` (a video path, image globs as one string, a camera index or a URL), the
    shared :class:`~aicalib_tf.calib.run_options.RunOptions` (the board, detector, lens model, outputs) and
    the loop's settings (:class:`~aicalib_tf.guided.session.GuidedConfig`)."""

    source: str
    target_px: float = 0.1
    max_views: int = 40
    save_partial: bool = False
    examine_all: bool = False

    def __post_init__(self):
        check_max_views(self.max_views)


def board_target(cfg):
    """What the detector looks for: the :class:`~aicalib_tf.geometry.charuco.CharucoBoard` of ``cfg.board``
    (a marker board: partial views name their corners by the markers), else ``cfg.pattern``."""
    if getattr(cfg, "board", None):
        from aicalib_tf.geometry.aprilgrid import is_aprilgrid, load_board
        from aicalib_tf.geometry.charuco import parse_board

        return load_board(cfg.board) if is_aprilgrid(cfg.board) else parse_board(cfg.board)
    return cfg.pattern


def board_name(cfg) -> str:
    """How messages name the board: "9x6 board", "ChArUco board (charuco:...)" or "AprilGrid (aprilgrid:...)"."""
    board = getattr(cfg, "board", None)
    if board:
        from aicalib_tf.geometry.aprilgrid import is_aprilgrid

        return f"{'AprilGrid' if is_aprilgrid(board) else 'ChArUco board'} ({board})"
    return f"{cfg.pattern[0]}x{cfg.pattern[1]} board"


def guided_source(images, camera) -> str | None:
    """The source the guided loop takes from the command line (``--camera``, or one argument that is a
    video file or a stream URL), or None for photos."""
    from aicalib_tf.sources import is_video, is_stream

    if camera is not None:
        return str(camera)
    if len(images) == 1 and (is_stream(images[0]) or is_video(images[0])):
        return images[0]
    return None


def parse_target(text: str) -> float:
    """``"0.1px"`` or ``"0.1"`` -> 0.1 (px, > 0)."""
    t = str(text).strip().lower().removesuffix("px").strip()
    try:
        value = float(t)
    except ValueError:
        value = float("nan")
    if not value > 0 or value == float("inf"):
        raise ValueError(f"--target must be a positive uncertainty in px such as 0.1px, got {text!r}")
    return value


def progress_line(session: GuidedCalibration, target_px: float) -> str:
    """One status line: frames seen and examined, views kept, coverage, the predicted uncertainty."""
    est = session._s.estimate
    sig = f"σ {est.sigma_px:.3f} px (target {target_px:g})" if est else "σ -"
    cov = f"covered {100 * est.covered:.0f}%" if est else "covered -"
    return f"frames {session.frames_seen} | examined {session.examined} | kept {len(session.views)} | {cov} | {sig}"


def summary_lines(session: GuidedCalibration, source: str, stopped: str, used: int | None = None) -> list[str]:
    """The report's head: what the loop saw, why it stopped and, given ``used`` (the number of final
    views), how many of the views seen the calibration took."""
    skipped = ", ".join(f"{n} {why}" for why, n in session.skipped.most_common())
    lines = [f"{source}: {session.frames_seen} frames, {session.examined} examined, {len(session.views)} views kept "
             f"({stopped})", f"  frames not kept: {skipped or 'none'}"]
    if used is not None:
        seen = len(session.views) + len(session._s.pool)
        lines.append(f"  calibrated with {used} of the {seen} views seen (kept or not): the best set of as many as were "
                     "kept, or more until the predicted uncertainty reaches the target (at most --max-views)")
    last = session._s
    if last.guidance is not None and not last.done:
        lines.append(f"  {last.guidance.text}")
    return lines


def _loop(session: GuidedCalibration, source, quiet: bool) -> str:
    """Feed the source to the session; returns why it stopped ("target reached", "end of the video", ...)."""
    last_print = 0.0
    for frame in source:
        update = session.add(frame)
        if not quiet and (update.kept or time.monotonic() - last_print > 0.5):
            print("\r" + progress_line(session, session.cfg.target_px).ljust(96), end="", file=sys.stderr, flush=True)
            last_print = time.monotonic()
        if update.done:
            return "target reached" if len(session.views) < session.cfg.max_views else "--max-views reached"
    return "end of the stream" if source.live else "end of the video, target not reached"


def run_guided(cfg: GuidedRunConfig) -> tuple[Calibration, str]:
    """Run the loop over the source, calibrate the kept views, write the files; returns (calibration, report).

    Raises OSError / ValueError naming the source for a missing or unreadable one (or a bad
    ``out``, before any frame is read), CalibrationError when no board (or too few views) came out
    of it; nothing is written then.
    """
    from aicalib_tf.calib.workflow import make_detector
    from aicalib_tf.guided.save import calibrate_session, save_calibration_set
    from aicalib_tf.outfolder import check_out_path
    from aicalib_tf.sources import open_source

    check_out_path(cfg.out)
    detect = make_detector(cfg.detector, board_target(cfg), cfg.network)
    session = GuidedCalibration(GuidedConfig(cfg.pattern, cfg.square, cfg.square_unit, cfg.model, cfg.target_px,
                                             cfg.max_views, gate=not cfg.examine_all), detect)
    partial = False
    with open_source(cfg.source) as source:
        try:
            stopped = _loop(session, source, cfg.quiet)
        except (KeyboardInterrupt, OSError) as exc:
            if not cfg.save_partial:
                raise
            partial, stopped = True, f"stopped early: {exc or 'interrupted'}"
        finally:
            if not cfg.quiet:
                print(file=sys.stderr)
        dropped = source.dropped
    name = source.name
    if not session.views and not partial:
        why = f"; {detect.why}" if cfg.board and detect.why else ""  # a marker board's detector says why
        raise CalibrationError(f"{name}: no {board_name(cfg)} found in the {session.examined} "
                               f"frames examined (of {session.frames_seen}){why}")
    meta = {**({"board": cfg.board} if cfg.board else {}),
            "detector": cfg.detector, "model": detect.info.get("model"), "model_sha256": detect.info.get("sha256"),
            "lens_model": cfg.model, "source": name, "frames": session.frames_seen, "examined": session.examined,
            "dropped": dropped, "kept_frames": session.kept_frames, "target_px": cfg.target_px,
            "stopped": stopped, "partial": partial}
    try:
        cal, used = calibrate_session(session, meta)
    except CalibrationError as exc:
        raise CalibrationError(f"{name}: {exc}") from None
    return cal, save_calibration_set(cal, used, cfg.out, summary_lines(session, name, stopped, len(used)))
