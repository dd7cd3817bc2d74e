"""Training on several devices or machines with ``tf.distribute`` (``train --strategy``).

* ``default``: one device, as before;
* ``mirrored``: every local GPU (``tf.distribute.MirroredStrategy``; on a machine without one, its CPU);
* ``multiworker``: ``tf.distribute.MultiWorkerMirroredStrategy``, the cluster and this process's
  place in it read from the ``TF_CONFIG`` variable, e.g. for worker 1 of two::

      TF_CONFIG='{"cluster": {"worker": ["host0:12345", "host1:12345"]}, "task": {"type": "worker", "index": 1}}'

  Every worker runs the same command. The chief (the ``chief`` task, else worker 0) writes the run
  folder; the others write theirs to a temporary folder that is removed at the end. A
  ``keras.callbacks.BackupAndRestore`` backup (``RUN_DIR/backup``, written by the chief and read
  by every worker, so RUN_DIR must be on storage all workers see) lets the cluster be restarted
  after a worker dies: the same commands continue from the last finished epoch.

``--batch-size`` and ``--learning-rate`` are per replica: the global batch is ``batch-size × replicas``
and the Adam rate ``learning-rate × replicas`` (the linear scaling rule); both are recorded in
config.json as ``global_batch_size`` and ``global_learning_rate``.
"""

from __future__ import annotations

import atexit
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import keras
import tensorflow as tf

from aicalib_tf.cnn.cluster import check_tf_config, peers, report_connected

__all__ = ["STRATEGIES", "make_strategy", "is_chief", "worker_dir", "WorkerBackup", "backup_epoch", "build_for_fit",
           "discard", "BACKUP_DIR"]

STRATEGIES = ("default", "mirrored", "multiworker")
BACKUP_DIR = "backup"


def make_strategy(name: str, connect_timeout_s: float | None = None) -> tf.distribute.Strategy:
    """The strategy ``name`` (see the module docstring). Call it before any other TensorFlow work.

    ``multiworker`` waits for every worker of TF_CONFIG to answer, at most ``connect_timeout_s``
    seconds (None: as long as TensorFlow waits): then one line names the peers and the process ends.
    Ctrl-C ends the wait at once; TensorFlow's own wait would ignore it. TensorFlow also swallows
    SIGTERM from then on: ``train`` runs this in a child of a supervisor that owns SIGTERM
    (:mod:`aicalib_tf.cnn.cluster`), which it tells here that the cluster is up.
    """
    if name not in STRATEGIES:
        raise ValueError(f"--strategy: unknown strategy {name!r}; choose from: {', '.join(STRATEGIES)}")
    if name == "mirrored":
        return tf.distribute.MirroredStrategy()
    if name == "multiworker":
        check_tf_config()
        strategy = _interruptible(tf.distribute.MultiWorkerMirroredStrategy, connect_timeout_s or float("inf"), peers())
        report_connected()  # to the supervisor that owns SIGTERM (aicalib_tf.cnn.cluster)
        return strategy
    return tf.distribute.get_strategy()


# the watchdog's program: wait for the parent to close our stdin (it is connected) or for the deadline
_WATCHDOG = """
import os, select, signal, sys
pid, timeout, peers = int(sys.argv[1]), float(sys.argv[2]), sys.argv[3]
if not select.select([sys.stdin], [], [], timeout)[0]:
    print(f"error: --strategy multiworker: the cluster did not come up within {timeout:g} s (waiting for {peers}); "
          "start every worker of TF_CONFIG with the same command, or correct its addresses", file=sys.stderr, flush=True)
    os.kill(pid, signal.SIGTERM)
    if not select.select([sys.stdin], [], [], 2.0)[0]:  # TensorFlow catches SIGTERM while it waits
        os.kill(pid, signal.SIGKILL)
"""


def _interruptible(build, timeout_s: float, peers: str):
    """``build()``, which blocks in TensorFlow's C++ code (holding the GIL) until every peer answers,
    with a deadline, and with Ctrl-C honoured.

    No Python code of this process runs during that wait, so Ctrl-C gets its default action (the
    process ends) while it lasts, and a watchdog process, told by a closed pipe that the wait is over,
    prints one error line at the deadline and ends this process (SIGTERM, then SIGKILL: TensorFlow
    catches SIGTERM during the wait).
    """
    sigs = (signal.SIGINT,)
    watchdog = None
    if timeout_s < float("inf"):
        watchdog = subprocess.Popen([sys.executable, "-c", _WATCHDOG, str(os.getpid()), str(timeout_s), peers],
                                    stdin=subprocess.PIPE)
    old = {sig: signal.signal(sig, signal.SIG_DFL) for sig in sigs}
    try:
        return build()
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
        if watchdog is not None:
            watchdog.stdin.close()
            watchdog.wait()


def is_chief(strategy: tf.distribute.Strategy) -> bool:
    """Whether this process writes the run folder: always, except a non-chief worker of a cluster."""
    resolver = getattr(strategy, "cluster_resolver", None)
    spec = resolver.cluster_spec().as_dict() if resolver is not None else {}
    if not spec:
        return True
    if resolver.task_type == "chief":
        return True
    return resolver.task_type == "worker" and resolver.task_id == 0 and "chief" not in spec


def worker_dir(strategy: tf.distribute.Strategy, run: Path) -> Path:
    """``run`` for the chief; a new temporary folder for any other worker (its logs and files are discarded)."""
    if is_chief(strategy):
        return run
    resolver = strategy.cluster_resolver
    path = Path(tempfile.mkdtemp(prefix=f"aicalib-{resolver.task_type}{resolver.task_id}-"))
    atexit.register(shutil.rmtree, path, ignore_errors=True)  # also when training fails
    return path


def backup_epoch(run: Path) -> int:
    """Epochs finished according to the run's BackupAndRestore backup (0 without one)."""
    path = Path(run) / BACKUP_DIR / "training_metadata.json"
    if not path.is_file():
        return 0
    try:
        return int(json.loads(path.read_text())["epoch"])
    except (ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{path}: not a readable backup ({exc}); delete {path.parent} to start over") from None


class WorkerBackup(keras.callbacks.BackupAndRestore):
    """``BackupAndRestore`` for a cluster: every worker restores from ``backup_dir`` (the chief's);
    the chief saves there, any other worker into its own ``save_dir`` (removed at the end)."""

    def __init__(self, backup_dir: Path, save_dir: Path):
        super().__init__(str(backup_dir), save_freq="epoch", double_checkpoint=True, delete_checkpoint=True)
        self._restore_paths = (self._weights_path, self._training_metadata_path)
        self._save_paths = (str(Path(save_dir) / "latest.weights.h5"), str(Path(save_dir) / "training_metadata.json"))
        self._save_dir = str(save_dir)

    def on_train_begin(self, logs=None):
        self._weights_path, self._training_metadata_path = self._restore_paths
        super().on_train_begin(logs)
        self._weights_path, self._training_metadata_path = self._save_paths
        self._prev_weights_path = f"{self._weights_path}.bkp"
        self._prev_training_metadata_path = f"{self._training_metadata_path}.bkp"
        self.backup_dir = self._save_dir
        self._current_epoch = getattr(self.model, "_initial_epoch", None) or 0


def build_for_fit(model: keras.Model) -> None:
    """Get ``model`` ready for ``fit`` under a strategy: build its loss and metrics from its input
    and output shapes, skip the build that ``fit`` does from a first batch, and shape the per-step figures so that they
    can be averaged over the workers. Call it inside ``strategy.scope()``.

    That build reduces the first distributed batch across replicas, which fails under
    MultiWorkerMirroredStrategy (a batch of PerReplica values cannot be all-reduced), and under
    any strategy it consumes one batch that training never sees. Building from shapes needs no data.
    """
    def spec(shape):
        return keras.KerasTensor(shape if isinstance(shape, tuple) else tuple(shape), "float32")

    model._symbolic_build(data_batch=(spec(model.input_shape), spec(model.output_shape)))
    model._maybe_symbolic_build = lambda iterator=None, data_batch=None: None
    if isinstance(tf.distribute.get_strategy(), tf.distribute.MultiWorkerMirroredStrategy):
        # fit averages each step's figures over the workers along axis 0, which scalars lack:
        # give them one (the mean over the replicas is then a scalar again)
        step = model.train_step
        model.train_step = lambda data: {k: tf.reshape(v, [1]) for k, v in step(data).items()}


def discard(run: Path, out: Path) -> None:
    """Remove a non-chief worker's temporary folder (``run`` differs from the real ``out``)."""
    if Path(run).resolve() != Path(out).resolve():
        shutil.rmtree(run, ignore_errors=True)
