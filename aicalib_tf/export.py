"""``python -m aicalib_tf.export``: write models/default.tflite and models/report.tflite (and their
.sha256) from the trained .keras models, models/default_int8.tflite (default quantised to int8,
calibrated on data_gen images), and the model card's runtime
section (size, sha256, output difference and speed against Keras); ``--warm`` instead compiles the
kernels ahead of time into ``aicalib_tf/_kernels_aot*.so`` (and numba's on-disk caches, the
fallback), then detects three synthetic boards: a first detection then costs no compile and loads
no numba. Logic: :mod:`aicalib_tf.cnn.export`, :mod:`aicalib_tf.cnn.model_card`,
:mod:`aicalib_tf.kernels`, :mod:`aicalib_tf.detect.warm`."""

from __future__ import annotations

import argparse
import os
import sys


INT8_CHECK_IMAGES = 6  # images per named condition on which the int8 model's detections are compared (as evaluate --quick)


def build_parser() -> argparse.ArgumentParser:
    """The command line's parser (docs/cli.md is generated from it)."""
    ap = argparse.ArgumentParser(prog="python -m aicalib_tf.export", description=__doc__.split("\n\n")[0])
    ap.add_argument("--warm", action="store_true",
                    help="only compile the kernels (ahead of time, and numba's caches) and detect three synthetic boards; export nothing")
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.warm:
        import subprocess

        # a child process builds them (this one must not load the kernels before they exist);
        # without a C compiler it says so, and numba's JIT caches, compiled by warm(), serve
        subprocess.call([sys.executable, "-m", "aicalib_tf.kernels"])
        from aicalib_tf.detect.warm import warm
        from aicalib_tf.kernels import MODE

        print(f"kernels ready ({'compiled ahead of time' if MODE == 'aot' else 'numba, just in time'}): "
              f"three detections in {warm():.2f} s")
        return 0
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    from aicalib_tf.bench.model_detections import compare_models, verdict_line
    from aicalib_tf.cnn.export import compare_runtime, export_all
    from aicalib_tf.cnn.model_card import runtime_section, with_runtime_section
    from aicalib_tf.cnn.spec import MODELS_DIR, RUNTIME_FILES
    from aicalib_tf.io import atomic_write_text

    try:
        for path in export_all():
            print(f"wrote {path} ({path.stat().st_size} bytes)")
        checks = {name: compare_runtime(name) for name in RUNTIME_FILES}
        int8 = verdict_line(compare_models({"float32": "default", "int8": "default_int8"}, INT8_CHECK_IMAGES),
                            "float32", "int8", INT8_CHECK_IMAGES)
    except (FileNotFoundError, ValueError) as exc:  # a missing or corrupt model, named by the loader
        print(f"error: {exc}", file=sys.stderr)
        return 2
    card = MODELS_DIR / "MODEL_CARD.md"
    atomic_write_text(card, with_runtime_section(card.read_text(encoding="utf-8"), runtime_section(MODELS_DIR, checks, int8)))
    print(f"int8: {int8}")
    print(f"updated {card}: " + "; ".join(f"{n} max diff {c['max_abs_diff']:.1e}, {c['runtime_ms']:.2f} ms "
                                         f"(Keras {c['keras_ms']:.2f} ms)" for n, c in checks.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
