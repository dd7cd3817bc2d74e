"""Images per second of ``python -m aicalib_tf.detect`` against ``--workers``.

    python benchmarks/batch_speed.py [--copies 4] [--workers 1,2] [--repeat 2]

Runs the detect command line in a fresh process on the 13 photos of tests/data/opencv_left,
each copied ``--copies`` times under new names, for each worker count in turn (``--repeat``
rounds, the least wall time kept), and checks that every run wrote the same files. The wall time
includes the process start, the model load and, with workers, the pool's start.
"""

from __future__ import annotations

import argparse
import filecmp
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PHOTOS = ROOT / "tests" / "data" / "opencv_left"


def _run(folder: Path, out: Path, workers: int) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "aicalib_tf.detect", str(folder / "*.jpg"), "--pattern", "9x6", "--out", str(out),
                    "--quiet", "--workers", str(workers)], check=True, cwd=ROOT, capture_output=True)
    return time.perf_counter() - t0


def _same(a: Path, b: Path) -> bool:
    names = sorted(p.name for p in a.iterdir())
    return names == sorted(p.name for p in b.iterdir()) and filecmp.cmpfiles(a, b, names, shallow=False)[0] == names


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--copies", type=int, default=4)
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "images"
        folder.mkdir()
        for k in range(a.copies):
            for f in sorted(PHOTOS.glob("*.jpg")):
                shutil.copy(f, folder / f"{f.stem}_{k}.jpg")
        n = len(list(folder.iterdir()))
        best = {}
        for _ in range(a.repeat):
            for w in (int(v) for v in a.workers.split(",")):
                shutil.rmtree(Path(tmp) / f"out{w}", ignore_errors=True)
                best[w] = min(best.get(w, float("inf")), _run(folder, Path(tmp) / f"out{w}", w))
        first = min(best)
        same = all(_same(Path(tmp) / f"out{first}", Path(tmp) / f"out{w}") for w in best)
        print(f"{n} images, {a.repeat} rounds, least wall time; outputs identical across worker counts: {same}")
        print("| workers | wall s | images/s |\n| ---: | ---: | ---: |")
        for w, s in sorted(best.items()):
            print(f"| {w} | {s:.2f} | {n / s:.1f} |")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
