"""The corner-map network on ONNX Runtime against LiteRT, on the same inputs.

    pip install onnxruntime tf2onnx   # not project dependencies
    python benchmarks/onnx_vs_litert.py [--repeat 30]

Converts models/default.tflite to ONNX with tf2onnx (``--tflite``, opset 17, into a temporary
folder), then times one call of each runtime on standardised synthetic 640x480, 960x540 and
1920x1080 boards with 1 and 2 threads (median of ``--repeat`` calls after one untimed call), and
prints the largest output difference between them.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from aicalib_tf.cnn.corner_map import network_input  # noqa: E402
from aicalib_tf.cnn.runtime import RuntimeModel  # noqa: E402
from aicalib_tf.detect.warm import synthetic_board  # noqa: E402

SIZES = ((640, 480), (960, 540), (1920, 1080))


def _median_ms(fn, x, repeat: int) -> float:
    fn(x)
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn(x)
        times.append(1e3 * (time.perf_counter() - t0))
    return float(np.median(times))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=30)
    a = ap.parse_args(argv)
    import onnxruntime as ort

    with tempfile.TemporaryDirectory() as tmp:
        onnx_path = Path(tmp) / "default.onnx"
        subprocess.run([sys.executable, "-m", "tf2onnx.convert", "--tflite", str(ROOT / "models" / "default.tflite"),
                        "--output", str(onnx_path), "--opset", "17"], check=True, capture_output=True)
        inputs = {s: network_input(synthetic_board(size=s)) for s in SIZES}
        print("| size | threads | LiteRT ms | ONNX Runtime ms | largest difference |\n| --- | ---: | ---: | ---: | ---: |")
        for threads in (1, 2):
            opts = ort.SessionOptions()
            opts.intra_op_num_threads, opts.inter_op_num_threads = threads, 1
            sess = ort.InferenceSession(str(onnx_path), opts, providers=["CPUExecutionProvider"])
            name = sess.get_inputs()[0].name
            lite = RuntimeModel(ROOT / "models" / "default.tflite", num_threads=threads)

            def onnx(x):
                return sess.run(None, {name: x})[0]
            for size, x in inputs.items():
                diff = float(np.abs(onnx(x) - lite(x)).max())
                print(f"| {size[0]}x{size[1]} | {threads} | {_median_ms(lite, x, a.repeat):.2f} | "
                      f"{_median_ms(onnx, x, a.repeat):.2f} | {diff:.1e} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
