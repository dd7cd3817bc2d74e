"""Detect chessboards in images: ``python -m aicalib_tf.detect IMAGES... --pattern 9x6 --out DIR``.

For each image it writes ``<stem>.png`` (the corners drawn over the image) and ``<stem>.json``
(corners (x, y) px, their (col, row) ids, scores, whether the board is complete, and why not),
atomically, and ends with the counts: full boards, partial boards, no board (with the reasons)
and unreadable files. ``--workers N`` (default: one per core, one per 8 images at most) detects and writes N images at a time
in worker processes that each load the model once (:mod:`aicalib_tf.detect.batch`); the files
and counts are the same as with ``--workers 1``, which runs in this process. An unreadable file
is counted and named at the end; the batch goes on. ``--board charuco:...`` finds a ChArUco board
instead (its corners named by its markers, :mod:`aicalib_tf.detect.charuco.detector`); ``--board aprilgrid:6x6,tag=88mm,spacing=0.3``
or a Kalibr target.yaml finds Kalibr's AprilGrid (tags decoded by OpenCV's aruco, corners by the
saddle fit, ids on the grid's lattice, :mod:`aicalib_tf.detect.boards.aprilgrid`). Exit codes: 0 done; 2 bad arguments or model.
"""

from __future__ import annotations

import sys
from collections import Counter

from aicalib_tf.cnn.spec import DETECTOR_NETWORK, NETWORK_HELP


def build_parser():
    """The command line's parser (docs/cli.md is generated from it)."""
    from aicalib_tf.cli import parser

    ap = parser("python -m aicalib_tf.detect", __doc__)
    ap.add_argument("images", nargs="+", help="image files or glob patterns (** recurses; each file once)")
    ap.add_argument("--pattern", help="inner corners, COLSxROWS, e.g. 9x6 (or --board)")
    ap.add_argument("--board", help="a ChArUco board instead of --pattern: charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100; "
                                    "an AprilGrid: aprilgrid:6x6,tag=88mm,spacing=0.3; or a Kalibr target.yaml")
    ap.add_argument("--out", required=True, help="folder for <image>.png overlays and <image>.json corners")
    ap.add_argument("--model", default=DETECTOR_NETWORK, help=NETWORK_HELP)
    ap.add_argument("--workers", type=int, default=None, help="worker processes (default: one per core, but one per 8 images at most)")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    return ap


def _parse_args(argv):
    return build_parser().parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Detect boards in images and write overlays and corner files; exit 2 on bad arguments."""
    import os

    from aicalib_tf.cli import run_main

    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    args = _parse_args(argv)
    return run_main(lambda: _main(args), debug=args.debug)


def _main(args) -> int:
    from aicalib_tf.cnn.model import file_sha256, load_model
    from aicalib_tf.detect.batch import worker_count
    from aicalib_tf.geometry.pattern import check_pattern, parse_pattern
    from aicalib_tf.io import expand_images
    from aicalib_tf.outfolder import OutputFolder

    if args.board:  # detect_corners dispatches on a ChArUco board, the file detector on an AprilGrid
        from aicalib_tf.geometry.aprilgrid import Checkerboard
        from aicalib_tf.geometry.boards import read_board

        pattern = read_board(args.board, circles_refused="detect")  # circle centres are placed with the lens
        pattern = pattern.pattern_size if isinstance(pattern, Checkerboard) else pattern  # a Kalibr checkerboard
    elif args.pattern:
        pattern = check_pattern(parse_pattern(args.pattern))
    else:
        raise ValueError("give --pattern COLSxROWS (a chessboard) or --board charuco:... (a ChArUco board)")
    files = expand_images(args.images)
    if not files:
        raise ValueError(f"no images match {' '.join(args.images)}")
    model = load_model(args.model)
    workers = worker_count(args.workers, len(files))
    sha = file_sha256(model.aicalib_path) if hasattr(model, "aicalib_path") else None
    del model  # each worker (or the one process) loads its own
    with OutputFolder(args.out, "detections") as folder:  # a bad --out fails here; swapped in at the end
        counts, reasons, failures = _detect_into(folder.path, files, pattern, sha, workers, args)
    print(f"{len(files)} images: {counts['complete']} full boards, {counts['partial']} partial (seen corners, ids fixed by the image), "
          f"{counts['none']} without a board, {counts['failed']} unreadable")
    for reason, n in reasons.most_common():
        print(f"  no board in {n}: {reason}")
    for msg in failures:
        print(f"  skipped: {msg}")
    return 0


def _detect_into(out, files, pattern, sha, workers, args):
    """Detect every file, writing its overlay and corners into ``out``; returns (counts, reasons, failures)."""
    from tqdm import tqdm

    from aicalib_tf.detect.batch import map_images
    from aicalib_tf.detect.outputs import file_detector, output_stems

    counts = {"complete": 0, "partial": 0, "none": 0, "failed": 0}
    reasons: Counter[str] = Counter()
    failures = []
    items = list(zip(files, output_stems(files)))
    results = map_images(items, file_detector, (pattern, str(args.model), out, sha), workers=workers)
    for kind, why in tqdm(results, total=len(items), desc="detect", unit="img", disable=args.quiet):
        counts[kind] += 1
        if kind == "failed":
            failures.append(why)
        elif kind == "none":
            reasons[why] += 1
    return counts, reasons, failures


if __name__ == "__main__":
    sys.exit(main())
