"""Compiled loops: numba kernels, built ahead of time into one extension module, numba as fallback.

Each kernel is written once, as numba-compilable Python, beside the maths it implements
(``detect/corners/saddle_kernels.py`` and the others in :data:`KERNEL_SOURCES`), and declared with
``@kernel("argument types", ...)``, one string per signature in numba's notation (``f4[:, ::1]`` a
C-ordered 2-D float32 array, ``u1`` uint8, ``i8`` an int64, ``b1`` a bool). A function that only kernels call is
``@helper``. Kernels run one of two ways:

* **ahead of time** (``MODE == "aot"``): ``python -m aicalib_tf.kernels`` (run by ``python -m
  aicalib_tf.export --warm``, that is ``make setup``) compiles every signature with numba's
  ``pycc`` into ``aicalib_tf/_kernels_aot*.so``. A process then loads plain machine code in under
  a millisecond: no ``import numba`` (0.3 s) and no numba runtime set-up at the first kernel call
  (0.4 s, its typing registries and scipy's BLAS).
* **just in time** (``MODE == "jit"``): ``numba.njit(cache=True, nogil=True)``, compiled on first
  use and cached on disk, when the extension is missing, was built from other kernel sources or on
  another CPU, or ``AICALIB_KERNELS=jit`` is set.

Both ways check each call's arguments against the declared signatures (dtype and dimensions;
an array not C-ordered is copied into C order) and raise ``TypeError`` on a mismatch: a compiled extension does not check types
itself, and the same check in JIT mode makes the tests catch a call the extension could not take.
"""

from __future__ import annotations

import hashlib
import importlib
import json
import os
import platform
import re
import sys
import warnings
from pathlib import Path

import numpy as np

__all__ = ["kernel", "helper", "MODE", "build_extension", "KERNEL_SOURCES"]

PACKAGE_DIR = Path(__file__).resolve().parent
EXTENSION = "_kernels_aot"  # the module pycc writes into the package: aicalib_tf/_kernels_aot*.so
STAMP_FILE = PACKAGE_DIR / f"{EXTENSION}.json"  # what the extension was built from: sources' sha256, CPU
MODE_ENV = "AICALIB_KERNELS"  # "jit" forces numba's just-in-time compilation (the build itself runs so)
# Every module that declares @kernel or @helper, relative to the package: the extension is used only
# while these files are those it was built from.
KERNEL_SOURCES = (
    "cnn/corner_map_kernels.py",
    "detect/corners/sampling.py",
    "detect/corners/saddle_kernels.py",
    "detect/corners/shadow_kernels.py",
    "detect/corners/junction_kernels.py",
    "detect/chessboard/lattice_kernels.py",
    "detect/chessboard/grid_kernels.py",
    "detect/pyramid_kernels.py",
    "detect/corners/sigma_kernels.py",
)
_DTYPES = {"f4": np.float32, "f8": np.float64, "i8": np.int64, "b1": np.bool_, "u1": np.uint8}
_SCALARS = {"f4": np.float32, "f8": float, "i8": int, "b1": bool, "u1": int}
_ARG = re.compile(r"\s*(f4|f8|i8|b1|u1)\s*(?:\[([^\]]*)\])?\s*$")

# name -> (module, python function, signatures); filled as kernel modules are imported
REGISTRY: dict[str, tuple[str, object, tuple[str, ...]]] = {}


def _split_args(sig: str) -> list[str]:
    """``"f4[:, ::1], i8"`` -> ``["f4[:, ::1]", "i8"]`` (commas inside brackets kept)."""
    out, depth, cur = [], 0, ""
    for ch in sig:
        depth += (ch == "[") - (ch == "]")
        if ch == "," and depth == 0:
            out.append(cur)
            cur = ""
        else:
            cur += ch
    return out + [cur] if cur.strip() else out


def parse_signature(sig: str) -> tuple[tuple[str, int], ...]:
    """One signature string -> per argument (type code, dimensions; 0 for a scalar).

    Arrays must be C-ordered (the last dimension ``::1``): the extension takes no other layout.
    """
    out = []
    for arg in _split_args(sig):
        m = _ARG.match(arg)
        if m is None:
            raise ValueError(f"kernel signature {sig!r}: cannot read {arg.strip()!r}")
        code, dims = m.group(1), m.group(2)
        if dims is None:
            out.append((code, 0))
            continue
        parts = [d.strip() for d in dims.split(",")]
        if parts[-1] != "::1" or any(p != ":" for p in parts[:-1]):
            raise ValueError(f"kernel signature {sig!r}: {arg.strip()!r} must be C-ordered, e.g. f8[:, ::1]")
        out.append((code, len(parts)))
    return tuple(out)


_DTYPE_OF = {code: np.dtype(t) for code, t in _DTYPES.items()}


def _prepared(spec, args) -> list | None:
    """The arguments as the kernel takes them, or None where they do not match ``spec``.

    Each array must have the declared dtype and dimensions (C-ordered: a copy only where it is
    not; no kernel writes into its arguments); each scalar (not an array of one or more dimensions)
    is converted to its declared type (float32 stays float32). One pass over the arguments: a kernel
    is called hundreds of times per image, and this check is its only Python overhead.
    """
    if len(spec) != len(args):
        return None
    out = list(args)
    for k, (code, ndim) in enumerate(spec):
        a = args[k]
        if ndim:
            if not isinstance(a, np.ndarray) or a.ndim != ndim:
                return None
            want = _DTYPE_OF[code]
            if a.dtype is not want and a.dtype != want:
                return None
            if not a.flags.c_contiguous:
                out[k] = np.ascontiguousarray(a)
        elif isinstance(a, np.ndarray) and a.ndim:
            return None
        else:
            out[k] = _SCALARS[code](a)
    return out


def _describe(args) -> str:
    return ", ".join(f"{a.dtype}{list(a.shape)}" if isinstance(a, np.ndarray) else type(a).__name__ for a in args)


def source_digest(root: Path = PACKAGE_DIR) -> str:
    """sha256 over this module and the kernel modules' sources (:data:`KERNEL_SOURCES` order)."""
    h = hashlib.sha256()
    for rel in ("kernels.py", *KERNEL_SOURCES):
        h.update(rel.encode() + b"\0" + (root / rel).read_bytes() + b"\0")
    return h.hexdigest()


def cpu_name() -> str:
    """This CPU's model and a digest of its feature flags: the extension is compiled for the
    building machine's instruction set, and a virtual machine may show the same model with fewer
    features."""
    model, flags = platform.processor(), ""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                key, _, value = line.partition(":")
                if key.strip() == "model name" and not flags:
                    model = value.strip()
                elif key.strip() in ("flags", "Features"):
                    flags = hashlib.sha256(" ".join(sorted(value.split())).encode()).hexdigest()[:12]
                    break
    except OSError:
        pass
    return f"{platform.machine()} {model} flags {flags or '?'}"


def _stamp() -> dict:
    return {"sources_sha256": source_digest(), "cpu": cpu_name()}


def _jit_forced() -> bool:
    return os.environ.get(MODE_ENV, "").strip().lower() == "jit"


def _load_extension():
    """The built extension module, or None (missing, stale, another CPU, or JIT asked for)."""
    if _jit_forced():
        return None
    try:
        ext = importlib.import_module(f"aicalib_tf.{EXTENSION}")
    except ImportError:
        return None
    try:
        built = json.loads(STAMP_FILE.read_text())
    except (OSError, ValueError):
        built = None
    if built != _stamp():
        warnings.warn(f"{Path(ext.__file__).name}: the compiled kernels were built from other sources or on "
                      "another CPU; using numba (just in time). Rebuild: python -m aicalib_tf.export --warm",
                      RuntimeWarning, stacklevel=3)
        return None
    return ext


_EXT = _load_extension()
MODE = "aot" if _EXT is not None else "jit"


def _numba():
    import numba  # noqa: PLC0415 -- only in JIT mode, or to build the extension

    return numba


def export_name(name: str, k: int) -> str:
    """The extension's name for signature k of kernel ``name``."""
    return f"{name}__{k}"


def kernel(*signatures: str):
    """Declare a compiled kernel: ``@kernel("f4[:, ::1], f8[:, ::1], i8")``, one string per signature.

    The decorated name becomes a checked call into the extension (AOT) or a numba dispatcher (JIT);
    the Python function stays at ``.py_func``.
    """
    specs = tuple(parse_signature(s) for s in signatures)

    def wrap(fn):
        name = fn.__name__
        if name in REGISTRY and REGISTRY[name][0] != fn.__module__:
            raise ValueError(f"kernel name {name!r} is declared in {REGISTRY[name][0]} and {fn.__module__}")
        REGISTRY[name] = (fn.__module__, fn, signatures)
        if _EXT is not None:
            targets = [getattr(_EXT, export_name(name, k)) for k in range(len(specs))]
        else:
            dispatcher = _numba().njit(cache=True, nogil=True)(fn)
            targets = [dispatcher] * len(specs)

        def call(*args):
            for spec, target in zip(specs, targets):
                ready = _prepared(spec, args)
                if ready is not None:
                    return target(*ready)
            raise TypeError(f"kernel {name}: arguments ({_describe(args)}) match none of its signatures {signatures}")

        call.__name__, call.__qualname__, call.__doc__ = name, fn.__qualname__, fn.__doc__
        call.__module__, call.py_func, call.signatures = fn.__module__, fn, signatures
        return call

    return wrap


def helper(fn):
    """Declare a function that only kernels call: a numba function in JIT mode and in the build,
    the plain Python function when the extension is in use (it is compiled inside the kernels)."""
    return fn if _EXT is not None else _numba().njit(cache=True, nogil=True)(fn)


def _import_kernel_modules() -> None:
    for rel in KERNEL_SOURCES:
        importlib.import_module("aicalib_tf." + rel[: -len(".py")].replace("/", "."))


def build_extension(directory: Path = PACKAGE_DIR) -> Path:
    """Compile every kernel signature into ``directory/_kernels_aot*.so`` and write its stamp; the path.

    Runs in JIT mode only (``AICALIB_KERNELS=jit``): it compiles the numba functions themselves.
    Each signature's return type is numba's own inference (a JIT compile, which also fills the
    on-disk JIT caches). Written to a temporary folder, then moved into place, stamp last.
    """
    import tempfile

    from aicalib_tf.io import atomic_write_text

    if _EXT is not None:
        raise RuntimeError(f"build_extension needs {MODE_ENV}=jit (this process loaded the extension)")
    numba = _numba()
    from numba.core import sigutils
    from numba.pycc import CC

    _import_kernel_modules()
    directory = Path(directory)
    with tempfile.TemporaryDirectory(dir=directory, prefix=".kernels-build-") as tmp:
        cc = CC(EXTENSION)
        cc.output_dir, cc.target_cpu, cc.verbose = tmp, "host", False
        for name, (_, fn, signatures) in sorted(REGISTRY.items()):
            dispatcher = numba.njit(cache=True, nogil=True)(fn)
            for k, sig in enumerate(signatures):
                args, _ = sigutils.normalize_signature(f"({sig},)")
                dispatcher.compile(tuple(args))
                cc.export(export_name(name, k), dispatcher.overloads[tuple(args)].signature)(fn)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # pycc's pending deprecation, and distutils' chatter
            cc.compile()
        (built,) = Path(tmp).glob(f"{EXTENSION}*")
        target = directory / built.name
        os.replace(built, target)
    atomic_write_text(directory / STAMP_FILE.name, json.dumps(_stamp()) + "\n")
    return target


def main() -> int:
    """``python -m aicalib_tf.kernels``: build the extension (in a child process in JIT mode). 0 if built."""
    import subprocess
    import time

    if _EXT is not None or not _jit_forced():
        env = dict(os.environ, **{MODE_ENV: "jit"})
        return subprocess.call([sys.executable, "-m", "aicalib_tf.kernels"], env=env)
    t0 = time.perf_counter()
    try:
        path = build_extension()
    except Exception as exc:  # no C compiler, or pycc failed: the JIT path still works
        print(f"compiled kernels not built ({type(exc).__name__}: {exc}); detection uses numba's JIT caches",
              file=sys.stderr)
        return 1
    print(f"compiled kernels: {path.name} ({len(REGISTRY)} kernels) in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":  # run as a script, this file is __main__: the kernels register in aicalib_tf.kernels
    from aicalib_tf.kernels import main as _main

    sys.exit(_main())
