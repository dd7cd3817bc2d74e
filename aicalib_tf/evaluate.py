"""The benchmark report: the CNN against OpenCV's chessboard detectors, on the same images.

    python -m aicalib_tf.evaluate [--out reports/DATE] [--quick] [--model PATH]
        [--detectors cnn,report,opencv,opencv-sb] [--conditions LIST] [--limit N] [--quiet]
    python -m aicalib_tf.evaluate --images DIR --pattern 9x6 [--degrade] [--out ...]

Default suite (no download, fixed seeds): data_gen renders of 9×6 boards at 640×480 under the
named conditions (clean, noise20/40, blur2/3, contrast, shading, jpeg15, saltpepper5, barrel,
fisheye150, fisheye185, fisheye_closeup (boards close to circular 150–200° fisheyes), tilt60, small,
occluded, partial, board-free clutter) plus clean 1920×1080 images; severity
sweeps (noise σ 0–60, blur σ 0.5–4 px, contrast, JPEG quality, lens distortion, tilt), each
level on the same scenes; and 4 calibration sequences (data_gen ``calib``, seed 11: two mild
lenses, two strong barrel lenses) with known K and distortion. ``--conditions`` takes condition
names, sweep names (noise, blur, contrast, jpeg, distortion, tilt), ``named``, ``sweeps`` or
``all`` (default); ``calib`` adds the calibration sequences (always run with ``all``).

Detectors, all in this one process and timed per call (time.perf_counter, after a warm-up at each image size); each
image goes through every detector in turn, and a condition's images are all rendered before any
is timed. At the end, each detector's 20 slowest images of each size are timed twice more, round
robin, and keep their least time (results.csv ``time_runs``; ``time_first_ms`` keeps the first
run's time): on a shared 2-core machine a single stall otherwise sets a detector's slowest time,
while an image that is slow every time stays slow.
The detectors:
cnn (the CNN pipeline with --model, default models/default.keras), report (the same pipeline
with the report's patch classifier), opencv (cv2.findChessboardCorners + cornerSubPix), and
opencv-sb (cv2.findChessboardCornersSB).

Metrics (aicalib_tf.bench.metrics, DESIGN.md): a *hit* is a full board whose corners all lie within
2 px of the truth under the board's symmetries; a full board with any corner further off is a
*wrong* detection; an incomplete board is *partial* (its recall over the visible corners and its
wrong ids are counted); nothing is a *miss*. Corner errors (median, RMSE, p95) are over the
corners of hits. On board-free images any full board is a false board. Calibration: each
detector's boards of a sequence (partial ones too) -> aicalib_tf.calib.workflow.calibrate_camera ->
focal error %, principal point px, distortion-field px against the true camera, and RMS.
Rigs (full suite with calibration, not --quick): the four data_gen rigs of aicalib_tf.bench.rigs
(two pinholes, pinhole + fisheye, two fisheyes, three cameras; 20 pairs at 1280×960), our rig
calibration against OpenCV's stereoCalibrate pipeline: baseline and rotation errors against the
truth and rectified |Δy| in-sample and on held-out pairs (rigs.csv).

With ``--workers N`` (default: one per core) N processes render the images, N conditions at a time,
before any of them is timed; the detectors and their timings stay in this process, one image at a
time, so the times are those of one detection on an idle machine, whatever N is.

Sizes: the full suite renders 100 images per named condition, 32 per sweep level, 30 at
1920×1080 and 20 views per calibration sequence; --quick renders 6, 3, 2 and 6 (2 per fisheye
condition); --limit N caps
every count at N (calibration views at max(3, N)).

--images DIR --pattern CxR: the user's photos, no ground truth: per image each detector's
result and time, pairwise agreement of full boards, and the calibration each detector gives.
--degrade adds seeded degradations of every photo (noise σ 20 and 40, blur σ 2.5, JPEG quality
8, low light, gradient with shadow, 3 % salt-and-pepper) scored against the clean photo's
consensus board (see aicalib_tf.bench.photos).

Writes into --out (default reports/<YYYYmmdd-HHMMSS>), atomically: results.csv (one row per
image × detector), summary.csv, calibration.csv, rigs.csv (full suite), report.md, figures/*.png and
config.json.
With ``--board charuco:...`` the suite is the ChArUco one instead (:mod:`aicalib_tf.bench.charuco`:
the chessboard conditions with the ChArUco board, the CNN pipeline against OpenCV's
CharucoDetector with default and refined parameters on the same images): correct corners, the
share of the visible ones named, wrong ids, the median error and time, per condition, written as
report.md and results.csv (10 images per condition, 3 with --quick, --limit N).

Exit codes: 0 done; 2 bad arguments.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

from aicalib_tf.bench.conditions import PATTERN, select_conditions
from aicalib_tf.bench.detectors import DETECTORS, make_detectors
from aicalib_tf.bench.runner import EvalConfig, _split_calib, run
from aicalib_tf.detect.batch import default_workers


def build_parser():
    """The command line's parser (docs/cli.md is generated from it)."""
    from aicalib_tf.cli import parser

    ap = parser("python -m aicalib_tf.evaluate", __doc__)
    ap.add_argument("--out", default=None, help="output folder (default: reports/<YYYYmmdd-HHMMSS>)")
    ap.add_argument("--quick", action="store_true", help="a small suite (about 2 minutes)")
    ap.add_argument("--model", default="default", help="the cnn detector's model: default, default_int8, fast, fast_int8, report or a .tflite/.keras path")
    ap.add_argument("--detectors", default=",".join(DETECTORS), help="comma list from %(default)s")
    ap.add_argument("--conditions", default=None, help="comma list of conditions / sweeps / named / sweeps / calib / all")
    ap.add_argument("--limit", type=int, default=None, help="at most N images per condition (tiny runs)")
    ap.add_argument("--images", default=None, help="a folder of the user's photos (no ground truth)")
    ap.add_argument("--pattern", default=None, help="inner corners COLSxROWS for --images, e.g. 9x6")
    ap.add_argument("--degrade", action="store_true", help="with --images: also score seeded degradations of each photo")
    ap.add_argument("--seed", type=int, default=0, help="seed of the --degrade noise (default: %(default)s)")
    ap.add_argument("--workers", type=int, default=None,
                    help="processes rendering the images (default: one per core); detection is timed in one process")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    ap.add_argument("--board", default=None,
                    help="the ChArUco suite with this board, e.g. charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100")
    return ap


def _parse_args(argv):
    return build_parser().parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Parse arguments, run, print where the report is; exit 2 on bad arguments."""
    started = time.perf_counter()
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    args = _parse_args(argv)
    from aicalib_tf.cli import run_main

    return run_main(lambda: _main(args, argv, started), debug=args.debug)


def _main(args, argv, started: float) -> int:
    dets = tuple(d.strip() for d in args.detectors.split(",") if d.strip())
    bad = [d for d in dets if d not in DETECTORS]
    if bad or not dets:
        raise ValueError(f"unknown detector(s) {', '.join(bad) or '(none)'}; choose from {', '.join(DETECTORS)}")
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    if args.limit is not None and args.limit < 1:
        raise ValueError(f"--limit must be >= 1, got {args.limit}")
    if args.board is not None:
        return _charuco_suite(args, argv, started)
    pattern = None
    if args.images is not None:
        from aicalib_tf.geometry.pattern import parse_pattern

        if args.pattern is None:
            raise ValueError("--images needs --pattern COLSxROWS")
        pattern = parse_pattern(args.pattern)
        if not Path(args.images).is_dir():
            raise ValueError(f"--images {args.images}: not a folder")
        from aicalib_tf.bench.photos import list_images

        list_images(Path(args.images))  # a folder without images is a bad argument
    elif args.pattern is not None or args.degrade:
        raise ValueError("--pattern and --degrade go with --images")
    else:
        spec, _ = _split_calib(args.conditions)
        if spec != "":
            select_conditions(spec)  # unknown names fail here, before any work
    out = args.out or str(Path("reports") / time.strftime("%Y%m%d-%H%M%S"))
    from aicalib_tf.outfolder import check_out_path

    check_out_path(out)  # a file, a path under a file, a name too long: refused before any work
    cfg = EvalConfig(out=out, quick=args.quick, model=args.model, detectors=dets, conditions=args.conditions,
                     limit=args.limit, images=args.images, pattern=pattern, degrade=args.degrade, seed=args.seed,
                     quiet=args.quiet, workers=args.workers or default_workers(), command="python -m aicalib_tf.evaluate " + " ".join(
                         sys.argv[1:] if argv is None else argv))
    detectors, info = make_detectors(dets, pattern or PATTERN, args.model)  # a bad model is a bad argument
    folder = run(cfg, detectors, info, started=started)
    print(f"report: {folder / 'report.md'}")
    return 0


CHARUCO_IMAGES = (10, 3)  # images per ChArUco condition: the suite, --quick


def _charuco_suite(args, argv, started: float) -> int:
    """``--board``: the ChArUco suite (module docstring) into ``--out``; ValueError for a bad board
    or options that belong to the chessboard suite (``--limit`` and ``--workers`` are checked by the caller)."""
    import pandas as pd

    from aicalib_tf.bench.charuco import detection_markdown, detection_table
    from aicalib_tf.bench.report import _csv
    from aicalib_tf.cnn.model import load_model
    from aicalib_tf.geometry.charuco import parse_board
    from aicalib_tf.io import atomic_write_text
    from aicalib_tf.outfolder import OutputFolder, check_out_path

    parse_board(args.board)  # a board that cannot be is an error before any work
    if args.images is not None or args.pattern is not None or args.conditions is not None or args.degrade:
        raise ValueError("--board runs the ChArUco suite: it takes --quick, --limit, --model and --out, not --images, "
                         "--pattern, --conditions or --degrade")
    out = args.out or str(Path("reports") / time.strftime("%Y%m%d-%H%M%S"))
    check_out_path(out)
    model = load_model(args.model)
    n = args.limit or CHARUCO_IMAGES[bool(args.quick)]
    rows = detection_table(args.board, n, model)
    command = "python -m aicalib_tf.evaluate " + " ".join(sys.argv[1:] if argv is None else argv)
    report = (f"# ChArUco benchmark\n\n`{command}`: {args.board}, {n} images per condition, "
              f"{time.perf_counter() - started:.0f} s\n\n{detection_markdown(rows)}\n")
    with OutputFolder(out, "report") as folder:
        atomic_write_text(folder.path / "report.md", report)
        _csv(pd.DataFrame(rows), folder.path / "results.csv")
    print(detection_markdown(rows))
    print(f"report: {Path(out) / 'report.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
