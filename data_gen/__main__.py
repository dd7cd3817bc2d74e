"""Render synthetic chessboards with exact ground truth.

Usage:
  python -m data_gen --out DIR --count N --preset NAME --seed S [--size WxH] [--pattern CxR] [--workers K]
      [--board charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100]

Writes DIR/index.csv, DIR/images/*.png, DIR/labels/*.json and DIR/meta.json (format in
DESIGN.md). The same arguments give byte-identical files whatever --workers is. --board renders a
ChArUco board instead of the preset's chessboards (labels then hold the markers' ids and corners).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from aicalib_tf.geometry.pattern import check_pattern, parse_pattern

from .dataset import DatasetConfig, check_output_dir, write_dataset
from .presets import PRESETS

__all__ = ["main", "parse_args"]


def _parse_size(text: str) -> tuple[int, int]:
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(p.isdigit() for p in parts):
        raise ValueError(f"--size must look like WIDTHxHEIGHT, e.g. 640x480, got {text!r}")
    w, h = int(parts[0]), int(parts[1])
    if not (32 <= w <= 8000 and 32 <= h <= 8000):
        raise ValueError(f"--size must be between 32x32 and 8000x8000, got {w}x{h}")
    return w, h


def parse_args(argv=None) -> tuple[DatasetConfig, bool]:
    """Parse and validate the command line; raises ``ValueError`` with a one-line message."""
    ap = argparse.ArgumentParser(prog="python -m data_gen", description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, type=Path, help="output folder (must not exist or be empty)")
    ap.add_argument("--count", required=True, type=int, help="number of images")
    ap.add_argument("--preset", required=True, help=f"one of: {', '.join(PRESETS)}")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--size", help="WIDTHxHEIGHT (default: the preset's sizes)")
    ap.add_argument("--pattern", help="COLSxROWS inner corners (default: the preset's)")
    ap.add_argument("--workers", type=int, default=1, help="processes (output does not depend on it)")
    ap.add_argument("--board", help="a ChArUco board instead of chessboards: charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100")
    ap.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    a = ap.parse_args(argv)
    if a.count < 1:
        raise ValueError(f"--count must be >= 1, got {a.count}")
    if a.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {a.seed}")
    if a.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {a.workers}")
    if a.preset not in PRESETS:
        raise ValueError(f"unknown --preset {a.preset!r}; choose from: {', '.join(PRESETS)}")
    size = _parse_size(a.size) if a.size else None
    pattern = check_pattern(parse_pattern(a.pattern)) if a.pattern else None
    if a.board:
        from aicalib_tf.geometry.charuco import parse_board

        parse_board(a.board)  # a bad description is a bad argument
    check_output_dir(a.out)
    cfg = DatasetConfig(out=a.out, count=a.count, preset=a.preset, seed=a.seed, size=size, pattern=pattern, workers=a.workers,
                        board=a.board)
    return cfg, not a.no_progress


def main(argv=None) -> int:
    """CLI entry (see the module docstring); returns the process exit code (2 on bad arguments)."""
    try:
        cfg, progress = parse_args(argv)
    except ValueError as exc:
        print(f"data_gen: error: {exc}", file=sys.stderr)
        return 2
    try:
        out = write_dataset(cfg, progress=progress)
    except (ValueError, RuntimeError, OSError) as exc:
        print(f"data_gen: error: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {cfg.count} images ({cfg.preset}, seed {cfg.seed}) to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
