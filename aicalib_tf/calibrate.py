"""Calibrate a camera from a folder of chessboard photos.

    python -m aicalib_tf.calibrate "photos/*.jpg" --pattern 9x6 --square 25mm [--out calib/]
        [--model auto|plumb_bob|rational_polynomial|thin_prism|equidistant|ds|eucm|splined_equidistant] [--rational] [--fix-k3]
        [--detector cnn|report|opencv|opencv-sb] [--network default|report|PATH.keras]
        [--resize-policy error|skip|crop|scale]

Every image goes through the detector (default: the CNN, which also returns partial boards;
each counts as a view with its own pose). One least-squares fit of the lens model over all views
follows, with outlier views rejected one at a time (see :mod:`aicalib_tf.calib.fit`). With
``--model auto`` (the default) every lens model is fitted and cross-validated on held-out views,
and the simplest one within one standard error of the best is kept; the report prints the table.
``--rational`` is ``--model rational_polynomial``. ``--model`` used to name the CNN's network: a
value ending in .keras, or "default"/"report", still does (with a note), else use ``--network``.

It prints a compact report (images used, skipped and rejected with reasons; RMS and worst view;
K and distortion with ±1σ; field of view; warnings) and writes into --out, atomically:
camera.yaml (OpenCV FileStorage), camera.json (the same plus board, detector, model sha256 and
per-view poses), camera_info.yaml (ROS), camchain.yaml (Kalibr), report.png, and an undistorted
preview of one image.

A rig (stereo pair or more cameras) takes one NAME=GLOB per camera instead of the images:

    python -m aicalib_tf.calibrate --rig cam0="left/*.png" cam1="right/*.png" [cam2=...] --pattern 9x6 --square 25mm --out rig/

Images are paired by a shared name stem (``left01``/``right01`` -> ``01``, or equal stems), else by
sorted order when the counts match; the report says which rule it used and lists unpaired files.
Each camera's lens is chosen as above (or forced: ``--model equidistant`` for all, or one per
camera: ``--model plumb_bob,equidistant``), then one joint fit refines every lens and the cameras'
poses; frames whose cameras disagree are rejected with the reason. It writes intrinsics.yml and
extrinsics.yml (OpenCV's stereo_calib nodes, plus E, F and distortion_model1/2), one ROS
camera_info per camera with the rectification, rig.json, each camera's own files, report.png
(rectified preview, per-pair epipolar errors, baseline with σ) and report.txt. A rig of three
or more cameras writes the stereo files per pair with camera 0 (cam0_cam2/...).

A video (a file OpenCV reads: .mp4, .avi, ...), a camera or a stream goes through the guided loop
(:mod:`aicalib_tf.guided`): frames are examined while the board rests, blurred frames and
near-duplicates are skipped, and a view is kept when it covers new image area or lowers the
predicted projection uncertainty; the loop stops at the --target uncertainty (90th percentile
over the covered area, every image region covered) or at --max-views, and prints where to hold
the board next. The files are those of the photo path, with the kept frames in camera.json:

    python -m aicalib_tf.calibrate video.mp4 --pattern 9x6 --square 25mm --out calib/ [--target 0.1px]
        [--max-views 40] [--save-partial]
    python -m aicalib_tf.calibrate --camera 0 --pattern 9x6 --square 25mm   (or --camera rtsp://...)

A run stopped early (Ctrl-C, a stream that stops), of one camera or of a rig, writes nothing
unless --save-partial, which writes the calibration so far marked partial.

A rig filmed on video (every --rig item a video file or a stream) goes through the same loop per
camera (:mod:`aicalib_tf.guided.rig_video`): each camera keeps its informative frames, and every
frame either camera keeps is paired with the other cameras' frame of that instant (by timestamp
within --sync-tolerance, or --pair-by index), detected there, and shared by the rig. Unpaired
frames are reported; cameras that drift out of sync are refused with the measured offset. The
files are those of the photo rig above, with each camera's kept frames in rig.json:

    python -m aicalib_tf.calibrate --rig cam0=left.mp4 cam1=right.mp4 --pattern 9x6 --square 25mm --out rig/
        [--sync-tolerance 10ms] [--pair-by time|index] [--target 0.1px] [--max-views 40]

Images of different sizes are an error naming the odd files unless --resize-policy says what to
do: skip them, crop them to the common size (top-left kept; exact when an image only has extra
rows or columns at the right or bottom, like 1281x721 among 1280x720), or scale their corners.

A ChArUco board replaces --pattern and --square: ``--board charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100``
(every view is partial by nature; each corner's id comes from the markers beside it). With --rig,
each camera may see a different part of the board in a pair: the ids tie them. Videos, cameras and
rig videos read it too (``video.mp4 --board charuco:...``): a board cut by the frame is a view.

Kalibr's AprilGrid is a board too: ``--board aprilgrid:6x6,tag=88mm,spacing=0.3[,family=tag36h11][,first=0]``
(tags across x up, tag size, gap between tags over the tag size; ids row-major from the bottom-left),
or Kalibr's target file ``--board target.yaml`` (``target_type: aprilgrid``, or ``checkerboard``
read as --pattern and --square). OpenCV's aruco decodes the tags; each tag corner is placed by the
saddle fit. Photos, videos and cameras read it as they read a ChArUco board.

OpenCV's circle grids, for photos: ``--board circles:4x11,spacing=20mm,asymmetric[,diameter=14mm]`` or
``circles:7x6,spacing=20mm,symmetric`` (OpenCV's patternSize (cols, rows) and its object points;
diameter defaults to half the nearest centre distance). cv2.findCirclesGrid finds the grid; each
centre is the circle's dark-area centroid, corrected for the projected-centre bias with the lens and
poses of a first calibration, then calibrated again (two corrections).

Exit codes: 0 success; 2 bad input (no images, bad --pattern or --square, a bad model, no board
found, fewer than 3 usable views, mixed sizes); nothing is written on failure.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from aicalib_tf.cnn.spec import DETECTOR_NETWORK, NETWORK_HELP
from aicalib_tf.calib.workflow import (
    DETECTORS,
    RESIZE_POLICIES,
    CalibrateConfig,
    parse_square,
    run,
)
from aicalib_tf.calib.flex import FLEX_DEFAULT, FLEX_MODES
from aicalib_tf.geometry.lens import MODELS


def build_parser():
    """The command line's parser (docs/cli.md is generated from it)."""
    from aicalib_tf.cli import parser

    ap = parser("python -m aicalib_tf.calibrate", __doc__)
    ap.add_argument("images", nargs="*", help="image files or glob patterns (quote globs)")
    ap.add_argument("--rig", nargs="+", metavar="NAME=GLOB",
                    help='calibrate a rig: one NAME=GLOB per camera, e.g. cam0="left/*.png" cam1="right/*.png"')
    ap.add_argument("--pattern", help="inner corners, COLSxROWS, e.g. 9x6 (or --board)")
    ap.add_argument("--board", help="a ChArUco board instead of --pattern and --square: "
                                    "charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100[,legacy][,first=0]; "
                                    "an AprilGrid: aprilgrid:6x6,tag=88mm,spacing=0.3[,family=tag36h11][,first=0]; "
                                    "a Kalibr target.yaml; "
                                    "or a circle grid: circles:4x11,spacing=20mm,asymmetric|symmetric[,diameter=10mm]")
    ap.add_argument("--square", default="1", help="square size with unit, e.g. 25mm (default: 1, unitless)")
    ap.add_argument("--out", default="calib", help="output folder (default: %(default)s)")
    ap.add_argument("--detector", default="cnn", choices=DETECTORS, help="corner detector (default: %(default)s)")
    ap.add_argument("--model", default="auto",
                    help=f"lens model: auto (chosen on held-out views) or one of {', '.join(MODELS)}; with --rig, one "
                         "for all cameras or a comma list, one per camera (default: %(default)s)")
    ap.add_argument("--network", default=DETECTOR_NETWORK, help=NETWORK_HELP)
    ap.add_argument("--fix-k3", action="store_true", help="hold k3 at 0 (pinhole models; narrow lenses, few views)")
    ap.add_argument("--rational", action="store_true", help="the same as --model rational_polynomial")
    ap.add_argument("--flex", choices=FLEX_MODES, default=None,
                    help="photos: shape solves the board's shape (its sag, twist and S-bends, 7 terms) with the camera, "
                         "each term shrunk towards flat by the noise of its estimate; auto (the default for photos) "
                         "keeps it only when it moves the lens by more than its noise, else the board is flat; sag "
                         "solves the parabolic sag alone; off: flat (videos, cameras and rigs; see docs/calibration.md)")
    ap.add_argument("--workers", type=int, default=None,
                    help="detection processes (default: one per core, but one per 8 images at most)")
    ap.add_argument("--resize-policy", default="error", choices=RESIZE_POLICIES,
                    help="images whose size differs from the most common one (default: %(default)s)")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    ap.add_argument("--camera", help="calibrate from a live camera (an index: 0, 1, ...) or a stream URL")
    ap.add_argument("--target", default="0.1px", help="video/camera: stop at this uncertainty (default: %(default)s)")
    ap.add_argument("--max-views", type=int, default=40, help="video/camera: keep at most this many views")
    ap.add_argument("--save-partial", action="store_true", help="video/camera (one or a rig): a run stopped early still writes, marked partial")
    ap.add_argument("--sync-tolerance", default="10ms",
                    help="rig videos: pair frames whose timestamps are this close (default: %(default)s)")
    ap.add_argument("--pair-by", default="time", choices=("time", "index"),
                    help="rig videos: pair the cameras' frames by timestamp or by frame number (default: %(default)s)")
    return ap


def _parse_args(argv):
    return build_parser().parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """CLI entry: returns 0 on success, 2 on bad input (message on stderr, no files written)."""
    from aicalib_tf.cli import run_main

    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    args = _parse_args(argv)
    return run_main(lambda: _main(args), debug=args.debug)


def _main(args) -> int:
    if args.model.endswith(".keras") or args.model in ("default", "report"):  # the old meaning of --model
        print(f"note: --model {args.model} names a network; use --network {args.model} (the lens model stays auto)",
              file=sys.stderr)
        args.network, args.model = args.model, "auto"
    if args.rational and args.model not in ("auto", "rational_polynomial"):
        print(f"error: --rational means --model rational_polynomial, but --model is {args.model}", file=sys.stderr)
        return 2
    bad = [m for m in args.model.split(",") if m != "auto" and m not in MODELS]
    if bad or ("," in args.model and not args.rig):
        print(f"error: unknown --model {args.model!r}; choose auto or one of {', '.join(MODELS)}"
              + (" (a comma list, one per camera, goes with --rig)" if not bad else ""), file=sys.stderr)
        return 2
    from aicalib_tf.guided.workflow import guided_source

    source = guided_source(args.images, args.camera)
    if args.flex not in (None, "off") and (source is not None or args.rig):
        raise ValueError("--flex is solved for photos of one camera; videos, cameras and rigs take the board flat")
    if args.board and args.board.strip().lower().startswith("circles:") and (source is not None or args.rig):
        raise ValueError("--board circles:... is read from photos of one camera; videos, cameras and rigs take "
                         "a chessboard, a ChArUco board or an AprilGrid")
    if source is not None and not args.rig:
        from aicalib_tf.guided.workflow import GuidedRunConfig, parse_target, run_guided

        return _run(lambda: GuidedRunConfig(source=source, target_px=parse_target(args.target), max_views=args.max_views,
                                            save_partial=args.save_partial, **_common(args)), run_guided,
                    "camera.yaml, camera.json (with the kept frames), camera_info.yaml, report.png")
    if bool(args.rig) == bool(args.images):
        print("error: give either images or --rig NAME=GLOB ... (not both)" if args.rig else "error: no images given",
              file=sys.stderr)
        return 2
    if args.rig and (args.fix_k3 or args.rational or args.resize_policy != "error"):
        given = [f for f, on in (("--fix-k3", args.fix_k3), ("--rational", args.rational),
                                 ("--resize-policy", args.resize_policy != "error")) if on]
        raise ValueError(f"{', '.join(given)} cannot be used with --rig (give --model per camera instead; "
                         "every image of a camera must have one size)")
    if args.rig:
        from aicalib_tf.calib.rig.workflow import RigConfig, parse_rig, run_rig
        from aicalib_tf.guided.rig_video import is_rig_video, run_rig_video

        cameras = tuple(parse_rig(args.rig))
        wrote = "rig.json, the stereo YAML files, camera_info per camera, camchain.yaml, report.png"
        if is_rig_video(cameras):
            return _run(lambda: _rig_video_config(args, cameras), run_rig_video, wrote)
        return _run(lambda: RigConfig(cameras=cameras, **_common(args)), run_rig, wrote)
    return _run(lambda: CalibrateConfig(images=tuple(args.images), fix_k3=args.fix_k3, rational=args.rational,
                                        resize_policy=args.resize_policy, flex=args.flex or FLEX_DEFAULT, **_common(args)), run,
                "camera.yaml, camera.json, camera_info.yaml, camchain.yaml, report.png")


def _rig_video_config(args, cameras):
    """The rig-video run's config from the command line (ValueError for a bad --target or --sync-tolerance)."""
    from aicalib_tf.guided.rig_video import RigVideoConfig, parse_tolerance
    from aicalib_tf.guided.workflow import parse_target

    return RigVideoConfig(cameras=cameras, target_px=parse_target(args.target), max_views=args.max_views,
                          sync_tolerance_s=parse_tolerance(args.sync_tolerance), pair_by=args.pair_by,
                          save_partial=args.save_partial, **_common(args))


def _common(args) -> dict:
    """The options one camera and a rig share, of photos or of the guided loop, parsed
    (ValueError for a bad --pattern, --square or --board)."""
    from aicalib_tf.geometry.aprilgrid import is_aprilgrid
    from aicalib_tf.geometry.circles import is_circles
    from aicalib_tf.geometry.circles import parse_board as parse_circles
    from aicalib_tf.geometry.pattern import check_pattern, parse_pattern

    if args.board and is_aprilgrid(args.board):  # an AprilGrid, or a Kalibr target file
        return _aprilgrid_common(args)
    if args.board and is_circles(args.board):  # an OpenCV circle grid
        board = parse_circles(args.board)
        return dict(pattern=board.pattern_size, square=board.square_size, square_unit=board.unit, board=args.board,
                    out=args.out, detector=args.detector, network=args.network,
                    model="rational_polynomial" if args.rational else args.model, quiet=args.quiet, workers=args.workers)
    if args.board:
        from aicalib_tf.geometry.charuco import parse_board

        board = parse_board(args.board)
        return dict(pattern=board.pattern_size, square=board.square, square_unit=board.unit, board=args.board,
                    out=args.out, detector=args.detector, network=args.network,
                    model="rational_polynomial" if args.rational else args.model, quiet=args.quiet, workers=args.workers)
    if not args.pattern:
        raise ValueError("give --pattern COLSxROWS (a chessboard) or --board charuco:... (a ChArUco board)")
    square, unit = parse_square(args.square)
    return dict(pattern=check_pattern(parse_pattern(args.pattern)), square=square, square_unit=unit, out=args.out,
                detector=args.detector, network=args.network,
                model="rational_polynomial" if args.rational else args.model, quiet=args.quiet, workers=args.workers)


def _aprilgrid_common(args) -> dict:
    """:func:`_common` for ``--board aprilgrid:...`` or a Kalibr target YAML (an AprilGrid, or a
    checkerboard read as ``--pattern``/``--square``)."""
    from aicalib_tf.geometry.aprilgrid import Checkerboard, load_board

    board = load_board(args.board)
    shared = dict(out=args.out, detector=args.detector, network=args.network,
                  model="rational_polynomial" if args.rational else args.model, quiet=args.quiet, workers=args.workers)
    if isinstance(board, Checkerboard):
        return dict(pattern=board.pattern_size, square=board.square, square_unit=board.unit, **shared)
    return dict(pattern=board.pattern_size, square=board.square_size, square_unit=board.unit, board=args.board, **shared)


def _run(build, run_fn, wrote: str) -> int:
    """Build the config, run it, print the report; errors reach :func:`aicalib_tf.cli.run_main`."""
    cfg = build()
    result, report = run_fn(cfg)
    print(report)
    if getattr(result, "quality", {}).get("status") == "failed":
        print(f"wrote {Path(cfg.out)}: rig.json marked failed, each camera's own calibration", file=sys.stderr)
        return 1
    print(f"wrote {Path(cfg.out)}: {wrote}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
