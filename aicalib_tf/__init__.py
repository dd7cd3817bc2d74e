"""aicalib_tf: AI-based camera calibration.

Public API (this package imports without TensorFlow; Keras loads only where a model is used):

* :func:`load_image` — the one input gate: path or array -> (H, W) float32 grey in [0, 1].
* :class:`ImageError` — raised for unusable images, naming the file.
* :func:`detect_corners` -> :class:`Detection` — a chessboard's inner corners, full or partial.
* :func:`find_chessboard_corners` — a drop-in for ``cv2.findChessboardCorners``.
* :func:`calibrate_camera` (:class:`View` in) -> :class:`Calibration` (``save``/``load``).
* :func:`undistort` — remove lens distortion with a calibration.
* :func:`load_model` — the shipped CNNs ("default", "report") or a ``.keras`` path, safe mode.
"""

from .io import ImageError, load_image

# Loaded on first use, so that ``python -m aicalib_tf.detect`` (or .calibrate) does not find its
# own module already imported by the package, and ``import aicalib_tf`` stays light.
_LAZY = {
    "Calibration": "calibration", "CalibrationError": "calibration", "View": "calibration",
    "calibrate_camera": "calibration", "undistort": "calib_io",
    "Detection": "detect", "detect_corners": "detect", "find_chessboard_corners": "detect",
}

__all__ = [
    "Calibration", "CalibrationError", "Detection", "ImageError", "View", "calibrate_camera", "detect_corners",
    "find_chessboard_corners", "load_image", "load_model", "undistort", "__version__",
]
__version__ = "0.1.0"


def load_model(weights="default", *, compile: bool = False):
    """Load a corner CNN (see :func:`aicalib_tf.model.load_model`); imports TensorFlow on first use."""
    from .model import load_model as _load

    return _load(weights, compile=compile)


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module 'aicalib_tf' has no attribute {name!r}")
