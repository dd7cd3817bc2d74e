"""aicalib_tf: AI-based camera calibration.

Public API (this package imports without TensorFlow; Keras loads only where a model is used):

* :func:`load_image` — the one input gate: path or array -> (H, W) float32 grey in [0, 1].
* :class:`ImageError` — raised for unusable images, naming the file.
"""

from .io import ImageError, load_image

__all__ = ["ImageError", "load_image", "__version__"]
__version__ = "0.1.0"
