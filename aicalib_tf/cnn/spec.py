"""What every side of the corner CNNs shares, importing neither TensorFlow nor Keras: the
architecture names, the patch size, where the shipped models live, a model's kind and file hashes."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

__all__ = ["ARCHITECTURES", "SHIPPED", "RUNTIME_FILES", "QUICK_NETWORKS", "DETECTOR_NETWORK",
           "NETWORK_HELP", "PATCH_SIZE", "MODELS_DIR", "model_kind", "file_sha256", "expected_sha256",
           "check_model_file", "write_sha256"]

ARCHITECTURES = ("default", "report", "default_v1", "default_c12", "default_c16", "default_pre",
                 "sep", "sep_s2", "sep_w", "sep_s2w", "quick")
SHIPPED = ("default", "report", "quick")  # the models shipped in models/ as .keras and .tflite
# every shipped runtime file (models/<name>.tflite) -> the .keras model it is exported from; default_int8
# and quick_int8 are default and quick post-training quantised to int8 (weights and activations),
# calibrated on data_gen renders
RUNTIME_FILES = {"default": "default", "report": "report", "default_int8": "default", "quick": "quick",
                 "quick_int8": "quick"}
# a shipped detector network -> the smaller network its quick passes run (the coarse scales where only a
# complete board counts, see aicalib_tf.detect.pyramid.quick_scales); the finer scales run the network itself
QUICK_NETWORKS = {"default": "quick", "default_int8": "quick_int8"}
# the network the detector runs when none is named (detect_corners, every command line): int8, whose
# detections match the float network's (benchmarks/int8_detection.py) in about 2/3 of the time
DETECTOR_NETWORK = "default_int8"
NETWORK_HELP = ("the cnn detector's network: default_int8 (the default), default (the same network in float32, "
                "the same detections, slower), report, or a .tflite/.keras path")
PATCH_SIZE = 32
MODELS_DIR = Path(os.environ.get("AICALIB_MODELS", Path(__file__).resolve().parents[2] / "models"))


def model_kind(model) -> str:
    """``"map"`` for a fully convolutional corner-map model, ``"patch"`` for a patch classifier.

    model : a Keras model or a :class:`aicalib_tf.cnn.runtime.RuntimeModel` (its ``kind``).
    Raises ``ValueError`` for a model with neither interface.
    """
    kind = getattr(model, "kind", None)
    if kind in ("map", "patch") and not hasattr(model, "input_shape"):
        return kind
    shape_in = tuple(model.input_shape)
    shape_out = tuple(model.output_shape)
    if len(shape_in) == 4 and shape_in[3] == 1 and shape_in[1] is None and shape_out[1:] == (None, None, 3):
        return "map"
    if shape_in[1:] == (PATCH_SIZE, PATCH_SIZE, 1) and shape_out[1:] == (1,):
        return "patch"
    raise ValueError(
        f"model {model.name!r} has input {shape_in} and output {shape_out}; expected a corner-map model "
        f"(None, None, None, 1) -> (None, None, None, 3) or a patch classifier (None, {PATCH_SIZE}, {PATCH_SIZE}, 1) -> (None, 1)"
    )


def file_sha256(path: str | os.PathLike) -> str:
    """Hex sha256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def expected_sha256(path: str | os.PathLike) -> str | None:
    """The sha256 recorded beside a model file (``<file>.sha256``, sha256sum's format: first word), or None."""
    side = Path(str(path) + ".sha256")
    if not side.is_file():
        return None
    text = side.read_text(encoding="ascii", errors="replace").split()
    return text[0].lower() if text else None


_REMEDY = {".tflite": "re-create it with `python -m aicalib_tf.export`",
           ".keras": "restore it (git checkout) or train it again (`python -m aicalib_tf.train`)"}


def check_model_file(path: str | os.PathLike, *, check_sha256: bool = True) -> str | None:
    """Check that a model file exists and matches the sha256 recorded beside it; returns that sha256 (or None).

    Raises ``FileNotFoundError`` or ``ValueError`` in one line naming the file, the expected sha256
    and what to do.
    """
    path = Path(path)
    want = expected_sha256(path)
    remedy = _REMEDY.get(path.suffix, "expected a .tflite or .keras file")
    if not path.is_file():
        expect = f" (expected sha256 {want})" if want else ""
        raise FileNotFoundError(f"model file not found: {path}{expect}; {remedy}")
    if check_sha256 and want:
        got = file_sha256(path)
        if got != want:
            raise ValueError(f"corrupt model file {path}: sha256 {got}, expected {want}; {remedy}")
    return want


def write_sha256(path: str | os.PathLike) -> str:
    """Write ``<path>.sha256`` (sha256sum's format), atomically, and return the hash."""
    from aicalib_tf.io import atomic_write_text

    sha = file_sha256(path)
    atomic_write_text(Path(str(path) + ".sha256"), f"{sha}  {Path(path).name}\n")
    return sha
