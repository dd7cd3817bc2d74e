"""Render synthetic chessboards with exact ground truth.

Usage:
  python -m data_gen --out DIR --count N --preset NAME --seed S [--size WxH] [--pattern CxR] [--workers K]
      [--board charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100 | aprilgrid:6x6,tag=88mm,spacing=0.3]
  python -m data_gen --format tfrecord --shards N [--shard i/N] --out DIR --count N --preset NAME ...

Writes DIR/index.csv, DIR/images/*.png, DIR/labels/*.json and DIR/meta.json (format in
DESIGN.md). The same arguments give byte-identical files whatever --workers is. --board renders a
ChArUco board instead of the preset's chessboards (labels then hold the markers' ids and corners), or
a Kalibr AprilGrid (its description or target YAML: labels hold every tag corner, its lattice ``ids``,
and the ``tags``' ids and corners).

With --format tfrecord it writes DIR/data-IIIII-of-NNNNN.tfrecord files (tf.train.Example: the
raw pixels, grey statistics, visible corners and label) and DIR/meta.json with the schema, for
``python -m aicalib_tf.train --data 'DIR/*.tfrecord'``. --shard i/N renders only shard i (one
job per machine, say): it is byte for byte shard i of a full run. Shards hold a few hundred MB at most.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from aicalib_tf.geometry.pattern import check_pattern, parse_pattern

from .dataset import MAX_COUNT, DatasetConfig, check_count, check_output_dir, check_pixels, write_dataset
from .presets import PRESETS
from .shards import ShardConfig, check_shards, with_default_shards, write_shards
from .targets import HELP as BOARD_HELP
from .targets import parse_marker_board

__all__ = ["main", "parse_args"]


def _parse_size(text: str) -> tuple[int, int]:
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(p.isdigit() for p in parts):
        raise ValueError(f"--size must look like WIDTHxHEIGHT, e.g. 640x480, got {text!r}")
    w, h = int(parts[0]), int(parts[1])
    if not (32 <= w <= 8000 and 32 <= h <= 8000):
        raise ValueError(f"--size must be between 32x32 and 8000x8000, got {w}x{h}")
    check_pixels(w, h)
    return w, h


def _parse_shard(text: str) -> tuple[int, int]:
    i, sep, n = text.partition("/")
    if not (sep and i.isdigit() and n.isdigit()):
        raise ValueError(f"--shard must look like i/N, e.g. 3/16, got {text!r}")
    return int(i), int(n)


def build_parser() -> argparse.ArgumentParser:
    """The command line's parser (docs/cli.md is generated from it)."""
    ap = argparse.ArgumentParser(prog="python -m data_gen", description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, type=Path, help="output folder (must not exist or be empty)")
    ap.add_argument("--count", required=True, type=int, help="number of images")
    ap.add_argument("--preset", required=True, help=f"one of: {', '.join(PRESETS)}")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--size", help="WIDTHxHEIGHT, at most 12,000,000 pixels (default: the preset's sizes)")
    ap.add_argument("--pattern", help="COLSxROWS inner corners (default: the preset's)")
    ap.add_argument("--workers", type=int, default=1, help="processes (output does not depend on it)")
    ap.add_argument("--board", help=BOARD_HELP)
    ap.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    ap.add_argument("--format", choices=("folder", "tfrecord"), default="folder", help="(default: %(default)s)")
    ap.add_argument("--shards", type=int, help="tfrecord: number of files (default: files of about 200 MB)")
    ap.add_argument("--shard", help="tfrecord: render only shard i of N, given as i/N")
    return ap


def parse_args(argv=None) -> tuple[DatasetConfig | ShardConfig, bool]:
    """Parse and validate the command line; raises ``ValueError`` with a one-line message."""
    a = build_parser().parse_args(argv)
    if a.format == "folder":
        if a.shards is not None or a.shard is not None:
            raise ValueError("--shards and --shard need --format tfrecord")
        check_count(a.count, MAX_COUNT, "; use --format tfrecord for larger sets")
    if a.seed < 0:
        raise ValueError(f"--seed must be >= 0, got {a.seed}")
    if a.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {a.workers}")
    if a.preset not in PRESETS:
        raise ValueError(f"unknown --preset {a.preset!r}; choose from: {', '.join(PRESETS)}")
    size = _parse_size(a.size) if a.size else None
    pattern = check_pattern(parse_pattern(a.pattern)) if a.pattern else None
    if a.board:
        parse_marker_board(a.board)  # a bad description is a bad argument
        if a.format == "tfrecord":
            raise ValueError("--board renders image folders only; --format tfrecord writes chessboard presets")
    cfg = DatasetConfig(out=a.out, count=a.count, preset=a.preset, seed=a.seed, size=size, pattern=pattern, workers=a.workers,
                        board=a.board)
    if a.format == "tfrecord":
        only = None
        if a.shard is not None:
            only, n = _parse_shard(a.shard)
            if a.shards is not None and a.shards != n:
                raise ValueError(f"--shard {a.shard} disagrees with --shards {a.shards}")
            a.shards = n
        scfg = with_default_shards(cfg, a.shards, only)
        check_shards(scfg)
        return scfg, not a.no_progress
    check_output_dir(a.out)
    return cfg, not a.no_progress


def main(argv=None) -> int:
    """CLI entry (see the module docstring); returns the process exit code (2 on bad arguments)."""
    try:
        cfg, progress = parse_args(argv)
    except ValueError as exc:
        print(f"data_gen: error: {exc}", file=sys.stderr)
        return 2
    try:
        if isinstance(cfg, ShardConfig):
            paths = write_shards(cfg, progress=progress)
            d = cfg.data
            print(f"wrote {len(paths)} of {cfg.shards} shards ({d.count} images in all, {d.preset}, seed {d.seed}) to {d.out}")
            return 0
        out = write_dataset(cfg, progress=progress)
    except ValueError as exc:
        print(f"data_gen: error: {exc}", file=sys.stderr)
        return 2
    except (RuntimeError, OSError) as exc:
        print(f"data_gen: error: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {cfg.count} images ({cfg.preset}, seed {cfg.seed}) to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
