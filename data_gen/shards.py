"""A dataset as sharded TFRecord files (``python -m data_gen --format tfrecord``), for tf.data training.

Layout::

    DIR/data-00000-of-00016.tfrecord ... data-00015-of-00016.tfrecord
    DIR/meta.json          generator version, config, the shard list and the example schema

Shard ``i`` of ``N`` holds images ``[i·count // N, (i+1)·count // N)`` in index order. Every
image is seeded by its own index (see :mod:`data_gen.sample`), so a shard rendered alone
(``--shard i/N``, e.g. one job per machine) is byte for byte the shard of a full run, and
``meta.json`` is the same from every shard. Each shard is written to a temporary file and renamed
into place; a folder may be filled by many shard jobs at once, and a job run again rewrites the
same bytes.

An example (``tf.train.Example``, features in :data:`SCHEMA`) holds what training takes from an
image: its pixels (raw: PNG saves only ~20% on these noisy renders and decoding it cost 15 ms a
crop, 40× the crop itself), its grey statistics (crops are standardised with the whole image's),
the visible corners from which the corner-map target of each random crop is built, and the full label. The target map is not stored:
it depends on the crop, flip and scale drawn at training time (see ``aicalib_tf.cnn.training_data``).
"""

from __future__ import annotations

import itertools
import os
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Iterator

import numpy as np
from tqdm import tqdm

from .dataset import DatasetConfig, _json_bytes, _make_one, check_count, imap_ordered
from .presets import get_preset
from .tfrecord import encode_example, frame_record

__all__ = ["ShardConfig", "write_shards", "shard_name", "shard_range", "SCHEMA", "MAX_SHARD_BYTES", "MAX_TFRECORD_COUNT"]

SCHEMA = {
    "image": {"type": "bytes", "shape": [], "meaning": "raw 8-bit grey pixels, height x width, row-major"},
    "height": {"type": "int64", "shape": [1], "meaning": "image rows"},
    "width": {"type": "int64", "shape": [1], "meaning": "image columns"},
    "corners": {"type": "float32", "shape": ["2k"], "meaning": "visible corners (x, y) px, OpenCV order, flattened"},
    "mean": {"type": "float32", "shape": [1], "meaning": "mean grey level of the image (0..255)"},
    "std": {"type": "float32", "shape": [1], "meaning": "standard deviation of the grey levels"},
    "has_board": {"type": "int64", "shape": [1], "meaning": "1 if the image shows a board"},
    "index": {"type": "int64", "shape": [1], "meaning": "image index (its seed with the dataset seed)"},
    "label": {"type": "bytes", "shape": [], "meaning": "the label JSON of the folder format (DESIGN.md)"},
}
MAX_SHARD_BYTES = 512 * 2**20  # from the pixel count and a generous label size: a bound, not an estimate
TARGET_SHARD_BYTES = 200 * 2**20  # what the default --shards aims for
MAX_TFRECORD_COUNT = 100_000_000
_LABEL_BYTES = 16_384  # generous bound of one label JSON


@dataclass(frozen=True)
class ShardConfig:
    """A TFRecord dataset: the image arguments, ``shards`` files, and which of them this run writes.

    only : the shard this run renders (``--shard i/N``), or None for all of them.
    """

    data: DatasetConfig
    shards: int
    only: int | None = None

    def to_meta(self) -> dict:
        n = self.data.count
        return {
            **self.data.to_meta(),
            "format": "tfrecord",
            "shards": self.shards,
            "files": [shard_name(i, self.shards) for i in range(self.shards)],
            "examples": [len(shard_range(i, self.shards, n)) for i in range(self.shards)],
            "schema": SCHEMA,
        }


def shard_name(i: int, n: int) -> str:
    return f"data-{i:05d}-of-{n:05d}.tfrecord"


def shard_range(i: int, n: int, count: int) -> range:
    """The image indices of shard ``i`` of ``n``."""
    return range(i * count // n, (i + 1) * count // n)


def _bytes_per_example(cfg: DatasetConfig) -> int:
    sizes = [cfg.size] if cfg.size else list(get_preset(cfg.preset).sizes)
    return max(w * h for w, h in sizes) + _LABEL_BYTES


def default_shards(cfg: DatasetConfig) -> int:
    """The fewest shards of about 200 MB at most (from the raw pixel bound)."""
    return max(1, -(-cfg.count * _bytes_per_example(cfg) // TARGET_SHARD_BYTES))


def check_shards(cfg: ShardConfig) -> None:
    """Raise ``ValueError`` naming the bad option (count, shard count, shard index, shard size)."""
    n = cfg.data.count
    check_count(n, MAX_TFRECORD_COUNT, "; render larger sets as several datasets with different --seed")
    if not 1 <= cfg.shards <= n:
        raise ValueError(f"--shards must be between 1 and --count ({n}), got {cfg.shards}")
    if cfg.only is not None and not 0 <= cfg.only < cfg.shards:
        raise ValueError(f"--shard must be i/N with 0 <= i < N, got {cfg.only}/{cfg.shards}")
    biggest = -(-n // cfg.shards) * _bytes_per_example(cfg.data)
    if biggest > MAX_SHARD_BYTES:
        need = -(-n * _bytes_per_example(cfg.data) // MAX_SHARD_BYTES)
        raise ValueError(f"--shards {cfg.shards}: shards of up to {biggest / 2**20:.0f} MB (at most "
                         f"{MAX_SHARD_BYTES // 2**20} MB); use --shards {need} or more")


def check_shard_dir(out: Path, meta: bytes) -> None:
    """Raise ``ValueError`` unless ``out`` is new, empty, or holds shards of this very dataset."""
    out = Path(out)
    if not out.exists():
        return
    if not out.is_dir():
        raise ValueError(f"--out {out}: exists and is not a folder")
    names = [p.name for p in out.iterdir() if not p.name.startswith(".")]
    if not names:
        return
    if "meta.json" not in names or (out / "meta.json").read_bytes() != meta:
        raise ValueError(f"--out {out}: holds another dataset (its meta.json differs); choose a new folder")


def _example(job: tuple) -> bytes:
    """Worker: render one image and return its framed TFRecord."""
    sample = _make_one(job)
    img = np.ascontiguousarray(sample.image, np.uint8)
    lab = sample.label
    corners = sample.corners[sample.visible] if lab["has_board"] else np.zeros((0, 2))
    h, w = sample.image.shape
    return frame_record(encode_example({
        "image": img.tobytes(), "height": np.array([h]), "width": np.array([w]),
        "mean": np.array([img.mean()], np.float32), "std": np.array([img.std()], np.float32),
        "corners": corners.astype(np.float32).reshape(-1), "has_board": np.array([int(bool(lab["has_board"]))]),
        "index": np.array([job[2]]), "label": _json_bytes(lab),
    }))


def _records(cfg: DatasetConfig, indices, count: int) -> Iterator[bytes]:
    """The framed records of ``indices`` (``count`` of them), in order, over one pool of workers."""
    jobs = ((cfg.preset, cfg.seed, i, cfg.size, cfg.pattern) for i in indices)
    return imap_ordered(_example, jobs, cfg.workers if count > 1 else 1)


def _atomic_write(path: Path, chunks, mode: int = 0o644) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.partial-", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            for chunk in chunks:
                f.write(chunk)
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_shards(cfg: ShardConfig, *, progress: bool = True) -> list[Path]:
    """Render the shards ``cfg`` asks for into ``cfg.data.out`` (and meta.json); returns their paths."""
    check_shards(cfg)
    out = Path(cfg.data.out)
    meta = _json_bytes(cfg.to_meta())
    check_shard_dir(out, meta)
    out.mkdir(parents=True, exist_ok=True)
    _atomic_write(out / "meta.json", [meta])  # first: a folder that shard jobs are filling says what it is
    todo = range(cfg.shards) if cfg.only is None else [cfg.only]
    total = sum(len(shard_range(i, cfg.shards, cfg.data.count)) for i in todo)
    bar = tqdm(total=total, desc=f"data_gen {cfg.data.preset} tfrecord", unit="img", disable=not progress)
    ranges = [shard_range(i, cfg.shards, cfg.data.count) for i in todo]
    records = _records(cfg.data, itertools.chain.from_iterable(ranges), total)  # one stream: one pool for all shards

    def counted(n):
        for r in itertools.islice(records, n):
            bar.update()
            yield r

    paths = []
    for i, indices in zip(todo, ranges):
        path = out / shard_name(i, cfg.shards)
        _atomic_write(path, counted(len(indices)))
        paths.append(path)
    records.close()
    bar.close()
    return paths


def with_default_shards(cfg: DatasetConfig, shards: int | None, only: int | None) -> ShardConfig:
    """A :class:`ShardConfig`; ``shards=None`` picks :func:`default_shards`."""
    return ShardConfig(data=replace(cfg), shards=shards if shards is not None else default_shards(cfg), only=only)
