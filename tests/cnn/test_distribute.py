"""Training on TFRecord shards with tf.distribute: a two-worker cluster trains like one worker with
the same global batch, and after losing a worker resumes from its BackupAndRestore backup to the
same loss curve and weights (one cluster shows both: killed after its first backup, started again).

Every run is tiny (3 epochs of 2 steps on 128×128 crops) and CPU only. Tolerances: the workers
all-reduce float32 gradients and sum the loss over replicas in another order than one worker's
batch reduction, so results agree to float32 rounding, not bit for bit (measured: losses within
1e-7 relative, weights within 3e-7 after 9 Adam steps); we allow 1e-5 relative on losses and
1e-5 absolute on weights (of size ~0.4), far below what one differing batch would give (~1e-3).
"""

import csv
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("tensorflow")

from data_gen.dataset import DatasetConfig  # noqa: E402
from data_gen.shards import ShardConfig, write_shards  # noqa: E402

EPOCHS = 3
TINY = ["--epochs", str(EPOCHS), "--steps", "2", "--val-images", "1", "--workers", "1", "--seed", "5", "--quiet",
        "--deterministic"]


_GIVEN: set[int] = set()  # ports handed out in this process


def _ports(n: int) -> list[int]:
    """``n`` free localhost ports, none handed out before in this process: clusters start side by
    side, and a port is only taken when a worker binds it, so the system could give it out twice."""
    ports: list[int] = []
    while len(ports) < n:
        with socket.socket() as s:
            s.bind(("localhost", 0))
            port = s.getsockname()[1]
        if port not in _GIVEN:
            _GIVEN.add(port)
            ports.append(port)
    return ports


def _train(*args, tf_config=None) -> subprocess.Popen:
    env = {**os.environ, "TF_CPP_MIN_LOG_LEVEL": "3"}
    env.pop("TF_CONFIG", None)
    if tf_config is not None:
        env["TF_CONFIG"] = json.dumps(tf_config)
    return subprocess.Popen([sys.executable, "-m", "aicalib_tf.train", *args], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _cluster(out: Path, data: str) -> list[subprocess.Popen]:
    """Two workers on localhost, per-replica batch 2 and rate 1e-3: global batch 4, rate 2e-3."""
    hosts = [f"localhost:{p}" for p in _ports(2)]
    return [_train("--strategy", "multiworker", "--out", str(out), "--data", data, "--batch-size", "2",
                   "--learning-rate", "1e-3", *TINY,
                   tf_config={"cluster": {"worker": hosts}, "task": {"type": "worker", "index": i}})
            for i in range(2)]


def _stop(procs) -> str:
    """Kill every process (a worker whose peer died waits for it forever) and return their output."""
    for p in procs:
        p.kill()
    return "\n".join(p.communicate()[0] or "" for p in procs)


def _finish(procs, timeout=240) -> None:
    for p in procs:
        try:
            out, _ = p.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"a training run took over {timeout} s:\n{_stop(procs)}") from None
        assert p.returncode == 0, out


def _losses(run: Path) -> dict[int, float]:
    return {int(r["epoch"]): float(r["loss"]) for r in csv.DictReader((run / "log.csv").open())}


def _weights(run: Path) -> list:
    from aicalib_tf.cnn.model import load_model

    return load_model(run / "model.keras").get_weights()


def _kill_after_first_backup(out: Path, workers) -> int:
    """Wait for the cluster's first backup, kill worker 1, then the chief (stuck without it); returns the epochs backed up."""
    meta = out / "backup" / "training_metadata.json"
    deadline = time.time() + 240
    while time.time() < deadline and all(p.poll() is None for p in workers):
        if meta.is_file() and json.loads(meta.read_text() or "{}").get("epoch", 0) >= 1:
            break
        time.sleep(0.05)
    if not all(p.poll() is None for p in workers):  # one stopped before the first backup
        raise AssertionError(f"a worker of the cluster stopped early:\n{_stop(workers)}")
    workers[1].send_signal(signal.SIGKILL)  # a worker dies; the chief cannot go on alone
    time.sleep(2.0)
    workers[0].send_signal(signal.SIGKILL)
    for p in workers:
        p.communicate()
    return json.loads(meta.read_text())["epoch"]


@pytest.mark.slow
def test_a_cluster_trains_like_one_worker_and_resumes_after_losing_a_worker_to_the_same_weights(tmp_path):
    """Side by side: one worker (batch 4, rate 2e-3) and a two-worker cluster (2 and 1e-3 per replica)
    that loses a worker after its first backup and is started again. The epochs before the kill are
    the fresh cluster's, those after the restarted one's: every epoch's loss and the final weights
    must be the single worker's (a cluster that never restarts takes the first part's path throughout)."""
    write_shards(ShardConfig(DatasetConfig(out=tmp_path / "shards", count=6, preset="train", seed=2, size=(320, 240)),
                             shards=2), progress=False)
    data = str(tmp_path / "shards" / "*.tfrecord")
    one = _train("--out", str(tmp_path / "one"), "--data", data, "--batch-size", "4", "--learning-rate", "2e-3", *TINY)
    doomed = _cluster(tmp_path / "two", data)
    backed_up = _kill_after_first_backup(tmp_path / "two", doomed)
    restarted = _cluster(tmp_path / "two", data)  # the same commands again
    _finish([one, *restarted])
    assert 1 <= backed_up < EPOCHS  # killed mid-run
    one, two = _losses(tmp_path / "one"), _losses(tmp_path / "two")
    assert sorted(one) == sorted(two) == list(range(EPOCHS))
    np.testing.assert_allclose([two[e] for e in range(EPOCHS)], [one[e] for e in range(EPOCHS)], rtol=1e-5)
    for a, b in zip(_weights(tmp_path / "two"), _weights(tmp_path / "one")):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-5)
    config = json.loads((tmp_path / "two" / "config.json").read_text())
    assert config["replicas"] == 2 and config["global_batch_size"] == 4 and config["global_learning_rate"] == 2e-3
    metrics = json.loads((tmp_path / "two" / "metrics.json").read_text())
    assert metrics["replicas"] == 2 and metrics["resumed_at_epoch"] == backed_up
    assert not (tmp_path / "two" / "backup").exists()  # removed when training ends


def test_multiworker_without_tf_config_is_one_line_exit_2(tmp_path, monkeypatch, capsys):
    from aicalib_tf.train import main

    monkeypatch.delenv("TF_CONFIG", raising=False)
    assert main(["--strategy", "multiworker", "--out", str(tmp_path / "r"), "--epochs", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: --strategy multiworker needs TF_CONFIG") and len(err.splitlines()) == 1
    assert not (tmp_path / "r").exists()


@pytest.mark.slow
def test_a_worker_that_never_comes_is_one_error_line_after_the_connect_timeout(tmp_path):
    """TF_CONFIG names a second worker that is never started: TensorFlow would wait forever (and
    ignore SIGTERM); the run ends after --connect-timeout with one line naming the missing worker."""
    mine, absent = _ports(2)
    env = dict(os.environ, TF_CONFIG=json.dumps({"cluster": {"worker": [f"localhost:{mine}", f"localhost:{absent}"]},
                                                 "task": {"type": "worker", "index": 0}}))
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "aicalib_tf.train", "--strategy", "multiworker", "--connect-timeout", "1",
                           "--out", str(tmp_path / "run"), "--quiet"], env=env, capture_output=True, text=True, timeout=240)
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error")]
    assert proc.returncode == 2 and time.monotonic() - t0 < 200
    assert len(errors) == 1 and f"worker 1 at localhost:{absent}" in errors[0] and "within 1 s" in errors[0], proc.stderr[-2000:]
    assert not (tmp_path / "run" / "model.keras").exists()
