"""Training a corner CNN: a config in, a run folder with checkpoints, logs, the model and its metrics out.

The command line is :mod:`aicalib_tf.train`; its docstring describes the run folder and determinism.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import asdict, dataclass, fields
from pathlib import Path

__all__ = ["TrainConfig", "train", "init_weights", "init_record", "VALIDATION_SEED"]

VALIDATION_SEED = 900001


@dataclass(frozen=True)
class TrainConfig:
    """Arguments of ``python -m aicalib_tf.train``."""

    out: str
    arch: str = "default"
    epochs: int = 40
    steps: int = 500
    batch_size: int = 32
    seed: int = 0
    preset: str = "train"
    pool_images: int = 4000
    val_images: int = 64
    learning_rate: float = 2e-3
    workers: int = 2
    threshold: float = 0.5
    focal_gamma: float = 2.0
    determinism: bool = True
    squeeze: float = 0.0
    shrink: float = 0.0
    shade: float = 0.0
    data: str = ""  # TFRecord shards (globs, comma-separated); "" renders the pool in memory
    strategy: str = "default"
    deterministic_data: bool = False
    init: str = ""  # start from this model's weights: a shipped name (default) or a .keras path; "" a fresh model
    connect_timeout: float = 300.0  # multiworker: seconds to wait for the cluster's other workers

    def check(self) -> None:
        """Raise ``ValueError`` naming the first bad option."""
        from aicalib_tf.cnn.model import ARCHITECTURES
        from aicalib_tf.cnn.training_data import parse_mix

        if self.arch not in ARCHITECTURES:
            raise ValueError(f"--arch: unknown architecture {self.arch!r}; choose from: {', '.join(ARCHITECTURES)}")
        try:
            parse_mix(self.preset)
        except ValueError as e:
            raise ValueError(f"--preset: {e}") from None
        for name in ("epochs", "steps", "batch_size", "pool_images", "val_images", "workers"):
            if getattr(self, name) < 1:
                raise ValueError(f"--{name.replace('_', '-')} must be >= 1, got {getattr(self, name)}")
        if not 0 < self.connect_timeout < float("inf"):
            raise ValueError(f"--connect-timeout must be a positive number of seconds, got {self.connect_timeout}")
        if self.seed < 0:
            raise ValueError(f"--seed must be >= 0, got {self.seed}")
        if not 0.0 < self.learning_rate < 1.0:
            raise ValueError(f"--learning-rate must be in (0, 1), got {self.learning_rate}")
        if self.focal_gamma < 0:
            raise ValueError(f"--focal-gamma must be >= 0, got {self.focal_gamma}")
        for name in ("squeeze", "shrink", "shade"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"--{name} must be in [0, 1], got {getattr(self, name)}")
        if not 0.0 < self.threshold < 1.0:
            raise ValueError(f"--threshold must be in (0, 1), got {self.threshold}")
        if self.strategy not in ("default", "mirrored", "multiworker"):
            raise ValueError(f"--strategy: unknown strategy {self.strategy!r}; choose from: default, mirrored, multiworker")
        if self.init and self.init not in ARCHITECTURES and not self.init.endswith(".keras"):
            raise ValueError(f"--init: expected a shipped model name ({', '.join(ARCHITECTURES)}) or a .keras file, "
                             f"got {self.init!r}")
        if self.data and self.arch == "report":
            raise ValueError("--data: TFRecord shards train corner-map models; the report's patch classifier "
                             "trains on an in-memory pool (leave out --data)")


def _layer_signature(model) -> list[tuple]:
    """What must agree for one model's weights to stand in for another's: per layer its class, its
    weight shapes, and the settings that change what the weights compute (strides, pooling, activation)."""
    sig = []
    for layer in model.layers:
        conf = layer.get_config()
        sig.append((type(layer).__name__, tuple(tuple(w.shape) for w in layer.weights),
                    *(str(conf.get(k)) for k in ("strides", "pool_size", "padding", "activation"))))
    return sig


def _init_path(init: str) -> Path:
    from aicalib_tf.cnn.model import MODELS_DIR
    from aicalib_tf.cnn.spec import ARCHITECTURES

    return MODELS_DIR / f"{init}.keras" if init in ARCHITECTURES else Path(init)


def init_weights(model, init: str) -> None:
    """Set ``model``'s weights to those of the ``.keras`` model ``init`` (a shipped name such as
    ``default``, or a path), loaded with ``safe_mode=True``.

    Raises ``ValueError`` naming the file when it is missing, unreadable, or holds another
    architecture than ``model`` (layers, weight shapes, strides, pooling).
    """
    from aicalib_tf.cnn.model import load_model

    path = _init_path(init)
    try:
        source = load_model(path, backend="keras")
    except (FileNotFoundError, ValueError) as exc:
        raise ValueError(f"--init: {exc}") from None
    got, want = _layer_signature(source), _layer_signature(model)
    if got != want:
        first = next((i for i, (a, b) in enumerate(zip(got, want)) if a != b), min(len(got), len(want)))
        raise ValueError(f"--init: {path} holds a {source.name!r} network that does not match --arch {model.name!r} "
                         f"({len(got)} layers against {len(want)}; first difference at layer {first})")
    model.set_weights(source.get_weights())


def init_record(init: str) -> dict:
    """What config.json and metrics.json record of ``--init``: the name given, the file and its sha256.

    Raises ``ValueError`` naming the file when there is none."""
    from aicalib_tf.cnn.model import file_sha256

    path = _init_path(init)
    if not path.is_file():
        raise ValueError(f"--init: model file not found: {path}")
    return {"init": init, "path": str(path), "sha256": file_sha256(path)}


def _write_json(path: Path, obj) -> None:
    from aicalib_tf.io import atomic_write_text
    from aicalib_tf.jsonio import dumps

    atomic_write_text(path, dumps(obj, indent=2) + "\n")  # strict JSON: a NaN loss is written as null


POOL_CACHE_ENV = "AICALIB_POOL_CACHE"


def cached_pool(count: int, seed: int, *, preset: str, workers: int = 1, progress: bool = True):
    """:func:`aicalib_tf.cnn.training_data.render_pool`, kept in the folder ``$AICALIB_POOL_CACHE`` when that is set.

    For running several trainings on one machine: the pool of a (count, seed, preset) is rendered
    once (saved atomically as .npz) and loaded by the other runs. The images are the same as
    rendering them; without the variable nothing is cached.
    """
    import io
    import zipfile

    import numpy as np

    from aicalib_tf.cnn.training_data import Pool, render_pool
    from aicalib_tf.io import atomic_write_bytes
    from data_gen.sample import GENERATOR_VERSION

    folder = os.environ.get(POOL_CACHE_ENV)
    if not folder:
        return render_pool(count, seed, preset=preset, workers=workers, progress=progress)
    name = f"pool-v{GENERATOR_VERSION}-{preset.replace(':', '_').replace(',', '+')}-{count}-{seed}.npz"
    path = Path(folder) / name
    if path.is_file():
        try:
            with np.load(path) as z:
                images, flat, counts, mean, std = z["images"], z["corners"], z["counts"], z["mean"], z["std"]
        except (OSError, ValueError, KeyError, zipfile.BadZipFile) as exc:
            raise ValueError(f"{path}: not a readable pool cache ({exc}); delete it to render the pool again") from None
        return Pool(images, np.split(flat, np.cumsum(counts)[:-1]), mean, std)
    pool = render_pool(count, seed, preset=preset, workers=workers, progress=progress)
    buf = io.BytesIO()
    np.savez(buf, images=pool.images, corners=np.concatenate([c.reshape(-1, 2) for c in pool.corners]).astype(np.float32),
             counts=np.array([len(c) for c in pool.corners], np.int64), mean=pool.mean, std=pool.std)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, buf.getvalue())
    return pool


def validation_set(preset: str, count: int, *, workers: int = 1, progress: bool = True):
    """The fixed validation images: (images (N, 480, 640) uint8, corners list of (k, 2))."""
    pool = cached_pool(count, VALIDATION_SEED, preset=preset, workers=workers, progress=progress)
    return pool.images, pool.corners


def evaluate_points(model, images, corners, threshold: float = 0.5) -> dict:
    """Corner precision/recall/localisation of ``model`` on whole images (see metrics.point_detection_stats).

    In float32 on every machine, so the figures are the same wherever training runs (inference
    may use bfloat16, see aicalib_tf.cnn.inference)."""
    import keras

    from aicalib_tf.cnn.point_metrics import point_detection_stats

    if keras.backend.backend() == "tensorflow":
        from aicalib_tf.cnn.inference import corner_points

        pairs = [(corner_points(model, img, threshold, precision="float32")[0], gt) for img, gt in zip(images, corners)]
    else:  # aicalib_tf.cnn.inference needs TensorFlow; the same float32 map and decoding on any backend
        pairs = [(_backend_corner_points(model, img, threshold), gt) for img, gt in zip(images, corners)]
    return point_detection_stats(pairs, max_distance=1.0)


def _backend_corner_points(model, gray, threshold: float):
    """Corner points of a corner-map model on a non-TensorFlow Keras backend (e.g. JAX, for training
    on a GPU machine without TensorFlow): as :func:`aicalib_tf.cnn.inference.corner_points` in float32."""
    import numpy as np

    from aicalib_tf.cnn.corner_map import decode_map, network_input
    from aicalib_tf.cnn.model import model_kind

    if model_kind(model) != "map":
        raise ValueError("validation of patch classifiers needs the TensorFlow backend")
    return decode_map(np.asarray(model.predict_on_batch(network_input(gray)))[0], threshold)[0]


def _callbacks(cfg: TrainConfig, run: Path, val, initial_epoch: int, wall_before: float, t_start: float, backup=()):
    import keras

    from aicalib_tf.cnn.model import save_model

    class Validation(keras.callbacks.Callback):
        """Adds val_precision, val_recall, val_f1 and val_loc_px to the epoch logs."""

        def on_epoch_end(self, epoch, logs=None):
            stats = evaluate_points(self.model, *val, cfg.threshold)
            logs = logs if logs is not None else {}
            logs.update(val_precision=stats["precision"], val_recall=stats["recall"],
                        val_f1=stats["f1"], val_loc_px=stats["loc_median_px"])
            print(f"\n  validation: precision {stats['precision']:.4f}  recall {stats['recall']:.4f}  "
                  f"loc median {stats['loc_median_px']:.3f} px  ({stats['true']} corners)", flush=True)

    class Checkpoint(keras.callbacks.Callback):
        """Saves checkpoint-<epochs done>.keras (model and optimiser state), then state.json naming it,
        then removes older checkpoints. A kill at any moment leaves a state.json whose checkpoint exists
        and matches its epoch count."""

        def on_epoch_end(self, epoch, logs=None):
            name = f"checkpoint-{epoch + 1:04d}.keras"
            save_model(self.model, run / name)
            _write_json(run / "state.json", {"epochs_done": epoch + 1, "checkpoint": name,
                                             "wall_s": round(wall_before + time.perf_counter() - t_start, 1)})
            for old in run.glob("checkpoint-*.keras"):
                if old.name != name:
                    old.unlink(missing_ok=True)

    try:  # Keras's TensorBoard callback writes through tf.summary: left out where TensorFlow is not installed
        import tensorflow  # noqa: F401

        tensorboard = [keras.callbacks.TensorBoard(str(run / "tensorboard"), write_graph=False, profile_batch=0)]
    except ImportError:
        tensorboard = []
    return [
        Validation(),  # first: it adds to the logs that the CSV logger writes
        keras.callbacks.CSVLogger(str(run / "log.csv"), append=initial_epoch > 0),
        *tensorboard,
        Checkpoint(),
        *backup,  # last: a backup of epoch e means its logs and checkpoint are written
    ]


def _training_data(cfg: TrainConfig, strategy, kind: str, global_batch: int, initial_epoch: int, progress: bool):
    """What ``fit`` reads: the TFRecord shards through tf.data (``--data``), or batches cut from a
    pool rendered in memory (global batches; tf.distribute splits them over the replicas)."""
    from aicalib_tf.cnn.training_data import CornerMapBatches, PatchBatches

    if cfg.data:
        from aicalib_tf.cnn.tfrecord_data import corner_dataset, find_shards

        files = find_shards(cfg.data)

        def per_pipeline(ctx):
            return corner_dataset(files, per_replica_batch=cfg.batch_size, steps=cfg.steps, seed=cfg.seed,
                                  first_epoch=initial_epoch, epochs=cfg.epochs, input_context=ctx,
                                  deterministic=cfg.deterministic_data, squeeze=cfg.squeeze, shrink=cfg.shrink,
                                  shade=cfg.shade)

        if strategy.num_replicas_in_sync == 1 and cfg.strategy == "default":
            return per_pipeline(None)
        return strategy.distribute_datasets_from_function(per_pipeline)
    pool = cached_pool(cfg.pool_images, cfg.seed, preset=cfg.preset, workers=cfg.workers, progress=progress)
    batches_cls = CornerMapBatches if kind == "map" else PatchBatches
    extra = {"squeeze": cfg.squeeze, "shrink": cfg.shrink, "shade": cfg.shade} if batches_cls is CornerMapBatches else {}
    return batches_cls(pool, batch_size=global_batch, steps=cfg.steps, seed=cfg.seed, epoch=initial_epoch, **extra)


def train(cfg: TrainConfig, *, resume: bool = False, progress: bool = True, epochs_given: int | None = None) -> dict:
    """Train as ``cfg`` says and write RUN_DIR; returns the final metrics dict.

    resume : continue the run in ``cfg.out`` from its last checkpoint; its config.json wins over
        ``cfg``, except that ``epochs_given`` (when not None) sets a new epoch count.
    """


    # size: a training run reads top to bottom: config, data, model, callbacks, fit, save (STYLE.md).
    cfg.check()
    from aicalib_tf.cnn import distribute

    strategy = distribute.make_strategy(cfg.strategy, cfg.connect_timeout)  # before any other TensorFlow work (MultiWorkerMirrored)
    out = Path(cfg.out)
    multiworker = cfg.strategy == "multiworker"
    if multiworker and resume:
        raise ValueError("--resume: a multiworker run resumes by itself from RUN_DIR/backup; run the same commands again")
    if resume:
        state = json.loads((out / "state.json").read_text()) if (out / "state.json").is_file() else {}
        if not state.get("checkpoint") or not (out / state["checkpoint"]).is_file():
            raise ValueError(f"--resume: {out} holds no checkpoint to resume from")
        saved = json.loads((out / "config.json").read_text())
        known = {f.name for f in fields(TrainConfig)}
        epochs = saved["epochs"] if epochs_given is None else epochs_given
        cfg = TrainConfig(**{**{k: v for k, v in saved.items() if k in known}, "epochs": epochs, "out": str(out)})
        initial_epoch = int(state["epochs_done"])
        wall_before = float(state.get("wall_s", 0.0))
    else:
        initial_epoch = distribute.backup_epoch(out) if multiworker else 0  # a cluster started again
        if (out / "model.keras").exists() or (not initial_epoch and (out / "state.json").exists()):
            raise ValueError(f"--out {out}: already holds a run; use --resume or a new folder")
        state = json.loads((out / "state.json").read_text()) if initial_epoch and (out / "state.json").is_file() else {}
        wall_before = float(state.get("wall_s", 0.0))
    run = distribute.worker_dir(strategy, out)  # a non-chief worker writes to a temporary folder
    run.mkdir(parents=True, exist_ok=True)
    replicas = int(strategy.num_replicas_in_sync)
    global_batch, global_lr = cfg.batch_size * replicas, cfg.learning_rate * replicas
    _write_json(run / "config.json", {**asdict(cfg), "replicas": replicas, "global_batch_size": global_batch,
                                      "global_learning_rate": global_lr,
                                      **({"init_model": init_record(cfg.init)} if cfg.init else {})})

    import keras
    import tensorflow as tf

    from aicalib_tf.cnn.model import (
        build_model,
        compile_model,
        file_sha256,
        load_model,
        model_kind,
        save_model,
    )
    from aicalib_tf.cnn.training_data import parse_mix

    keras.utils.set_random_seed(cfg.seed)
    if cfg.determinism and keras.backend.backend() == "tensorflow":
        import tensorflow as tf

        tf.config.experimental.enable_op_determinism()
    t0 = time.perf_counter()
    val_preset = parse_mix(cfg.preset)[0][0]  # a mix validates on its first preset
    val = validation_set(val_preset, cfg.val_images, workers=cfg.workers, progress=progress)
    with strategy.scope():
        if resume:
            model = load_model(out / state["checkpoint"], compile=True)
        else:
            model = build_model(cfg.arch)
            if cfg.init:
                init_weights(model, cfg.init)
            model = compile_model(model, global_lr, focal_gamma=cfg.focal_gamma)
        if cfg.strategy != "default":
            distribute.build_for_fit(model)
    batches = _training_data(cfg, strategy, model_kind(model), global_batch, initial_epoch, progress)
    prep_s = time.perf_counter() - t0
    if initial_epoch < cfg.epochs:
        schedule = keras.callbacks.LearningRateScheduler(
            lambda e, lr: global_lr * 0.5 * (1 + math.cos(math.pi * e / cfg.epochs))
        )
        backup = [distribute.WorkerBackup(out / distribute.BACKUP_DIR, run / distribute.BACKUP_DIR)] if multiworker else []
        # shuffle=False: batches are already random per (seed, epoch, index); Keras's own shuffle
        # draws from Python's global random, which a resumed process cannot replay
        try:
            model.fit(batches, epochs=cfg.epochs, initial_epoch=initial_epoch, verbose=1 if progress else 2,
                      shuffle=False, steps_per_epoch=cfg.steps,
                      callbacks=[schedule, *_callbacks(cfg, run, val, initial_epoch, wall_before, t0, backup)])
        except tf.errors.DataLossError as exc:  # a record's checksum broken past the first (check_shard reads those)
            message = " ".join(str(exc.message).split()).split(" [[")[0]  # TensorFlow's own words, not the graph's trace
            raise ValueError(f"--data: a shard could not be read: {message[:300]}") from None
    final = run / "model.keras"
    save_model(model, final)
    stats = evaluate_points(model, *val, cfg.threshold)
    previous = json.loads((run / "metrics.json").read_text()) if resume and (run / "metrics.json").exists() else {}
    metrics = {
        **stats,
        "arch": cfg.arch,
        "params": int(model.count_params()),
        "epochs": cfg.epochs,
        "resumed_at_epoch": initial_epoch if resume or initial_epoch else None,
        "data_prep_s": round(prep_s, 1),
        "replicas": replicas,
        "global_batch_size": global_batch,
        "global_learning_rate": global_lr,
        "wall_s_this_process": round(time.perf_counter() - t0, 1),
        "wall_s_total": round(wall_before + time.perf_counter() - t0, 1),
        "validation": {"preset": val_preset, "seed": VALIDATION_SEED, "images": cfg.val_images, "match_px": 1.0},
        "init": init_record(cfg.init) if cfg.init else None,
        "sha256": file_sha256(final),
        "size_bytes": final.stat().st_size,
        **({"previous": previous} if previous else {}),
    }
    _write_json(run / "metrics.json", metrics)
    distribute.discard(run, out)
    return metrics
