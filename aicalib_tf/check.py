"""Field check: does an existing calibration still hold? (for a camera that may have been knocked)

    python -m aicalib_tf.check calib/camera.json "check/*.jpg" [--out check.json]
    python -m aicalib_tf.check calib/ drive.mp4 --every 15

The calibration is a camera.json, a camera.yaml (OpenCV; it carries no covariance, so the check
takes its intrinsics as exact and flags more readily) or a folder holding camera.json. Show the
same board (the calibration's pattern and square size) in about 15 new photos or a short video
from varied angles. Every image goes through the detector; the intrinsics stay as calibrated and
only the boards' poses are fitted; a second fit refits every intrinsic, and its residuals give
the corner noise of the new footage (its light, blur and distance, whatever they are). Two tests
follow (:mod:`aicalib_tf.calib.check`), each at level --alpha (default 0.01), both at the new
footage's own noise:

- the drift of fx, fy, cx, cy, refitted to the new views with the distortion held, against
  the calibration's values, with both uncertainties combined (a chi-square test over the four);
- the lens test: how much refitting every intrinsic lowers the residuals (a changed distortion
  leaves a radial pattern; blur and noise do not), beyond what the calibration's uncertainty allows.

Both allow at least 0.04 px per axis of corner error that repeats between views (a detector's
systematic error), so very clean footage does not make a negligible change significant.

It prints the verdict, the views used and skipped with reasons, the corner noise of both footages,
each drift with ±1σ, and the smallest fx change and principal-point shift these views detect 95% of
the time (with a note when the new footage is much noisier than the calibration's); --out writes
the same as JSON (atomically). --out must be a new file or one an earlier check wrote, never one
of the inputs.

A video file (.mp4, .avi, .mov, .mkv, .webm, .m4v, .mpg) is sampled every --every frames
(default 10, at most --max-frames of them).

Exit codes: 0 the calibration holds; 1 it does not; 2 bad input (an unreadable calibration or one
the check cannot use, such as a covariance that is not one or too large to detect a change, no
images, fewer than 3 usable views, images of another size than the calibration's, an --out that
is an input or a file this command did not write).
"""

from __future__ import annotations

import dataclasses
import os
import sys
from collections import Counter
from pathlib import Path

from aicalib_tf.cnn.spec import DETECTOR_NETWORK, NETWORK_HELP

WRITTEN_BY = "aicalib_tf.check"  # the --out file's "written_by": a later run may replace such a file
MAX_OUT_BYTES = 64 << 20  # an existing --out larger than this is not a check result


@dataclasses.dataclass(frozen=True)
class CheckConfig:
    """Everything one field check needs (the CLI's options)."""

    calibration: str
    sources: tuple[str, ...]
    detector: str = "cnn"
    network: str = DETECTOR_NETWORK
    alpha: float = 0.01
    hold_distortion: bool = True
    every: int = 10
    max_frames: int = 200
    workers: int | None = None
    out: str | None = None


def build_parser():
    """The command line's parser (docs/cli.md is generated from it)."""
    from aicalib_tf.calib.workflow import DETECTORS
    from aicalib_tf.cli import parser

    ap = parser("python -m aicalib_tf.check", __doc__)
    ap.add_argument("calibration", help="camera.json, camera.yaml or a folder holding camera.json")
    ap.add_argument("sources", nargs="+", help="photos, glob patterns (quote them) or a video file")
    ap.add_argument("--out", default=None, help="also write the result as JSON to this file")
    ap.add_argument("--alpha", type=float, default=0.01, help="each test's false-alarm rate (default: %(default)s)")
    ap.add_argument("--all-intrinsics", action="store_true",
                    help="refit the distortion too for the drift (default: held at the calibration's)")
    ap.add_argument("--detector", default="cnn", choices=DETECTORS, help="corner detector (default: %(default)s)")
    ap.add_argument("--network", default=DETECTOR_NETWORK, help=NETWORK_HELP)
    ap.add_argument("--every", type=int, default=10, help="video: use every Nth frame (default: %(default)s)")
    ap.add_argument("--max-frames", type=int, default=200, help="video: at most this many frames (default: %(default)s)")
    ap.add_argument("--workers", type=int, default=None, help="detection processes for photos (default: one per core)")
    return ap


def _parse_args(argv):
    return build_parser().parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """CLI entry: 0 the calibration holds, 1 it does not, 2 bad input (one line on stderr)."""
    from aicalib_tf.cli import run_main

    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    args = _parse_args(argv)
    cfg = CheckConfig(calibration=args.calibration, sources=tuple(args.sources), detector=args.detector,
                      network=args.network, alpha=args.alpha, hold_distortion=not args.all_intrinsics,
                      every=args.every, max_frames=args.max_frames, workers=args.workers, out=args.out)
    return run_main(lambda: _main(cfg), debug=args.debug)


def _main(cfg: CheckConfig) -> int:
    result, report = run_check(cfg)
    print(report)
    if cfg.out:
        print(f"wrote {cfg.out}")
    return 0 if result.holds else 1


def run_check(cfg: CheckConfig):
    """Load, detect, check, write --out; returns (CheckResult with every skipped view, printed report).

    Raises FileNotFoundError / ValueError / CalibrationError for bad input, before writing anything.
    """
    from aicalib_tf.calib.check import MIN_CHECK_VIEWS, check_calibration, check_fields, format_check
    from aicalib_tf.calib.files import existing_file, load_calibration
    from aicalib_tf.calib.fit import CalibrationError
    from aicalib_tf.calib.schema import file_errors
    from aicalib_tf.jsonio import dumps
    from aicalib_tf.io import atomic_write_text, expand_images

    if not 0.0 < cfg.alpha < 0.5:
        raise ValueError(f"--alpha must be in (0, 0.5), got {cfg.alpha}")
    if cfg.every < 1 or cfg.max_frames < 1:
        raise ValueError(f"--every and --max-frames must be >= 1, got {cfg.every} and {cfg.max_frames}")
    cal = load_calibration(cfg.calibration)
    cal_file = existing_file(cfg.calibration, "camera.json", "calibration")
    with file_errors(cal_file, "calibration for a field check"):
        check_fields(cal)
    files = expand_images(cfg.sources)
    if not files:
        raise ValueError(f"no photos or video match {' '.join(cfg.sources)}")
    if cfg.out:
        check_out_file(cfg.out, [cal_file, *files])
    views, skipped = _detect(files, cal, cfg)
    if len(views) < MIN_CHECK_VIEWS:
        why = "; ".join(f"{k}: {v}" for k, v in list(skipped.items())[:3]) + ("; ..." if len(skipped) > 3 else "")
        raise CalibrationError(f"{len(views)} of {len(views) + len(skipped)} images show the calibration's "
                               f"{cal.pattern_size[0]}x{cal.pattern_size[1]} board; the check needs at least "
                               f"{MIN_CHECK_VIEWS}" + (f" ({why})" if why else ""))
    result = check_calibration(cal, views, alpha=cfg.alpha, hold_distortion=cfg.hold_distortion)
    result = dataclasses.replace(result, skipped={**skipped, **result.skipped})
    report = format_check(result, source=str(cfg.calibration))
    if cfg.out:
        doc = {"written_by": WRITTEN_BY, "calibration": str(cfg.calibration), "sources": list(cfg.sources),
               "detector": cfg.detector, **result.to_dict()}
        atomic_write_text(Path(cfg.out), dumps(doc) + "\n")
    return result, report


def _written_by_check(path: Path) -> bool:
    """Whether an existing file is a result this command wrote (strict JSON with ``written_by``, or an
    older result: an object with the calibration, sources, verdict and drift test)."""
    from aicalib_tf.jsonio import read_json

    try:
        if path.stat().st_size > MAX_OUT_BYTES:
            return False
        doc = read_json(path, max_bytes=MAX_OUT_BYTES)
    except (OSError, ValueError):
        return False
    return isinstance(doc, dict) and (doc.get("written_by") == WRITTEN_BY
                                      or {"calibration", "sources", "holds", "drift_test"} <= doc.keys())


def check_out_file(out: str, inputs) -> Path:
    """The --out file after refusing, with a ValueError naming it: an empty name, a folder, a path
    whose folder does not exist, one of ``inputs`` (the calibration, photos, videos; links followed),
    or an existing file that this command did not write (:func:`_written_by_check`)."""
    if not str(out).strip():
        raise ValueError("--out: an empty file name")
    path = Path(os.path.realpath(out))
    if path.is_dir():
        raise ValueError(f"{out}: is a folder; --out takes a file name such as check.json")
    if not path.parent.is_dir():
        raise ValueError(f"{out}: the folder {path.parent} does not exist")
    if any(path == Path(os.path.realpath(f)) for f in inputs):
        raise ValueError(f"{out}: is one of the inputs of this check; --out would overwrite it, choose another file")
    if path.exists() and not _written_by_check(path):
        raise ValueError(f"{out}: exists and is not a result of python -m aicalib_tf.check; --out replaces only "
                         "those, so remove it or choose another file")
    return path


def board_of(cal):
    """What the detector looks for: the calibration's marker board (a ChArUco board or an AprilGrid,
    ``meta["board"]`` of its camera.json), else its chessboard pattern."""
    text = (cal.meta or {}).get("board")
    if not isinstance(text, str) or not text:
        return tuple(cal.pattern_size)
    from aicalib_tf.geometry.aprilgrid import is_aprilgrid, load_board
    from aicalib_tf.geometry.charuco import parse_board
    from aicalib_tf.geometry.circles import is_circles

    if is_circles(text):  # its centres need the projected-centre bias removed (calib.circle_bias), per view
        raise ValueError(f"the calibration was made with a circle grid ({text}); the field check reads "
                         "chessboards, ChArUco boards and AprilGrids")
    return load_board(text) if is_aprilgrid(text) else parse_board(text)


def _detect(files: list[str], cal, cfg: CheckConfig):
    """Views of the calibration's board in every photo and sampled video frame; (views, {label: why skipped})."""
    from aicalib_tf.calib.fit import View
    from aicalib_tf.calib.workflow import _file_detector
    from aicalib_tf.detect.batch import map_images
    from aicalib_tf.io import display_name
    from aicalib_tf.sources import is_video

    videos = [f for f in files if is_video(f)]
    photos = [f for f in files if f not in videos]
    views, skipped = [], {}
    cols, rows = cal.pattern_size
    found = list(zip(photos, map_images(photos, _file_detector, (cfg.detector, board_of(cal), cfg.network),
                                        workers=cfg.workers))) if photos else []
    for video in videos:
        found += list(_detect_frames(video, cal, cfg))
    names = Counter(Path(label).name for label, _ in found)
    for source, res in found:
        label = Path(source).name if names[Path(source).name] == 1 else source
        if isinstance(res, str):
            skipped[label] = res.removeprefix(f"{display_name(source)}: ")
        elif res[0] != tuple(cal.image_size):
            skipped[label] = (f"image is {res[0][0]}x{res[0][1]}, the calibration is for "
                              f"{cal.image_size[0]}x{cal.image_size[1]}")
        elif res[1] is None:
            skipped[label] = f"no {cols}x{rows} board found" + (f": {res[2]}" if res[2] else "")
        else:
            views.append(View(label, *res[1], relative=res[3], sigmas=res[5]))
    return views, skipped


def _detect_frames(video: str, cal, cfg: CheckConfig):
    """(label, detection as :func:`aicalib_tf.calib.workflow._file_detector`'s work returns) per sampled
    frame of a video."""
    from aicalib_tf.calib.workflow import make_detector
    from aicalib_tf.io import load_image

    detect = make_detector(cfg.detector, board_of(cal), cfg.network)
    for index, frame in video_frames(video, cfg.every, cfg.max_frames):
        gray = load_image(frame)
        hit = detect(gray)
        yield f"{video}#{index}", (gray.shape[::-1], hit, detect.why, detect.relative, None, detect.sigmas)


def video_frames(path: str, every: int = 10, limit: int = 200):
    """(frame index, (H, W) uint8 grey frame) for every ``every``-th frame of a video file, at most
    ``limit``, through the shared frame iterator (:class:`aicalib_tf.sources.VideoFile`). Raises
    FileNotFoundError / ValueError naming a file that is missing or not a readable video."""
    from itertools import islice

    from aicalib_tf.sources import VideoFile

    with VideoFile(path) as source:
        for frame in islice((f for f in source if f.index % every == 0), limit):
            yield frame.index, frame.gray


if __name__ == "__main__":
    sys.exit(main())
