"""Many images over a process pool: each worker sets its detector up once, results come back in order.

:func:`map_images` runs ``work(item)`` for every item, where ``work = setup(*args)`` is built once
in each worker process (loading the model there, once), and yields the results in the items'
order, as they complete. With one worker (or one item) it runs in this process, without a pool,
and gives the same results: detection is deterministic and each image is detected on its own.

Workers are forked from a fork server (Linux; elsewhere spawned) that has imported the pipeline
once, about 0.5 s for the first pool of a process; a worker then starts in about 10 ms and
loads the model. A plain fork of the caller is not used: after OpenCV's or the interpreter's
thread pools have run in it, a forked child can hang on their locks. As with spawn, a script that
asks for more than one worker must keep its work under ``if __name__ == "__main__":`` (the
workers import the main module). Each worker's interpreter and OpenCV run on one
thread (``AICALIB_THREADS=1``, ``cv2.setNumThreads(1)``): N workers keep N cores busy. ``work``
should return a failure (an unreadable file, say) as a value rather than raise: an exception
raised in a worker ends the batch.
"""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from typing import Callable, Iterable, Iterator

__all__ = ["default_workers", "map_images", "worker_count", "worker_pool"]

# measured (benchmarks/batch_speed.py, OpenCV's 640x480 photos, kernels compiled ahead of time): 13 photos
# take 0.96 s in one process and 0.91 s with a pool of 2, 26 photos 1.75 and 1.42 s (with numba's JIT,
# whose set-up each worker paid, a pool paid from about 33 images)
MIN_ITEMS_PER_WORKER = 8
MAX_WORKERS_PER_CORE = 4  # more processes than this per core only multiply memory (each loads the model)
_WORK: list = []  # in a worker process: the work function its setup built


def default_workers() -> int:
    """The ``--workers`` default: every core (``os.cpu_count()``)."""
    return max(1, os.cpu_count() or 1)


def worker_count(workers: int | None, items: int) -> int:
    """Processes to use: ``workers``, at most one per item, at least 1. None (the default): one per
    core, but no more than one per ``MIN_ITEMS_PER_WORKER`` items (a pool's start costs about as
    much as that many detections).

    Raises ValueError for ``workers`` < 1 or over :data:`MAX_WORKERS_PER_CORE` per core.
    """
    if workers is not None and workers < 1:
        raise ValueError(f"--workers must be >= 1, got {workers}")
    cap = MAX_WORKERS_PER_CORE * (os.cpu_count() or 1)
    if workers is not None and workers > cap:
        raise ValueError(f"--workers {workers} is more than {cap} ({MAX_WORKERS_PER_CORE} per core); each loads the model")
    if workers is None:
        workers = min(default_workers(), items // MIN_ITEMS_PER_WORKER)
    return max(1, min(workers, items))


PRELOAD = ["aicalib_tf.detect.outputs", "aicalib_tf.cnn.runtime"]  # imported once by the fork server


def _context():
    """Forkserver where the platform has it, else spawn. Never a plain fork: a process forked after
    OpenCV's or the interpreter's thread pools ran hangs on their locks (measured: cv2.setNumThreads
    in a child forked after a detection never returns)."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(PRELOAD)
        return ctx
    return multiprocessing.get_context("spawn")


def _init_worker(setup: Callable, args: tuple) -> None:
    import cv2

    from aicalib_tf.cnn.runtime import THREADS_ENV

    os.environ[THREADS_ENV] = "1"
    cv2.setNumThreads(1)
    _WORK[:] = [setup(*args)]


def _run(item):
    return _WORK[0](item)


@contextmanager
def worker_pool(setup: Callable, args: tuple = (), *, workers: int = 1):
    """A pool of ``workers`` processes, each with ``work = setup(*args)``, kept open over many batches.

    Yields ``run(items) -> iterator of work(item)``, in order; with ``workers`` 1 it runs in this
    process. setup : a module-level function (sent to the workers by reference); args : picklable.
    """
    if workers <= 1:
        work = setup(*args)
        yield lambda items: map(work, list(items))
        return
    with ProcessPoolExecutor(workers, mp_context=_context(), initializer=_init_worker, initargs=(setup, args)) as pool:
        yield lambda items: pool.map(_run, list(items), chunksize=1)


def map_images(items: Iterable, setup: Callable, args: tuple = (), *, workers: int | None = None) -> Iterator:
    """Yield ``work(item)`` for each item, in order, where ``work = setup(*args)`` once per process.

    setup : a module-level function (it is sent to the workers by reference); args : picklable.
    workers : processes (None: one per core); see :func:`worker_count`.
    """
    items = list(items)
    with worker_pool(setup, args, workers=worker_count(workers, len(items))) as run:
        yield from run(items)
