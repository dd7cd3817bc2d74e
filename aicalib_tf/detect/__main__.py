"""Detect chessboards in images: ``python -m aicalib_tf.detect IMAGES... --pattern 9x6 --out DIR``.

For each image it writes ``<stem>.png`` (the corners drawn over the image) and ``<stem>.json``
(corners (x, y) px, their (col, row) ids, scores, whether the board is complete, and why not),
atomically, and ends with the counts: full boards, partial boards, no board (with the reasons)
and unreadable files. Exit codes: 0 done; 2 bad arguments or model.
"""

from __future__ import annotations

import sys
from collections import Counter

import cv2

from aicalib_tf.detect.draw import draw_detection
from aicalib_tf.detect.pipeline import detect_corners
from aicalib_tf.io import load_image


def _parse_args(argv):
    import argparse

    ap = argparse.ArgumentParser(prog="python -m aicalib_tf.detect", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("images", nargs="+", help="image files or glob patterns (** recurses; each file once)")
    ap.add_argument("--pattern", required=True, help="inner corners, COLSxROWS, e.g. 9x6")
    ap.add_argument("--out", required=True, help="folder for <image>.png overlays and <image>.json corners")
    ap.add_argument("--model", default="default", help="default, default_int8 (int8, about 2x faster), report, or a .tflite/.keras path (default: %(default)s)")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    return ap.parse_args(argv)


def _write_one(out, f, gray, det, pattern, used: set, *, model: str, sha) -> None:
    """Write ``<stem>.png`` (the overlay) and ``<stem>.json`` (the corners) of one image, atomically."""
    import json
    from pathlib import Path

    from aicalib_tf.io import atomic_write_bytes, atomic_write_text

    stem = Path(f).stem
    if stem in used:  # a/x.jpg and b/x.png must not overwrite each other
        stem = f"{stem}-{len(used)}"
    used.add(stem)
    ok, png = cv2.imencode(".png", draw_detection(gray, det))
    atomic_write_bytes(out / f"{stem}.png", png.tobytes())
    record = {
        "file": str(f), "image_size": list(det.image_size), "pattern_size": list(pattern),
        "found": det.found, "complete": det.complete, "reason": det.reason, "corners": det.corners.tolist(),
        "ids": det.ids.tolist(), "scores": det.scores.tolist(), "model": model, "model_sha256": sha,
    }
    atomic_write_text(out / f"{stem}.json", json.dumps(record, indent=1) + "\n")


def main(argv: list[str] | None = None) -> int:
    """Detect boards in images and write overlays and corner files; exit 2 on bad arguments."""
    import os

    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    import sys
    from pathlib import Path

    from tqdm import tqdm

    from aicalib_tf.cnn.model import file_sha256, load_model
    from aicalib_tf.geometry.pattern import parse_pattern
    from aicalib_tf.io import (
        ImageError,
        expand_images,
    )

    args = _parse_args(argv)
    try:
        pattern = parse_pattern(args.pattern)
        files = expand_images(args.images)
        if not files:
            raise ValueError(f"no images match {' '.join(args.images)}")
        model = load_model(args.model)
    except (ValueError, FileNotFoundError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sha = file_sha256(model.aicalib_path) if hasattr(model, "aicalib_path") else None
    counts = {"complete": 0, "partial": 0, "none": 0, "failed": 0}
    reasons: Counter[str] = Counter()
    failures = []
    used: set[str] = set()
    for f in tqdm(files, desc="detect", unit="img", disable=args.quiet):
        try:
            gray = load_image(f)
            det = detect_corners(gray, pattern, model=model)
        except ImageError as exc:
            counts["failed"] += 1
            failures.append(str(exc))
            continue
        counts["complete" if det.complete else "partial" if det.found else "none"] += 1
        if not det.found:
            reasons[det.reason] += 1
        _write_one(out, f, gray, det, pattern, used, model=str(args.model), sha=sha)
    print(f"{len(files)} images: {counts['complete']} full boards, {counts['partial']} partial (seen corners, ids fixed by the image), "
          f"{counts['none']} without a board, {counts['failed']} unreadable")
    for reason, n in reasons.most_common():
        print(f"  no board in {n}: {reason}")
    for msg in failures:
        print(f"  skipped: {msg}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
