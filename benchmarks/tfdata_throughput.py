"""Training input at scale: TFRecord shards through tf.data against rendering in the training process.

    python benchmarks/tfdata_throughput.py [--count N] [--shards S] [--batches B] [--workers K]

Reports, for the ``train`` preset at 640x480 on this machine:
* the time to write N images as S TFRecord shards (``data_gen --format tfrecord``), and to render
  the same N images into memory as ``train`` does without ``--data`` (its pool);
* input throughput in training crops (128x128 + target map) per second: tf.data from the shards
  (parallel, and with ``--deterministic``), and the in-process path (crops cut from a rendered
  pool by ``CornerMapBatches``; its rendering cost is the first item). Nothing is trained.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")


def write_shards_s(out: Path, count: int, shards: int, workers: int) -> float:
    from data_gen.dataset import DatasetConfig
    from data_gen.shards import ShardConfig, write_shards

    t = time.perf_counter()
    write_shards(ShardConfig(DatasetConfig(out=out, count=count, preset="train", seed=0, workers=workers), shards),
                 progress=False)
    return time.perf_counter() - t


def render_pool_s(count: int, workers: int):
    from aicalib_tf.cnn.training_data import render_pool

    t = time.perf_counter()
    pool = render_pool(count, 0, preset="train", workers=workers, progress=False)
    return time.perf_counter() - t, pool


def tfdata_rate(files: list[str], batches: int, batch: int, deterministic: bool) -> float:
    from aicalib_tf.cnn.tfrecord_data import corner_dataset

    ds = corner_dataset(files, per_replica_batch=batch, steps=batches + 2, seed=0, first_epoch=0, epochs=1,
                        deterministic=deterministic)
    it = iter(ds)
    next(it), next(it)  # warm up: graph, first files, numpy crop path
    t = time.perf_counter()
    for _ in range(batches):
        next(it)
    return batches * batch / (time.perf_counter() - t)


def pool_rate(pool, batches: int, batch: int) -> float:
    from aicalib_tf.cnn.training_data import CornerMapBatches

    data = CornerMapBatches(pool, batch_size=batch, steps=batches + 1, seed=0)
    data[0]
    t = time.perf_counter()
    for i in range(1, batches + 1):
        data[i]
    return batches * batch / (time.perf_counter() - t)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--count", type=int, default=200, help="images (default: %(default)s)")
    ap.add_argument("--shards", type=int, default=4, help="(default: %(default)s)")
    ap.add_argument("--batches", type=int, default=50, help="batches timed per input path (default: %(default)s)")
    ap.add_argument("--batch-size", type=int, default=32, help="(default: %(default)s)")
    ap.add_argument("--workers", type=int, default=2, help="rendering processes (default: %(default)s)")
    a = ap.parse_args(argv)
    import glob

    print(f"cores: {os.cpu_count()}; {a.count} images of preset train at 640x480, {a.workers} rendering workers")
    with tempfile.TemporaryDirectory() as tmp:
        shards_s = write_shards_s(Path(tmp) / "shards", a.count, a.shards, a.workers)
        size_mb = sum(p.stat().st_size for p in (Path(tmp) / "shards").glob("*.tfrecord")) / 2**20
        pool_s, pool = render_pool_s(a.count, a.workers)
        print(f"write {a.shards} shards ({size_mb:.1f} MB): {shards_s:7.1f} s  ({a.count / shards_s:5.1f} img/s)")
        print(f"render the pool in memory:  {pool_s:7.1f} s  ({a.count / pool_s:5.1f} img/s)")
        files = sorted(glob.glob(str(Path(tmp) / "shards" / "*.tfrecord")))
        fast = tfdata_rate(files, a.batches, a.batch_size, deterministic=False)
        det = tfdata_rate(files, a.batches, a.batch_size, deterministic=True)
        mem = pool_rate(pool, a.batches, a.batch_size)
        print(f"crops/s, tf.data from shards:                  {fast:8.0f}")
        print(f"crops/s, tf.data from shards, --deterministic: {det:8.0f}")
        print(f"crops/s, in-process pool (after rendering):    {mem:8.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
