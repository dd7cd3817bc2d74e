"""Ship trained runs: copy each run's model into models/ and write models/MODEL_CARD.md.

    python -m aicalib_tf.cnn.model_card runs/default runs/report [--out models]

Each RUN_DIR must hold ``model.keras``, ``config.json`` and ``metrics.json`` from
``python -m aicalib_tf.train``. The model is copied to ``OUT/<arch>.keras`` (atomically) and the
card records, per model: the exact training command, preset, seed, wall time, parameter count,
validation metrics, file size and sha256.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from aicalib_tf.cnn.spec import write_sha256
from aicalib_tf.io import atomic_write_bytes, atomic_write_text

__all__ = ["train_command", "card_section", "runtime_section", "with_runtime_section", "main", "RUNTIME_HEADING"]

RUNTIME_HEADING = "## Runtime files (LiteRT)"

INTRO = """# Model card

Two Keras 3 Sequential models find chessboard inner corners (X-junctions) in grey images. Both
ship here as `.keras` (training, `load_model(name, backend="keras")`, `safe_mode=True`) and as
LiteRT `.tflite` exports, which `aicalib_tf.cnn.model.load_model("default" | "report")` runs
without TensorFlow (see the runtime section at the end).

- `default.keras` is fully convolutional: 3×3 Conv2D 4 at full resolution → 8 at stride 2 → 16 →
  max-pool → 32 → 32 → 32, ReLU, then a 1×1 Conv2D to 3 sigmoid channels. It runs once on a whole
  standardised image and gives a corner map with one cell per 4×4 pixels: the corner weight, and
  where in the cell the corner lies. Receptive field 35 px.
- `report.keras` is the network of the report "Artificial Intelligence based Camera Calibration":
  four 3×3 Conv2D layers (16, 32, 64, 128 filters, ReLU), each followed by 2×2 max-pooling, then
  Flatten, Dense(64, ReLU) and Dense(1, sigmoid). It classifies a 32×32 patch: is there a corner
  within a pixel of its centre? On a whole image it scores patches around the 800 strongest
  saddle points of the smoothed image.

Training data: data_gen renders 640×480 scenes of the `train` preset (every lens from 40° to 120°
HFOV, barrel and pincushion distortion, tilts to 60°, partial and occluded boards, noise, blur,
JPEG, salt-and-pepper, shadows, low contrast) plus 10% board-free clutter images; `default` also
trains on a quarter of `distorted` scenes (`--preset train:0.75,distorted:0.25`: strong lenses),
and on crops squeezed into acute junctions (`--squeeze`) or cut at half size (`--shrink`: squares
half as wide), see `aicalib_tf/data.py`. Checker-like distractor patches are switched off in
training: their X-junctions are real, so a local corner detector should fire on them, and the
grid assembly rejects them.

Both were trained on this project's 2-core CPU without a GPU. The same command and seed give the
same data order and, with TensorFlow's op determinism on (the default), the same weights on the
same machine and library versions (tested on a short run).

"""

_FLAGS = ("arch", "epochs", "steps", "batch_size", "seed", "preset", "pool_images", "val_images", "learning_rate",
          "focal_gamma", "squeeze", "shrink")


def train_command(config: dict) -> str:
    """The ``python -m aicalib_tf.train`` command line that reproduces ``config``."""
    parts = ["python -m aicalib_tf.train", f"--out runs/{config['arch']}"]
    # runs from before --focal-gamma existed used cross-entropy; before --squeeze and --shrink, neither
    config = {"focal_gamma": 0.0, "squeeze": 0.0, "shrink": 0.0, **config}
    parts += [f"--{k.replace('_', '-')} {config[k]}" for k in _FLAGS]
    if config.get("shade"):  # crops under random light and blur laws (runs before --shade have none)
        parts.append(f"--shade {config['shade']}")
    if config.get("init"):  # a fine-tune from a trained model's weights
        parts.append(f"--init {config['init']}")
    if config.get("data"):  # runs on TFRecord shards or several devices (older runs have neither)
        parts += [f"--data '{config['data']}'"] + (["--deterministic"] if config.get("deterministic_data") else [])
    if config.get("strategy", "default") != "default":
        parts.append(f"--strategy {config['strategy']}")
    return " ".join(parts)


def _prep_note(metrics: dict) -> str:
    """How much of the wall time went to rendering (or loading a cached) image pool, if recorded."""
    prep = metrics.get("data_prep_s")
    if prep is None:
        return ""
    return f" (of which {prep / 60.0:.1f} min rendering or loading the image pools)"


def _data_line(config: dict) -> str:
    if config.get("data"):
        return (f"- Data: TFRecord shards `{config['data']}` (`python -m data_gen --format tfrecord`), crops drawn "
                f"with seed {config['seed']}.")
    return (f"- Data: data_gen preset `{config['preset']}` (checker distractors off; 10% board-free clutter images), "
            f"{config['pool_images']} rendered 640×480 images, seed {config['seed']}.")


def _scale_line(config: dict) -> list[str]:
    """The replicas, global batch and rate of a run that recorded them (older runs: one replica)."""
    if "replicas" not in config:
        return []
    return [f"- Replicas: {config['replicas']} (`--strategy {config.get('strategy', 'default')}`); global batch "
            f"{config['global_batch_size']}, peak learning rate {config['global_learning_rate']:g} "
            f"(per replica: {config['batch_size']} and {config['learning_rate']:g})."]


def card_section(config: dict, metrics: dict) -> str:
    """The Markdown section of one model."""
    minutes = metrics.get("wall_s_total", metrics["wall_s_this_process"]) / 60.0
    v = metrics["validation"]
    return "\n".join([
        f"## `{config['arch']}.keras`",
        "",
        f"- Training command: `{train_command(config)}`",
        _data_line(config),
        f"- Wall time on the 2-core CPU, rendering included: {minutes:.1f} min{_prep_note(metrics)}.",
        *_scale_line(config),
        f"- Parameters: {metrics['params']:,}. File: {metrics['size_bytes'] / 1e6:.2f} MB.",
        f"- sha256: `{metrics['sha256']}`",
        f"- Validation ({v['images']} images of preset `{v['preset']}`, seed {v['seed']}, never trained on; "
        f"a match is within {v['match_px']:g} px of a visible true corner, corner weight ≥ {config['threshold']}):",
        "",
        "  | precision | recall | F1 | localisation median px | p95 px |",
        "  | --- | --- | --- | --- | --- |",
        f"  | {metrics['precision']:.4f} | {metrics['recall']:.4f} | {metrics['f1']:.4f} | "
        f"{metrics['loc_median_px']:.3f} | {metrics['loc_p95_px']:.3f} |",
        "",
    ])


def runtime_section(models_dir: Path, checks: dict, int8_detections: str = "") -> str:
    """The card's section on the shipped .tflite files: each one's size, sha256 and ``checks[name]``
    (:func:`aicalib_tf.cnn.export.compare_runtime`: output difference and speed against Keras);
    ``int8_detections``: the int8 model's detections against float32, one sentence
    (:func:`aicalib_tf.bench.model_detections.verdict_line`)."""
    from aicalib_tf.cnn.spec import file_sha256

    lines = [RUNTIME_HEADING, "",
             "Written by `python -m aicalib_tf.export` (Keras -> SavedModel -> `tf.lite.TFLiteConverter`, float32, "
             "TFLite builtin ops; `default_int8` quantised to int8 in weights and activations, float input and output, "
             "calibrated on 48 data_gen renders of every preset) and run by `aicalib_tf.cnn.runtime` on `ai_edge_litert`'s interpreter, which "
             "checks each file against its `<file>.sha256` on load. Compared with the `.keras` model on this "
             "machine when exported:", ""]
    for name, c in checks.items():
        path = Path(models_dir) / f"{name}.tflite"
        lines += [f"- `{name}.tflite`: {path.stat().st_size:,} bytes, sha256 `{file_sha256(path)}`; on {c['inputs']}: "
                  f"largest output difference {c['max_abs_diff']:.1e}, {c['runtime_ms']:.2f} ms per call against "
                  f"{c['keras_ms']:.2f} ms for Keras (median)."]
    lines += ["", "`tests/test_runtime.py` checks that detection with the runtime gives the Keras model's ids and "
              "corners within 1e-3 px on three real photos."]
    if int8_detections:
        lines += ["", "`default_int8.tflite` is the network the detector runs unless another is named "
                  "(`aicalib_tf.cnn.spec.DETECTOR_NETWORK`; `--model default` or `--network default` on the command "
                  "lines runs the float32 one). Detections, " + int8_detections + "."]
    return "\n".join(lines + [""])


def with_runtime_section(card: str, section: str) -> str:
    """``card`` with its runtime section (from :data:`RUNTIME_HEADING` to the next ``## `` heading) replaced by
    ``section``, or ``section`` appended."""
    start = card.find(RUNTIME_HEADING)
    if start < 0:
        return card.rstrip("\n") + "\n\n" + section
    end = card.find("\n## ", start + len(RUNTIME_HEADING))
    return card[:start] + section + (card[end + 1:] if end >= 0 else "")


def build_parser() -> argparse.ArgumentParser:
    """The command line's parser (docs/cli.md is generated from it)."""
    ap = argparse.ArgumentParser(prog="python -m aicalib_tf.cnn.model_card", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", type=Path, help="run folders of python -m aicalib_tf.train")
    ap.add_argument("--out", type=Path, default=Path("models"))
    ap.add_argument("--intro", type=Path, help="Markdown put before the per-model sections")
    return ap


def main(argv: list[str] | None = None) -> int:
    """CLI entry (see the module docstring); returns the process exit code (2 on bad arguments)."""
    args = build_parser().parse_args(argv)
    runs = []
    for run in args.runs:  # check every run before writing anything
        try:
            config = json.loads((run / "config.json").read_text())
            metrics = json.loads((run / "metrics.json").read_text())
            data = (run / "model.keras").read_bytes()
            log = (run / "log.csv").read_bytes()
        except (OSError, ValueError) as exc:
            print(f"error: {run}: not a finished training run ({exc})", file=sys.stderr)
            return 2
        runs.append((config, metrics, data, log))
    args.out.mkdir(parents=True, exist_ok=True)
    sections = []
    for config, metrics, data, log in runs:
        atomic_write_bytes(args.out / f"{config['arch']}.keras", data)
        write_sha256(args.out / f"{config['arch']}.keras")  # checked on load (aicalib_tf.cnn.spec.check_model_file)
        atomic_write_bytes(args.out / f"{config['arch']}_log.csv", log)
        sections.append(card_section(config, metrics))
    intro = args.intro.read_text() if args.intro else INTRO
    atomic_write_text(args.out / "MODEL_CARD.md", intro + "\n".join(sections))
    print(f"wrote {args.out / 'MODEL_CARD.md'} and {len(sections)} model(s); run `python -m aicalib_tf.export` to "
          "write their .tflite files and the card's runtime section")
    return 0


if __name__ == "__main__":
    sys.exit(main())
