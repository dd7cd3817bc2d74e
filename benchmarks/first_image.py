"""First image against the median in a fresh process: compile stalls.

    python benchmarks/first_image.py [--cold] [--prepare] [--images N]

In a fresh Python process: import the pipeline, load the shipped model, then detect the 13
photos of tests/data/opencv_left (640x480) one after another, each timed; prints the first
image's time, the median of the others and their ratio, and which way the kernels ran (compiled
ahead of time, or numba's JIT; ``AICALIB_KERNELS=jit`` in the environment forces the JIT).
``--cold`` first deletes the numba on-disk caches of aicalib_tf's kernels (``__pycache__/*.nbi,
*.nbc``) and runs the JIT, as after a fresh install without ``make setup``'s build and warm step;
the caches are written again by that run. ``--prepare`` calls
:func:`aicalib_tf.detect.warm.warm` with the model and the photos' size before the first image. Set ``AICALIB_THREADS``
as for any run.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
from aicalib_tf.kernels import MODE
from aicalib_tf.cnn.model import load_model
from aicalib_tf.detect.pipeline import detect_corners
from aicalib_tf.io import load_image
model = load_model("default")
if PREPARE:
    from aicalib_tf.detect.warm import warm
    warm(model, (640, 480))
t_load = time.perf_counter() - t0
images = [load_image(p) for p in sys.argv[1:]]
times = []
for g in images:
    t = time.perf_counter()
    detect_corners(g, (9, 6), model=model)
    times.append(1e3 * (time.perf_counter() - t))
print(json.dumps({"import_load_s": t_load, "ms": times, "kernels": MODE}))
"""


def clear_caches() -> int:
    """Delete aicalib_tf's numba cache files; returns how many."""
    files = [p for ext in ("*.nbi", "*.nbc") for p in (ROOT / "aicalib_tf").rglob(f"__pycache__/{ext}")]
    for p in files:
        p.unlink()
    return len(files)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cold", action="store_true", help="delete the numba caches first")
    ap.add_argument("--images", type=int, default=13)
    ap.add_argument("--prepare", action="store_true", help="call aicalib_tf.detect.warm.warm(model, (640, 480)) before the first image")
    a = ap.parse_args(argv)
    if a.cold:
        print(f"deleted {clear_caches()} numba cache files")
    env = dict(os.environ, AICALIB_KERNELS="jit") if a.cold else None
    photos = sorted((ROOT / "tests" / "data" / "opencv_left").glob("*.jpg"))[: a.images]
    child = CHILD.replace("PREPARE", str(a.prepare))
    out = subprocess.run([sys.executable, "-c", child, *map(str, photos)], cwd=ROOT, capture_output=True, text=True,
                         check=True, env=env)
    res = json.loads(out.stdout.strip().splitlines()[-1])
    ms = res["ms"]
    med = sorted(ms[1:])[len(ms[1:]) // 2]
    print(f"kernels {res['kernels']}; import + model load{' + warm' if a.prepare else ''} {res['import_load_s']:.2f} s; first image {ms[0]:.0f} ms, median of the other "
          f"{len(ms) - 1} {med:.1f} ms, ratio {ms[0] / med:.1f}x (target <= 3x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
