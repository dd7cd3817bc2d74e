"""Write a dataset to disk in the format of ``../shared/DESIGN.md``.

Layout::

    DIR/index.csv          file, label, condition, camera_id, seed, index, width, height
    DIR/images/NNNNNN.png  8-bit grey
    DIR/labels/NNNNNN.json
    DIR/meta.json          generator version and full config

The whole dataset is built in a temporary sibling folder and renamed into place at the end, so
an interrupted run never leaves a half-written DIR. Output bytes depend only on the arguments,
never on ``workers``. Jobs are streamed (a window of a few per worker in flight, index rows written
as they come), so memory does not grow with ``count``; ``count`` is bounded by ``MAX_COUNT``.
"""

from __future__ import annotations

import csv
import itertools
import multiprocessing as mp
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Iterator

import cv2
from tqdm import tqdm

from aicalib_tf.jsonio import dumps

from .presets import get_preset
from .sample import GENERATOR_VERSION, make_sample

__all__ = ["DatasetConfig", "write_dataset", "check_output_dir", "check_count", "iter_samples", "imap_ordered", "MAX_COUNT", "MAX_PIXELS", "check_pixels"]

MAX_COUNT = 1_000_000  # images in one folder dataset (6-digit names); --format tfrecord allows more
MAX_PIXELS = 12_000_000  # px of one rendered image: 12 MP renders at about 1.1 GB peak (memory grows with the pixels)
INDEX_COLUMNS = ("file", "label", "condition", "camera_id", "seed", "index", "width", "height")


@dataclass(frozen=True)
class DatasetConfig:
    """Arguments of ``python -m data_gen``."""

    out: Path
    count: int
    preset: str
    seed: int = 0
    size: tuple[int, int] | None = None
    pattern: tuple[int, int] | None = None
    workers: int = 1
    board: str | None = None  # a ChArUco board or an AprilGrid (data_gen.targets) replacing the preset's chessboards

    def recipe(self):
        """The preset, with the board replaced when ``board`` is given."""
        return get_preset(self.preset, board=self.board) if self.board else get_preset(self.preset)

    def to_meta(self) -> dict:
        return {
            "generator": "data_gen",
            "version": GENERATOR_VERSION,
            "preset": self.preset,
            "count": self.count,
            "seed": self.seed,
            "size": list(self.size) if self.size else None,
            "pattern": list(self.pattern) if self.pattern else None,
            "preset_config": self.recipe().to_dict(),
        }


def check_count(count: int, limit: int = MAX_COUNT, hint: str = "") -> None:
    """Raise ``ValueError`` unless 1 <= ``count`` <= ``limit``."""
    if count < 1:
        raise ValueError(f"--count must be >= 1, got {count}")
    if count > limit:
        raise ValueError(f"--count must be at most {limit}, got {count}{hint}")


def check_pixels(width: int, height: int, limit: int = MAX_PIXELS) -> None:
    """Raise ``ValueError`` when a width×height image has more than ``limit`` pixels (its render would not fit in
    bounded memory); the message says how to get a larger frame."""
    if int(width) * int(height) > limit:
        raise ValueError(f"--size {width}x{height} has {int(width) * int(height):,} pixels; data_gen renders at most "
                         f"{limit:,} (e.g. 4000x3000) in bounded memory; resize a render for larger frames")


def imap_ordered(fn: Callable, jobs: Iterable, workers: int = 1, window: int = 16) -> Iterator:
    """``fn(job)`` for each job, in order, over ``workers`` spawned processes (or in this one).

    Jobs are read from the iterable lazily: at most ``window`` per worker are in flight, so a huge
    (or endless) stream of jobs runs in constant memory. Results never depend on ``workers``.
    """
    jobs = iter(jobs)
    if workers <= 1:
        yield from map(fn, jobs)
        return
    chunk = max(1, window // 4)
    with mp.get_context("spawn").Pool(workers) as pool:
        while True:
            batch = list(itertools.islice(jobs, window * workers))
            if not batch:
                return
            yield from pool.imap(fn, batch, chunksize=chunk)


def check_output_dir(out: Path) -> None:
    """Raise ``ValueError`` unless ``out`` can be created (or is an empty folder) and is writable."""
    out = Path(out)
    if out.exists():
        if not out.is_dir():
            raise ValueError(f"--out {out}: exists and is not a folder")
        if any(out.iterdir()):
            raise ValueError(f"--out {out}: folder is not empty; choose a new folder")
    parent = out.parent if str(out.parent) else Path(".")
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"--out {out}: cannot write in {parent}")


def _json_bytes(obj) -> bytes:
    return (dumps(obj) + "\n").encode()  # strict JSON: a corner the lens does not image is null, never NaN


def _render_one(job: tuple) -> list:
    """Worker: render image ``index`` and write its PNG and JSON into the staging folder."""
    stage, _, seed, index, _, _ = job
    sample = _make_one(job[1:])
    name = f"{index:06d}"
    ok, png = cv2.imencode(".png", sample.image, [cv2.IMWRITE_PNG_COMPRESSION, 3])
    if not ok:
        raise RuntimeError(f"PNG encoding failed for image {index}")
    Path(stage, "images", name + ".png").write_bytes(png.tobytes())
    Path(stage, "labels", name + ".json").write_bytes(_json_bytes(sample.label))
    w, h = sample.label["image_size"]
    return [f"images/{name}.png", f"labels/{name}.json", sample.label["condition"], sample.label["camera_id"], seed, index, w, h]


def _make_one(job: tuple):
    preset, seed, index, size, pattern = job
    return make_sample(preset, seed, index, size=size, pattern=pattern)


def iter_samples(preset, seed: int, indices, *, size=None, pattern=None, workers: int = 1) -> Iterator:
    """Yield ``make_sample(preset, seed, i)`` for each i in ``indices``, in order.

    preset : a preset name or a ``Preset`` (overrides travel to the workers).
    workers : processes (spawned, so a parent holding TensorFlow is safe). Output never depends on it.
    """
    jobs = ((preset, seed, int(i), size, pattern) for i in indices)
    yield from imap_ordered(_make_one, jobs, workers if len(indices) > 1 else 1)


def write_dataset(cfg: DatasetConfig, *, progress: bool = True) -> Path:
    """Render ``cfg.count`` images into ``cfg.out``; returns the folder."""
    out = Path(cfg.out)
    check_count(cfg.count)
    check_output_dir(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    try:
        (stage / "images").mkdir()
        (stage / "labels").mkdir()
        preset = cfg.recipe() if cfg.board else cfg.preset  # a Preset travels to the workers as it is
        jobs = ((str(stage), preset, cfg.seed, i, cfg.size, cfg.pattern) for i in range(cfg.count))
        bar = tqdm(total=cfg.count, desc=f"data_gen {cfg.preset}", unit="img", disable=not progress)
        with open(stage / "index.csv", "w", newline="") as f:
            writer = csv.writer(f, lineterminator="\n")
            writer.writerow(INDEX_COLUMNS)
            for row in imap_ordered(_render_one, jobs, cfg.workers if cfg.count > 1 else 1):
                writer.writerow(row)
                bar.update()
        bar.close()
        (stage / "meta.json").write_bytes(_json_bytes(cfg.to_meta()))
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(stage, 0o777 & ~umask)  # mkdtemp makes it private; a dataset is a normal folder
        if out.exists():
            out.rmdir()  # checked empty above
        os.rename(stage, out)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    return out
