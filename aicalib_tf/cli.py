"""One error path for every command line: bad input is one line and exit 2, a crash says so.

Each entry point's ``main(argv)`` parses its arguments with a parser from :func:`parser` (which
adds ``--debug``) and runs its body through :func:`run_main`:

- an expected error (:class:`ValueError`, :class:`OSError`, :class:`ImportError`, the image
  gate's :class:`~aicalib_tf.io.ImageError`, a calibration that cannot be made) prints
  ``error: <what>: <why>`` on stderr and exits 2;
- any other exception is a bug: one line that says so and asks for a report, exit 2, and the
  traceback only with ``--debug``;
- running out of memory is one line too (exit 2), its traceback with ``--debug`` as for every error;
- Ctrl-C prints ``interrupted`` and exits 130.

Exit codes, as in every command: 0 done, 1 a check that did not pass, 2 bad input.
"""

from __future__ import annotations

import argparse
import errno
import os
import sys
import traceback
from typing import Callable

__all__ = ["EXIT_OK", "EXIT_FAILED", "EXIT_BAD_INPUT", "InputError", "parser", "run_main", "describe_error"]

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT = 0, 1, 2
EXIT_INTERRUPTED = 130
ISSUES_HINT = "this is a bug in aicalib_tf; please report it with the command line (rerun with --debug for the traceback)"


class InputError(ValueError):
    """Bad input that a command line reports as one line (the message names the input and the problem)."""


def parser(prog: str, doc: str | None) -> argparse.ArgumentParser:
    """An ArgumentParser whose help is the module docstring, with ``--debug`` added."""
    ap = argparse.ArgumentParser(prog=prog, description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--debug", action="store_true", help="on an unexpected error, print the traceback")
    return ap


def describe_error(exc: BaseException) -> str:
    """One line for an expected error: ``<what>: <why>`` where the exception knows both (printable:
    undecodable bytes of a file name shown as \\xNN, :func:`aicalib_tf.io.display_name`)."""
    from aicalib_tf.io import display_name, redact_credentials

    def _printable(text) -> str:  # and a URL's password never printed
        return redact_credentials(display_name(text))

    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        name = os.fsdecode(exc.filename) if isinstance(exc.filename, bytes) else str(exc.filename)
        why = exc.strerror
        if exc.errno == errno.ENAMETOOLONG:
            why = "file name too long"
        return f"{_printable(name)}: {why}"
    text = str(exc) or type(exc).__name__
    if isinstance(exc, KeyError):  # str(KeyError('x')) is "'x'"
        text = f"missing field {text}"
    return _printable(" ".join(text.split()))


def _expected(exc: BaseException) -> bool:
    from aicalib_tf.io import ImageError

    if isinstance(exc, (ValueError, OSError, ImportError, ImageError)):
        return not isinstance(exc, (UnicodeError,)) or isinstance(exc, ImageError)
    name = type(exc).__name__
    return name in ("CalibrationError", "RigError")


def run_main(body: Callable[[], int], *, debug: bool = False, stderr=None) -> int:
    """Run a command line's body; returns its exit code, or 2 (130 on Ctrl-C) with one line on stderr."""
    err = stderr or sys.stderr
    try:
        code = body()
        return EXIT_OK if code is None else int(code)
    except KeyboardInterrupt:
        print("interrupted", file=err)
        return EXIT_INTERRUPTED
    except SystemExit:
        raise
    except MemoryError:
        print("error: out of memory (try fewer or smaller images, or fewer --workers)", file=err)
        if debug:
            traceback.print_exc(file=err)
        return EXIT_BAD_INPUT
    except Exception as exc:  # noqa: BLE001 - the one place every error is turned into a line
        if _expected(exc):
            print(f"error: {describe_error(exc)}", file=err)
            if debug:
                traceback.print_exc(file=err)
            return EXIT_BAD_INPUT
        print(f"error: unexpected {type(exc).__name__}: {describe_error(exc)}; {ISSUES_HINT}", file=err)
        if debug:
            traceback.print_exc(file=err)
        return EXIT_BAD_INPUT


def debug_flag(argv: list[str] | None) -> bool:
    """Whether ``--debug`` is among the arguments (before they are parsed, so a parse error can use it)."""
    return "--debug" in (sys.argv[1:] if argv is None else argv)
