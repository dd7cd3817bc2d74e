"""aicalib_tf: AI-based camera calibration.

Public API (this package imports without TensorFlow; Keras loads only where a model is used):

* :func:`load_image` — the one input gate: path or array -> (H, W) float32 grey in [0, 1].
* :class:`ImageError` — raised for unusable images, naming the file.
* :func:`detect_corners` -> :class:`Detection` — a chessboard's inner corners, full or partial.
* :func:`find_chessboard_corners` — a drop-in for ``cv2.findChessboardCorners``.
* :class:`Tracker` — detection through a stream of video frames, searching near the last board first.
* :func:`calibrate_camera` (:class:`View` in) -> :class:`Calibration`;
  :func:`save_calibration` / :func:`load_calibration` write and read its files.
* :func:`undistort` — remove lens distortion with a calibration.
* :func:`check_calibration` — does a calibration still hold for new views? (the field check).
* :func:`load_model` — the shipped CNNs ("default", "report") or a ``.keras`` path, safe mode.

The package's rooms (``docs/architecture.md``): :mod:`~aicalib_tf.geometry` (patterns, lens
models, poses), :mod:`~aicalib_tf.cnn` (the network; the only TensorFlow user),
:mod:`~aicalib_tf.detect` (image -> board), :mod:`~aicalib_tf.calib` (views -> camera -> files),
:mod:`~aicalib_tf.bench` (the benchmark). ``train``, ``evaluate``, ``calibrate``, ``check`` and
``detect`` are the command lines.
"""

# importing the image gate first sets OpenCV's pixel cap and log level before OpenCV loads
from aicalib_tf.io import ImageError, load_image

# Loaded on first use, so that ``import aicalib_tf`` stays light (no numba kernels, no OpenCV
# calibration code) until a name is asked for.
_LAZY = {
    "Calibration": "calib.fit", "CalibrationError": "calib.fit", "View": "calib.fit",
    "calibrate_camera": "calib.fit", "undistort": "calib.files", "save_calibration": "calib.files",
    "load_calibration": "calib.files", "check_calibration": "calib.check",
    "Detection": "detect.pipeline", "detect_corners": "detect.pipeline", "find_chessboard_corners": "detect.dropin",
    "Tracker": "detect.track",
}

__all__ = [
    "Calibration", "CalibrationError", "Detection", "ImageError", "Tracker", "View", "calibrate_camera",
    "check_calibration", "detect_corners",
    "find_chessboard_corners", "load_calibration", "load_image", "load_model", "save_calibration", "undistort",
    "__version__",
]
__version__ = "0.2.0"


def load_model(weights="default", *, compile: bool = False):
    """Load a corner CNN (see :func:`aicalib_tf.cnn.model.load_model`); imports TensorFlow on first use."""
    from aicalib_tf.cnn.model import load_model as _load

    return _load(weights, compile=compile)


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f"aicalib_tf.{_LAZY[name]}"), name)
    raise AttributeError(f"module 'aicalib_tf' has no attribute {name!r}")
