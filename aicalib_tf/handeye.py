"""Hand-eye calibration: where a robot's camera sits, from the robot's poses and the camera's board views.

    python -m aicalib_tf.handeye "images/*.png" --poses poses.csv --pattern 9x6 --square 25mm
        --setup eye-in-hand|eye-to-hand --out DIR [--intrinsics camera.json] [--model plumb_bob|auto|...]
        [--robot-sigma 0.01deg,0.05mm] [--board charuco:...] [--detector cnn|opencv|...] [--save-partial]

eye-in-hand: the camera rides on the flange and sees a board fixed in the cell; the result is
T_flange_camera (and T_base_board). eye-to-hand: the camera is fixed and the flange holds the board;
the result is T_base_camera (and T_flange_board). Frames as ROS names them, metres.

--poses holds one row per image: the flange (tool) frame in the robot's base frame, T_base_flange,
in metres with a unit quaternion (Hamilton, x y z w, as ROS):

    image,x,y,z,qx,qy,qz,qw
    img00.png,0.512,0.031,0.402,0.0,0.7071068,0.0,0.7071068

The same data may come as JSON or YAML (.json, .yaml: a list of {image, x, y, z, qx, qy, qz, qw}
or {image, matrix: 4x4}). Rows are matched to images by file name; unmatched rows and images are
listed. A quaternion whose norm is within 1e-3 of 1 is normalised with a warning.

Without --intrinsics the camera is calibrated from the same images first (--model: plumb_bob by
default, any of calibrate's models, or auto) and its intrinsics are refined in the hand-eye fit; with --intrinsics camera.json
(calibrate's file) they are held. Then: each view's board pose; a closed-form start robust to
robot rows that belong to other images (those are named and left out); one least-squares fit of
the board corners over the hand-eye transform, the board's pose, the robot's poses (each with
--robot-sigma per axis, not exact) and the intrinsics; a finer test of each robot pose against the
one its image implies. A chessboard may be read turned by 180° in some views; the robot decides.

It prints a report (views used and rejected with reasons, the transforms with ±1σ, the robot
residuals, the rotations' spread, two halves' agreement, the verdict and warnings naming what to
add) and writes into --out, atomically: handeye.json (the transforms, 6x6 covariances, views used
and rejected, residuals in px and in mm/deg against the robot, the verdict), handeye.yaml (OpenCV
FileStorage), static_transform.txt (``parent child x y z qx qy qz qw`` and the ROS 2
static_transform_publisher command) and report.png.

Exit codes: 0 done; 2 bad input (no images, a bad poses file: missing columns, NaN, a quaternion
that is not unit, translations over 10 m (millimetres?); fewer than 3 usable views; rotations all
about one axis). A failed fit writes nothing unless --save-partial (handeye.json marked failed).
"""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path

from aicalib_tf.cnn.spec import DETECTOR_NETWORK, NETWORK_HELP

__all__ = ["build_parser", "main", "parse_robot_sigma"]


def parse_robot_sigma(text: str) -> tuple[float, float]:
    """``"0.01deg,0.05mm"`` -> (0.01 degrees, 0.05 mm). Units: deg or rad; mm, cm, m or um."""
    m = re.fullmatch(r"\s*([0-9.eE+-]+)\s*(deg|rad)?\s*,\s*([0-9.eE+-]+)\s*(mm|cm|m|um)?\s*", str(text))
    if not m:
        raise ValueError(f"--robot-sigma must be ROTATION,TRANSLATION such as 0.01deg,0.05mm, got {text!r}")
    try:
        rot, tr = float(m.group(1)), float(m.group(3))
    except ValueError:
        raise ValueError(f"--robot-sigma must be ROTATION,TRANSLATION such as 0.01deg,0.05mm, got {text!r}") from None
    rot *= 57.29577951308232 if m.group(2) == "rad" else 1.0
    tr *= {"cm": 10.0, "m": 1000.0, "um": 1e-3}.get(m.group(4) or "mm", 1.0)
    if not (rot > 0 and tr > 0):
        raise ValueError(f"--robot-sigma must be positive, got {text!r}")
    if not (rot < 90 and tr < 1000):  # a robot reporting its pose worse than this has no pose to report
        raise ValueError(f"--robot-sigma must be under 90deg,1m (a robot's pose noise), got {text!r}")
    return rot, tr


def build_parser():
    """The command line's parser (docs/cli.md is generated from it)."""
    from aicalib_tf.calib.handeye.calibrate import SETUPS
    from aicalib_tf.calib.workflow import DETECTORS
    from aicalib_tf.cli import parser
    from aicalib_tf.geometry.lens import MODELS

    ap = parser("python -m aicalib_tf.handeye", __doc__)
    ap.add_argument("images", nargs="+", help="image files or glob patterns (quote globs)")
    ap.add_argument("--poses", required=True, help="robot poses T_base_flange: CSV image,x,y,z,qx,qy,qz,qw (m), "
                                                   "or .json/.yaml lists")
    ap.add_argument("--setup", required=True, choices=SETUPS, help="camera on the flange, or fixed in the cell")
    ap.add_argument("--pattern", help="inner corners, COLSxROWS, e.g. 9x6 (or --board)")
    ap.add_argument("--board", help="a ChArUco board instead of --pattern and --square: "
                                    "charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100[,legacy][,first=0]; "
                                    "an AprilGrid: aprilgrid:6x6,tag=88mm,spacing=0.3; or a Kalibr target.yaml")
    ap.add_argument("--square", default=None, help="square size with unit, e.g. 25mm")
    ap.add_argument("--out", default="handeye", help="output folder (default: %(default)s)")
    ap.add_argument("--intrinsics", help="camera.json (or camera.yaml) of calibrate: hold these intrinsics")
    ap.add_argument("--model", default="plumb_bob",
                    help=f"lens model without --intrinsics: one of {', '.join(MODELS)}, or auto (each model fitted and "
                         "cross-validated, as calibrate does: slower) (default: %(default)s)")
    ap.add_argument("--robot-sigma", default="0.01deg,0.05mm",
                    help="the robot's reported pose noise per axis, ROTATION,TRANSLATION (default: %(default)s)")
    ap.add_argument("--detector", default="cnn", choices=DETECTORS, help="corner detector (default: %(default)s)")
    ap.add_argument("--network", default=DETECTOR_NETWORK, help=NETWORK_HELP)
    ap.add_argument("--workers", type=int, default=None, help="detection processes (default: one per core)")
    ap.add_argument("--save-partial", action="store_true", help="a failed fit still writes handeye.json, marked failed")
    ap.add_argument("--seed", type=int, default=0, help="the robust start's random draws (default: %(default)s)")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    return ap


def _config(args):
    from aicalib_tf.calib.handeye.workflow import HandEyeConfig
    from aicalib_tf.calib.workflow import parse_square
    from aicalib_tf.geometry.lens import MODELS
    from aicalib_tf.geometry.pattern import check_pattern, parse_pattern

    if args.model != "auto" and args.model not in MODELS:
        raise ValueError(f"unknown --model {args.model!r}; choose auto or one of {', '.join(MODELS)}")
    rot, tr = parse_robot_sigma(args.robot_sigma)
    common = dict(images=tuple(args.images), poses=args.poses, setup=args.setup, out=args.out,
                  intrinsics=args.intrinsics, model=args.model, detector=args.detector, network=args.network,
                  sigma_rot_deg=rot, sigma_t_mm=tr, save_partial=args.save_partial, quiet=args.quiet,
                  workers=args.workers, seed=args.seed)
    if args.board:
        from aicalib_tf.geometry.aprilgrid import AprilGrid, Checkerboard
        from aicalib_tf.geometry.boards import read_board

        board = read_board(args.board, circles_refused="handeye")
        if isinstance(board, Checkerboard):  # a Kalibr checkerboard target: a chessboard
            return HandEyeConfig(pattern=board.pattern_size, square=board.square, square_unit=board.unit, **common)
        square = board.square_size if isinstance(board, AprilGrid) else board.square
        return HandEyeConfig(pattern=board.pattern_size, square=square, square_unit=board.unit, board=args.board,
                             **common)
    if not args.pattern or not args.square:
        raise ValueError("give --pattern COLSxROWS and --square SIZE (e.g. 25mm), or --board charuco:...")
    square, unit = parse_square(args.square)
    return HandEyeConfig(pattern=check_pattern(parse_pattern(args.pattern)), square=square, square_unit=unit, **common)


def _main(args) -> int:
    from aicalib_tf.calib.handeye.workflow import run_handeye

    cfg = _config(args)
    result, report = run_handeye(cfg)
    print(report)
    print(f"wrote {Path(cfg.out)}: handeye.json, handeye.yaml, static_transform.txt, report.png, report.txt")
    return 0


def main(argv: list[str] | None = None) -> int:
    """CLI entry: 0 on success, 2 on bad input (one line on stderr, no files written)."""
    from aicalib_tf.cli import run_main

    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    args = build_parser().parse_args(argv)
    return run_main(lambda: _main(args), debug=args.debug)


if __name__ == "__main__":
    sys.exit(main())
