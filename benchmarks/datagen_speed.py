"""data_gen throughput: images per second, in memory and written to disk.

    python benchmarks/datagen_speed.py [--quick]

Reports, for the presets clean, hard and train at 640x480 and 1920x1080:
* in-memory samples/s on one process (what training on the fly gets per worker);
* a dataset written by `python -m data_gen` with 1 and 2 workers (PNG + JSON included).
Target: >= 20 images/s for `train` at 640x480 with 2 workers on a 2-core machine.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

from data_gen import make_sample
from data_gen.dataset import DatasetConfig, write_dataset


def in_memory_rate(preset: str, size: tuple[int, int], n: int) -> float:
    make_sample(preset, 999, 0, size=size)  # warm caches and imports
    t = time.perf_counter()
    for i in range(n):
        make_sample(preset, 0, i, size=size)
    return n / (time.perf_counter() - t)


def disk_rate(preset: str, size: tuple[int, int], n: int, workers: int) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        write_dataset(DatasetConfig(out=Path(tmp) / "ds", count=n, preset=preset, seed=0, size=size, workers=workers), progress=False)
        return n / (time.perf_counter() - t)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer images (noisier figures)")
    a = ap.parse_args(argv)
    n_small, n_big = (20, 4) if a.quick else (100, 20)
    print(f"cores: {os.cpu_count()}")
    print("preset  size        in-memory img/s (1 proc)  disk img/s (1 worker)  disk img/s (2 workers)")
    for preset in ("clean", "hard", "train"):
        for size, n in (((640, 480), n_small), ((1920, 1080), n_big)):
            mem = in_memory_rate(preset, size, n)
            d1 = disk_rate(preset, size, n, 1)
            d2 = disk_rate(preset, size, 2 * n, 2)
            print(f"{preset:6s}  {size[0]}x{size[1]:<5d}  {mem:24.1f}  {d1:21.1f}  {d2:22.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
