"""SIGTERM during a multiworker run's wait for its cluster: one line, exit 143, nothing written, no
process left behind (TensorFlow holds the GIL and swallows SIGTERM while it waits; the supervisor
of :mod:`aicalib_tf.cnn.cluster` owns the signal)."""

import json
import os
import signal
import socket
import subprocess
import sys
import time

import pytest

from aicalib_tf.cnn.cluster import EXIT_TERMINATED


def _free_ports(n):
    socks = [socket.socket() for _ in range(n)]
    for s in socks:
        s.bind(("localhost", 0))
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


def _listening(port) -> bool:
    try:
        socket.create_connection(("localhost", port), timeout=0.2).close()
        return True
    except OSError:
        return False


def _alive(pid) -> bool:
    """Whether ``pid`` runs (a zombie waiting for its new parent to reap it does not)."""
    try:
        return open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _children(pid) -> list[int]:
    try:
        return [int(c) for c in open(f"/proc/{pid}/task/{pid}/children").read().split()]
    except OSError:
        return []


def _wait_for_an_absent_worker(out, **popen) -> tuple[subprocess.Popen, int, int]:
    """``python -m aicalib_tf.train --strategy multiworker --out OUT`` as worker 0 of a two-worker cluster
    whose worker 1 never comes, so the run waits for it (up to 120 s): (the command, its port, the absent
    worker's port). ``popen``: subprocess.Popen's keywords for the output (stderr=..., text=...)."""
    mine, absent = _free_ports(2)
    env = dict(os.environ, TF_CPP_MIN_LOG_LEVEL="3",
               TF_CONFIG=json.dumps({"cluster": {"worker": [f"localhost:{mine}", f"localhost:{absent}"]},
                                     "task": {"type": "worker", "index": 0}}))
    proc = subprocess.Popen([sys.executable, "-m", "aicalib_tf.train", "--strategy", "multiworker", "--connect-timeout",
                             "120", "--out", str(out), "--quiet"], env=env, **popen)
    return proc, mine, absent


def test_sigterm_while_waiting_for_an_absent_worker_ends_the_run_at_once(tmp_path):
    proc, mine, absent = _wait_for_an_absent_worker(tmp_path / "run", stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not _listening(mine) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.1)  # the training process's own server is up: it waits in TensorFlow for worker 1
    if not _listening(mine):
        proc.kill()
        pytest.fail(f"the worker never started its server: {proc.communicate()[1][-2000:]}")
    time.sleep(0.5)
    trainer = _children(proc.pid)
    assert trainer, "the run has no training process"
    t0 = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    try:
        _, err = proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail("SIGTERM was ignored during the cluster wait")
    assert time.monotonic() - t0 < 5
    assert proc.returncode == EXIT_TERMINATED == 143
    errors = [line for line in err.splitlines() if line.startswith("error")]
    assert len(errors) == 1 and "terminated while waiting for the cluster" in errors[0], err[-2000:]
    assert f"worker 1 at localhost:{absent}" in errors[0] and "Traceback" not in err
    assert not (tmp_path / "run").exists()
    time.sleep(0.2)
    assert not any(_alive(pid) for pid in trainer)


def test_a_bad_tf_config_is_refused_by_the_supervisor_in_one_line(tmp_path, monkeypatch, capsys):
    from aicalib_tf.train import main

    monkeypatch.setenv("TF_CONFIG", '{"cluster": {"worker": ["localhost:1"]}, "task": {"type": "worker", "index": 3}}')
    assert main(["--strategy", "multiworker", "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: TF_CONFIG: not a cluster")
    assert not (tmp_path / "r").exists()


def test_a_sigkill_of_the_command_takes_its_training_process_with_it(tmp_path):
    proc, _, _ = _wait_for_an_absent_worker(tmp_path / "run", stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 30
    while not _children(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    trainer = _children(proc.pid)
    proc.kill()
    proc.wait()
    assert trainer
    deadline = time.monotonic() + 5
    while any(_alive(pid) for pid in trainer) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(_alive(pid) for pid in trainer)
