"""Train a corner CNN on data_gen images: ``python -m aicalib_tf.train``.

Examples::

    python -m aicalib_tf.train --arch default --out runs/default            # the default network
    python -m aicalib_tf.train --arch report --out runs/report              # the report's network
    python -m aicalib_tf.train --out runs/default --resume                  # continue a killed run
    python -m aicalib_tf.train --init default --learning-rate 0.0005 --epochs 6 --out runs/ft  # fine-tune
    python -m aicalib_tf.train --data 'shards/*.tfrecord' --out runs/big    # from data_gen --format tfrecord
    TF_CONFIG=... python -m aicalib_tf.train --strategy multiworker --data 'shards/*.tfrecord' --out runs/big

``--init MODEL`` starts from the weights of a trained model (a shipped name such as ``default``,
or a .keras file; loaded with safe_mode) instead of a fresh initialisation, for fine-tuning on
new data: the model must have ``--arch``'s layers. The learning-rate schedule starts again from
``--learning-rate``, so a fine-tune usually takes a lower one. config.json and metrics.json
record the init file and its sha256.

The exact commands of the shipped models, with their data options, are in models/MODEL_CARD.md.

A run renders a seeded pool of ``--preset`` images in memory, then trains on crops cut from it
(see :mod:`aicalib_tf.cnn.training_data`; ``--preset`` may mix presets, e.g. ``train:0.8,distorted:0.2``;
``--squeeze P`` warps a share P of the corner-map crops into acute junctions and thin squares;
``--shrink P`` cuts a share P from the image at half size: squares half as wide; ``--shade P`` puts a
share P under a random light fall-off, blur and noise: dim, soft corners as at a vignetted rim).
After each epoch it scores corner precision, recall (a match is within 1 px) and localisation
error on a fixed validation set (``--preset``, or a mix's first preset; seed 900001, never
trained on) and saves a checkpoint. RUN_DIR receives:

    config.json        the effective configuration (written first, atomically)
    checkpoint-NNNN.keras  the model after the last finished epoch, with its optimiser state
    state.json         how many epochs are finished, and which checkpoint holds them
    log.csv            one row per epoch: loss and the validation metrics
    tensorboard/       TensorBoard logs
    model.keras        the final model (atomically, at the end)
    metrics.json       the final validation metrics, wall time and parameter count

Training at scale: ``--data`` reads TFRecord shards of ``python -m data_gen --format tfrecord``
through tf.data (files interleaved in parallel, shuffled, cropped and batched in parallel,
prefetched; ``--deterministic`` fixes the element order, see :mod:`aicalib_tf.cnn.tfrecord_data`)
instead of rendering a pool in memory (the default, for a small run). ``--strategy mirrored``
trains on every local GPU, ``--strategy multiworker`` on a cluster described by TF_CONFIG
(chief-only run folder, restart from a BackupAndRestore backup, see
:mod:`aicalib_tf.cnn.distribute`; the training runs in a child of this command, which owns
SIGTERM: it ends the run at once with one line and exit 143, see :mod:`aicalib_tf.cnn.cluster`). ``--batch-size`` and ``--learning-rate`` are per replica: the
global batch and rate scale with the replicas and are recorded in config.json and metrics.json.

Determinism: the same seed gives the same pool, crops and data order. On CPU the weights are
reproducible run to run when TensorFlow's op determinism is on (it is, see ``--no-determinism``).

Other Keras backends: with ``KERAS_BACKEND=jax`` (e.g. on a GPU machine without TensorFlow) a
corner-map model trains and validates the same way (float32 map, same decoding), without
TensorBoard logs or op determinism; its .keras file loads under TensorFlow. Several runs on one
machine can share their rendered pools through ``AICALIB_POOL_CACHE=DIR`` (see :func:`cached_pool`).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from aicalib_tf.cli import debug_flag, parser, run_main
from aicalib_tf.cnn.cluster import CHILD_ENV, run_supervised
from aicalib_tf.cnn.train import TrainConfig, train


def build_parser() -> argparse.ArgumentParser:
    """The command line's parser (docs/cli.md is generated from it)."""
    ap = parser("python -m aicalib_tf.train", __doc__)
    d = TrainConfig(out="")
    ap.add_argument("--out", required=True, metavar="RUN_DIR", help="run folder (created)")
    ap.add_argument("--arch", default=d.arch, help="default | report | default_v1 | default_c12 | default_c16 | default_pre (default: %(default)s)")
    ap.add_argument("--epochs", type=int, default=None, help=f"epochs (default: {d.epochs}; with --resume: the run's own)")
    ap.add_argument("--steps", type=int, default=d.steps, help="batches per epoch (default: %(default)s)")
    ap.add_argument("--batch-size", type=int, default=d.batch_size, help="per replica (default: %(default)s)")
    ap.add_argument("--seed", type=int, default=d.seed, help="data and initialisation seed (default: %(default)s)")
    ap.add_argument("--preset", default=d.preset, help="data_gen preset to train on, or a mix such as train:0.8,distorted:0.2 (default: %(default)s)")
    ap.add_argument("--pool-images", type=int, default=d.pool_images, help="images rendered for training (default: %(default)s)")
    ap.add_argument("--val-images", type=int, default=d.val_images, help="validation images (default: %(default)s)")
    ap.add_argument("--learning-rate", type=float, default=d.learning_rate, help="peak Adam rate per replica, cosine decay (default: %(default)s)")
    ap.add_argument("--workers", type=int, default=d.workers, help="rendering processes (default: %(default)s)")
    ap.add_argument("--threshold", type=float, default=d.threshold, help="corner weight for validation (default: %(default)s)")
    ap.add_argument("--focal-gamma", type=float, default=d.focal_gamma,
                    help="default model: focal-loss γ; 0 for weighted cross-entropy (default: %(default)s)")
    ap.add_argument("--squeeze", type=float, default=d.squeeze,
                    help="default model: share of training crops squeezed up to 3x in a random direction "
                         "(acute X-junctions, thin squares) (default: %(default)s)")
    ap.add_argument("--shrink", type=float, default=d.shrink,
                    help="default model: share of training crops cut from the image at half size "
                         "(squares half as wide) (default: %(default)s)")
    ap.add_argument("--shade", type=float, default=d.shade,
                    help="default model: share of training crops under a random light fall-off, blur and noise "
                         "(dim, low-contrast, soft corners as at a vignetted rim) (default: %(default)s)")
    ap.add_argument("--data", default=d.data, metavar="GLOB",
                    help="TFRecord shards of data_gen --format tfrecord (globs, comma-separated); default: render a pool in memory")
    ap.add_argument("--deterministic", action="store_true", help="--data: a fixed element order (slower parallel stages)")
    ap.add_argument("--strategy", default=d.strategy, help="default | mirrored | multiworker (TF_CONFIG) (default: %(default)s)")
    ap.add_argument("--connect-timeout", type=float, default=d.connect_timeout, metavar="SECONDS",
                    help="multiworker: give up when the cluster's other workers do not answer within this time "
                         "(default: %(default)s)")
    ap.add_argument("--no-determinism", action="store_true", help="allow non-deterministic TensorFlow ops (other Keras backends: no effect)")
    ap.add_argument("--init", default=d.init, metavar="MODEL",
                    help="start from this model's weights: a shipped name (default) or a .keras file with --arch's layers "
                         "(default: a fresh initialisation)")
    ap.add_argument("--resume", action="store_true", help="continue the run in --out from its last checkpoint")
    ap.add_argument("--quiet", action="store_true", help="no progress bars")
    return ap


def main(argv: list[str] | None = None) -> int:
    """CLI entry (see the module docstring); returns the process exit code (2 on bad arguments)."""
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    return run_main(lambda: _run(argv), debug=debug_flag(argv))


def _run(argv: list[str] | None) -> int:
    args = build_parser().parse_args(argv)
    if args.strategy == "multiworker" and CHILD_ENV not in os.environ:  # a supervisor owns SIGTERM
        return run_supervised(list(sys.argv[1:] if argv is None else argv))
    d = TrainConfig(out="")
    cfg = TrainConfig(
        out=args.out, arch=args.arch, epochs=args.epochs if args.epochs is not None else d.epochs, steps=args.steps, batch_size=args.batch_size,
        seed=args.seed, preset=args.preset, pool_images=args.pool_images, val_images=args.val_images,
        learning_rate=args.learning_rate, workers=args.workers, threshold=args.threshold, focal_gamma=args.focal_gamma,
        determinism=not args.no_determinism, squeeze=args.squeeze, shrink=args.shrink, shade=args.shade,
        data=args.data, strategy=args.strategy, deterministic_data=args.deterministic, init=args.init,
        connect_timeout=args.connect_timeout,
    )
    metrics = train(cfg, resume=args.resume, progress=not args.quiet, epochs_given=args.epochs)
    print(f"done: precision {metrics['precision']:.4f}, recall {metrics['recall']:.4f}, "
          f"loc median {metrics['loc_median_px']:.3f} px; model {Path(cfg.out) / 'model.keras'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
