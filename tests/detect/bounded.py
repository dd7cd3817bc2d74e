"""The detector in a child process under an address-space limit, for tests of memory bounds.

A test that runs the detector on a large or hostile image asks :class:`BoundedDetector` rather
than calling it in the pytest process: the child runs under ``resource.setrlimit(RLIMIT_AS)``, so
a blow-up ends as a failed test (a MemoryError, or the child's death, reported with the image's
size) instead of taking the machine's memory. One child serves every image of a test module; it
is started again after a failure.
"""

from __future__ import annotations

import multiprocessing as mp
import traceback

import numpy as np

LIMIT = 2 * 2**30  # bytes of address space: about 1 GB more than the detector's peak on a 48 MP photo
TIMEOUT = 300.0  # s for one image


def _serve(conn, limit: int, model: str | None) -> None:
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    from aicalib_tf.cnn.model import load_model
    from aicalib_tf.detect.pipeline import detect_corners

    net = None if model is None else load_model(model)

    while True:
        msg = conn.recv()
        if msg is None:
            return
        img, pattern = msg
        try:
            conn.send(("ok", detect_corners(img, pattern, model=net)))
        except MemoryError:
            conn.send(("memory", traceback.format_exc()))
        except Exception:  # noqa: BLE001 - sent back whole, for the test to report
            conn.send(("error", traceback.format_exc()))


class BoundedDetector:
    """``detect(image, pattern) -> Detection`` run in a child limited to ``limit`` bytes of address space.

    model : a shipped network's name for :func:`aicalib_tf.cnn.model.load_model`, or None (the detector's default).
    """

    def __init__(self, limit: int = LIMIT, model: str | None = None):
        self.limit, self.model, self.proc, self.conn = limit, model, None, None

    def _start(self) -> None:
        ctx = mp.get_context("spawn")  # a fresh interpreter: nothing inherited from pytest's memory
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_serve, args=(child, self.limit, self.model), daemon=True)
        self.proc.start()
        child.close()

    def __call__(self, img: np.ndarray, pattern=None):
        if self.proc is None or not self.proc.is_alive():
            self._start()
        what = f"detect_corners on a {img.shape} {img.dtype} image, pattern {pattern!r}"
        try:
            self.conn.send((img, pattern))
            if not self.conn.poll(TIMEOUT):
                self.close()
                raise AssertionError(f"{what}: no answer in {TIMEOUT:.0f} s")
            kind, value = self.conn.recv()
        except (EOFError, BrokenPipeError, ConnectionResetError):
            code = self.proc.exitcode
            self.close()
            raise AssertionError(f"{what}: the child died (exit code {code}) under {self.limit / 2**30:.1f} GiB") from None
        if kind == "memory":
            raise AssertionError(f"{what}: MemoryError under {self.limit / 2**30:.1f} GiB of address space\n{value}")
        if kind == "error":
            raise AssertionError(f"{what} raised:\n{value}")
        return value

    def close(self) -> None:
        if self.proc is not None:
            try:
                self.conn.send(None)
            except (BrokenPipeError, OSError):
                pass
            self.proc.join(5)
            if self.proc.is_alive():
                self.proc.kill()
                self.proc.join()
        self.proc = self.conn = None
