"""A ``--strategy multiworker`` run under a supervisor process that owns SIGTERM (imports no TensorFlow).

While a worker waits for the rest of its cluster, TensorFlow blocks in C++ code that holds the
GIL and installs its own SIGTERM handler (for preemption), so a SIGTERM sent to the worker would
be swallowed and no Python code of that process could react to it. ``train --strategy
multiworker`` therefore runs the training in a child process (the same command line) and waits
for it here:

- SIGTERM to the command (``kill PID``, a scheduler stopping the job) prints one line, ends the
  training process at once (SIGKILL: it cannot be stopped otherwise) and exits 143 (128 + SIGTERM).
  Before the cluster is up nothing has been written; after, the cluster resumes from
  RUN_DIR/backup when its commands are run again;
- Ctrl-C reaches the training process itself (the terminal signals both): it ends the wait at
  once, or training with ``interrupted`` and exit 130, as in every command;
- the training process dies with the command, however it ends (a SIGKILL included);
- the training process's exit code is the command's; if it is killed by a signal while it waits
  for the cluster (the ``--connect-timeout`` deadline, whose line it has printed), the exit code is 2.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

__all__ = ["CHILD_ENV", "EXIT_TERMINATED", "check_tf_config", "peers", "run_supervised", "report_connected"]

CHILD_ENV = "AICALIB_CLUSTER_FD"  # in the training process: the pipe to tell the supervisor the cluster is up
EXIT_TERMINATED = 128 + signal.SIGTERM


def check_tf_config() -> None:
    """Raise ``ValueError`` unless TF_CONFIG names a cluster with this process's task in it."""
    text = os.environ.get("TF_CONFIG")
    if not text:
        raise ValueError("--strategy multiworker needs TF_CONFIG set to the cluster and this worker's task, e.g. "
                         '{"cluster": {"worker": ["host0:12345", "host1:12345"]}, "task": {"type": "worker", "index": 0}}')
    try:
        cfg = json.loads(text)
        workers = cfg["cluster"]["worker"]
        task = cfg["task"]
        ok = isinstance(workers, list) and task["type"] in cfg["cluster"] and 0 <= int(task["index"]) < len(cfg["cluster"][task["type"]])
    except (ValueError, KeyError, TypeError):
        ok = False
    if not ok:
        raise ValueError(f"TF_CONFIG: not a cluster with this worker's task in it: {text[:200]}")


def peers() -> str:
    """The other tasks of TF_CONFIG's cluster, as ``worker 1 at host:port, ...``."""
    cfg = json.loads(os.environ["TF_CONFIG"])
    me = (cfg["task"]["type"], int(cfg["task"]["index"]))
    return ", ".join(f"{kind} {i} at {addr}" for kind, addrs in cfg["cluster"].items() for i, addr in enumerate(addrs)
                     if (kind, i) != me)


def report_connected() -> None:
    """In the training process: tell the supervisor that every worker of the cluster answered."""
    fd = os.environ.pop(CHILD_ENV, None)
    if fd is not None:
        try:
            os.write(int(fd), b"1")
            os.close(int(fd))
        except (OSError, ValueError):
            pass


def run_supervised(argv: list[str], stderr=None) -> int:
    """Run ``python -m aicalib_tf.train ARGV`` as the training process and wait for it (see the
    module docstring); returns the command's exit code."""
    err = stderr or sys.stderr
    check_tf_config()
    read, write = os.pipe()
    terminated: list[int] = []
    children: list[subprocess.Popen] = []

    def on_term(signum, frame):
        terminated.append(signum)
        for child in children:
            child.kill()

    old_term = signal.signal(signal.SIGTERM, on_term)
    try:
        children.append(subprocess.Popen([sys.executable, "-m", "aicalib_tf.train", *argv],
                                         env={**os.environ, CHILD_ENV: str(write)}, pass_fds=(write,),
                                         preexec_fn=_die_with(os.getpid())))
        os.close(write)
        if terminated:
            children[0].kill()
        old_int = signal.signal(signal.SIGINT, signal.SIG_IGN)  # the terminal's Ctrl-C reaches the child too
        try:
            code = children[0].wait()
        finally:
            signal.signal(signal.SIGINT, old_int)
    finally:
        signal.signal(signal.SIGTERM, old_term)
    connected = _connected(read)
    if terminated:
        where = "during training; run the same commands again to resume from the backup" if connected else \
            f"while waiting for the cluster ({peers()}); nothing was written"
        print(f"error: terminated {where}", file=err)
        return EXIT_TERMINATED
    if code == -signal.SIGINT:
        print("interrupted", file=err)
        return 128 + signal.SIGINT
    if code < 0:  # killed: at the connect deadline, its watchdog printed the line
        if connected:
            print(f"error: the training process was ended by signal {-code}", file=err)
        return 2
    return code


def _die_with(parent: int):
    """In the child before exec: be killed (SIGKILL) when ``parent`` ends, however it ends (Linux's
    PR_SET_PDEATHSIG; a SIGKILL of the command must not leave its training running)."""
    def arm():
        if sys.platform.startswith("linux"):
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))  # 1: PR_SET_PDEATHSIG
        if os.getppid() != parent:  # it ended before the line above
            os._exit(EXIT_TERMINATED)
    return arm


def _connected(fd: int) -> bool:
    try:
        os.set_blocking(fd, False)
        return os.read(fd, 1) == b"1"
    except (BlockingIOError, OSError):
        return False
    finally:
        os.close(fd)
