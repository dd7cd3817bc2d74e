"""``python -m aicalib_tf.export``: write models/default.tflite and models/report.tflite (and their
.sha256) from the trained .keras models, optionally an int8 model; ``--warm`` compiles the numba
kernels' on-disk caches instead (a first detection then costs no compile). Logic:
:mod:`aicalib_tf.cnn.export`, :mod:`aicalib_tf.detect.warm`."""

from __future__ import annotations

import argparse
import os
import sys


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m aicalib_tf.export", description=__doc__.split("\n\n")[0])
    ap.add_argument("--int8", action="store_true", help="also write models/default_int8.tflite (calibrated on data_gen images)")
    ap.add_argument("--warm", action="store_true", help="only compile the numba caches (detect one bundled image), export nothing")
    ap.add_argument("--card", action="store_true", help="re-render models/MODEL_CARD.md afterwards")
    args = ap.parse_args(argv)
    if args.warm:
        from aicalib_tf.detect.warm import warm

        print(f"numba caches ready: one detection in {warm():.2f} s")
        return 0
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    from aicalib_tf.cnn.export import export_all

    for path in export_all(int8=args.int8):
        print(f"wrote {path} ({path.stat().st_size} bytes)")
    if args.card:
        from aicalib_tf.cnn.model_card import main as card

        card([])
    return 0


if __name__ == "__main__":
    sys.exit(main())
