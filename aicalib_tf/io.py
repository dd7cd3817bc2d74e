"""The one input gate for images, and atomic file writes.

Every image enters through :func:`load_image` (a path or an array; uint8 or uint16; grey, BGR
or BGRA) and leaves as float32 grey in [0, 1]. Every output file is written through
:func:`atomic_write_bytes` / :func:`atomic_write_text`: a temporary file in the same folder,
then ``os.replace``, so a reader never sees half a file.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import cv2
import numpy as np

__all__ = ["ImageError", "load_image", "to_gray_float", "expand_images", "atomic_write_bytes", "atomic_write_text"]


class ImageError(ValueError):
    """An image that cannot be used; the message names the file (or says 'array') and why."""


def to_gray_float(image: np.ndarray, name: str = "array") -> np.ndarray:
    """Convert an image array to (H, W) float32 grey in [0, 1].

    image : (H, W), (H, W, 1), (H, W, 3) BGR or (H, W, 4) BGRA; uint8, uint16, or float in [0, 1].
    """
    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] not in (3, 4)):
        raise ImageError(f"{name}: expected (H, W) grey or (H, W, 3|4) colour, got shape {a.shape}")
    if a.shape[0] < 1 or a.shape[1] < 1:
        raise ImageError(f"{name}: empty image, shape {a.shape}")
    if a.dtype == np.uint8:
        scale = 1.0 / 255.0
    elif a.dtype == np.uint16:
        scale = 1.0 / 65535.0
    elif a.dtype in (np.float32, np.float64):
        if not np.all(np.isfinite(a)):
            raise ImageError(f"{name}: float image contains NaN or inf")
        lo, hi = float(a.min()), float(a.max())
        if lo < -1e-3 or hi > 1.0 + 1e-3:  # e.g. 0–255 values in a float array
            raise ImageError(f"{name}: float image must be in [0, 1], got values from {lo:g} to {hi:g}")
        scale = 1.0
    else:
        raise ImageError(f"{name}: unsupported dtype {a.dtype}; use uint8, uint16 or float in [0, 1]")
    a = a.astype(np.float32) * np.float32(scale)
    if a.ndim == 3:
        code = cv2.COLOR_BGRA2GRAY if a.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        a = cv2.cvtColor(a, code)
    return np.clip(a, 0.0, 1.0)


def load_image(src) -> np.ndarray:
    """Read a path (any format OpenCV reads) or take an array; return (H, W) float32 grey in [0, 1].

    Raises :class:`ImageError` naming the file for a missing, unreadable or corrupt file.
    """
    if isinstance(src, (str, os.PathLike)):
        path = Path(src)
        if not path.is_file():
            raise ImageError(f"{path}: no such file")
        data = np.fromfile(path, dtype=np.uint8)
        if data.size == 0:
            raise ImageError(f"{path}: empty file")
        if _truncated_jpeg(data.tobytes()):
            raise ImageError(f"{path}: truncated JPEG (the image data ends without an end-of-image marker)")
        img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
        if img is None:
            raise ImageError(f"{path}: not a readable image (corrupt or unsupported format)")
        return to_gray_float(img, str(path))
    return to_gray_float(src)


def _truncated_jpeg(data: bytes) -> bool:
    """A JPEG whose last scan (after the last SOS marker, FF DA) has no end-of-image marker (FF D9).

    OpenCV decodes such files with a warning and grey fill; we refuse them. Markers cannot occur
    inside entropy-coded data (0xFF is stuffed there), and an EXIF thumbnail's EOI comes before
    the main image's scans, so it cannot mask a truncated main image.
    """
    if not data.startswith(b"\xff\xd8"):
        return False
    sos = data.rfind(b"\xff\xda")
    return sos < 0 or data.find(b"\xff\xd9", sos) < 0


def expand_images(patterns) -> list[str]:
    """Paths and glob patterns -> a sorted, de-duplicated list of paths (order of the patterns kept).

    A pattern with ``*``, ``?`` or ``[`` is globbed (``**`` recurses); anything else is taken as a
    path, whether or not it exists (the loader reports missing files by name).
    """
    import glob

    out: list[str] = []
    seen: set[str] = set()
    for item in [patterns] if isinstance(patterns, (str, os.PathLike)) else patterns:
        item = str(item)
        matches = sorted(glob.glob(item, recursive=True)) if any(ch in item for ch in "*?[") else [item]
        for m in matches:
            if m not in seen:
                seen.add(m)
                out.append(m)
    return out


def atomic_write_bytes(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file in the same folder, then rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def atomic_write_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def quantize(img: np.ndarray) -> np.ndarray:
    """Clip to [0, 1] and round to uint8, like a sensor's ADC. Returns (H, W) uint8."""
    return np.clip(np.rint(img * 255.0), 0, 255).astype(np.uint8)


