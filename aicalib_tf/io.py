"""The one input gate for images, and atomic file writes.

Every image enters through :func:`load_image` (a path or an array; uint8 or uint16; grey, BGR
or BGRA) and leaves as float32 grey in [0, 1]; :func:`read_image` checks it the same way and leaves it
unconverted, for a stage that converts only the part it needs (:class:`aicalib_tf.detect.pyramid.Frame`). A file is read as bytes (any file name works) and
its pixel count is checked from the header before anything is decoded: an image over
:data:`MAX_PIXELS` (100 MP; ``AICALIB_MAX_PIXELS`` changes it) is refused without allocating it. Every output file is written through
:func:`atomic_write_bytes` / :func:`atomic_write_text`: a temporary file in the same folder,
then ``os.replace``, so a reader never sees half a file.
"""

from __future__ import annotations

import os
import re
import tempfile
from pathlib import Path

MAX_PIXELS = 100_000_000  # the largest image accepted (px); the environment's AICALIB_MAX_PIXELS overrides it
# Before OpenCV loads: its decoders' own pixel cap (a backstop for formats whose header the gate
# cannot read), and no decoder warnings on stderr (the gate reports an unreadable image once, by name).
os.environ.setdefault("OPENCV_IO_MAX_IMAGE_PIXELS", str(MAX_PIXELS))
os.environ.setdefault("OPENCV_LOG_LEVEL", "FATAL")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["ImageError", "load_image", "read_image", "to_gray_float", "checked_image", "as_gray_float", "expand_images",
           "atomic_write_bytes", "atomic_write_text",
           "display_name", "redact_credentials", "max_pixels", "image_size_from_header", "IMAGE_SUFFIXES", "MAX_PIXELS"]

MAX_FILE_BYTES = 2 << 30  # an image file larger than this is refused before it is read
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".pgm", ".ppm", ".pbm", ".pnm", ".jp2",
                  ".exr", ".hdr", ".sr", ".ras", ".pxm", ".pfm")  # what OpenCV decodes; a folder stands for these


class ImageError(ValueError):
    """An image that cannot be used; the message names the file (or says 'array') and why."""


def checked_image(image: np.ndarray, name: str = "array") -> np.ndarray:
    """The image gate's checks on an array, without converting it.

    image : (H, W), (H, W, 1), (H, W, 3) BGR or (H, W, 4) BGRA; uint8, uint16, or float in [0, 1].
    Returns the same array ((H, W, 1) as (H, W)); raises :class:`ImageError` naming ``name``.
    """
    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] not in (3, 4)):
        raise ImageError(f"{name}: expected (H, W) grey or (H, W, 3|4) colour, got shape {a.shape}")
    if a.shape[0] < 1 or a.shape[1] < 1:
        raise ImageError(f"{name}: empty image, shape {a.shape}")
    if a.dtype in (np.float32, np.float64):
        if not np.all(np.isfinite(a)):
            raise ImageError(f"{name}: float image contains NaN or inf")
        lo, hi = float(a.min()), float(a.max())
        if lo < -1e-3 or hi > 1.0 + 1e-3:  # e.g. 0–255 values in a float array
            raise ImageError(f"{name}: float image must be in [0, 1], got values from {lo:g} to {hi:g}")
    elif a.dtype not in (np.uint8, np.uint16):
        raise ImageError(f"{name}: unsupported dtype {a.dtype}; use uint8, uint16 or float in [0, 1]")
    return a


def as_gray_float(a: np.ndarray) -> np.ndarray:
    """A :func:`checked_image` array (or any region of one) as (H, W) float32 grey in [0, 1].

    A new array (the caller's is never changed). Each pixel's value depends on that pixel alone, so a
    region converted on its own equals the same region of the whole image converted (grey exactly,
    colour within 1e-7: OpenCV's conversion rounds the last pixels of a row in another order).
    """
    scale = {np.dtype(np.uint8): 1.0 / 255.0, np.dtype(np.uint16): 1.0 / 65535.0}.get(a.dtype, 1.0)
    exact = a.ndim == 2 and a.dtype.kind == "u"  # integer grey: already in [0, 1] once scaled
    # one pass; float input has scale 1
    a = a.astype(np.float32) if a.dtype.kind == "f" else np.multiply(a, np.float32(scale), dtype=np.float32)
    if a.ndim == 3:
        code = cv2.COLOR_BGRA2GRAY if a.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        a = cv2.cvtColor(a, code)
    return a if exact else np.clip(a, 0.0, 1.0, out=a)


def to_gray_float(image: np.ndarray, name: str = "array") -> np.ndarray:
    """Convert an image array to (H, W) float32 grey in [0, 1] (:func:`checked_image`, then
    :func:`as_gray_float`)."""
    return as_gray_float(checked_image(image, name))


def display_name(path) -> str:
    """A path as text that prints on any terminal (undecodable bytes of a file name shown as \\xNN)."""
    text = os.fsdecode(path) if isinstance(path, bytes) else str(path)
    return text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")


_CREDENTIALS = re.compile(r"(?i)\b([a-z][a-z0-9+.-]*://[^/\s:@]*):[^/\s]*@")  # the last @ ends the password


_SECRET_QUERY = re.compile(r"(?i)([?&;](?:password|passwd|pass|pwd|token|access_token|key|api_?key|secret|auth)=)"
                           r"[^&;#\s]*?(?=[&;#\s]|:\s|:$|$)")  # a value ends before a message's ": "


def redact_credentials(text: str) -> str:
    """``text`` with the password of every URL in it replaced by ``***`` (``rtsp://user:***@host/``), and
    the value of a query field that holds one (``?password=``, ``&token=``, ...), for anything printed or
    written: messages, reports, a calibration's ``source``."""
    return _SECRET_QUERY.sub(r"\1***", _CREDENTIALS.sub(r"\1:***@", str(text)))


def max_pixels() -> int:
    """The pixel cap: :data:`MAX_PIXELS`, or ``AICALIB_MAX_PIXELS`` from the environment."""
    text = os.environ.get("AICALIB_MAX_PIXELS", "")
    try:
        value = int(float(text)) if text else MAX_PIXELS
    except ValueError:
        raise ValueError(f"AICALIB_MAX_PIXELS must be a number of pixels, got {text!r}") from None
    if value < 1:
        raise ValueError(f"AICALIB_MAX_PIXELS must be positive, got {text!r}")
    return value


def image_size_from_header(data: bytes) -> tuple[int, int] | None:
    """(width, height) from an image file's header, without decoding its pixels; None if unknown.

    Pillow reads the header of every common format lazily; its own size limit is lifted for the
    read, because the caller applies :func:`max_pixels`.
    """
    import io as _io
    import warnings

    from PIL import Image

    old = Image.MAX_IMAGE_PIXELS
    Image.MAX_IMAGE_PIXELS = None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(_io.BytesIO(data)) as im:
                return int(im.size[0]), int(im.size[1])
    except Exception:  # noqa: BLE001 - any format Pillow does not know: OpenCV decides below
        return None
    finally:
        Image.MAX_IMAGE_PIXELS = old


def _read_bytes(path: Path) -> np.ndarray:
    name = display_name(path)
    try:
        if not path.is_file():
            raise ImageError(f"{name}: {'a folder, not an image' if path.is_dir() else 'no such file'}")
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ImageError(f"{name}: file of {size / 2**30:.1f} GiB is larger than an image this tool reads")
        return np.fromfile(path, dtype=np.uint8)
    except OSError as exc:
        raise ImageError(f"{name}: {exc.strerror or exc}") from None


def load_image(src) -> np.ndarray:
    """Read a path (any format OpenCV reads) or take an array; return (H, W) float32 grey in [0, 1].

    Raises :class:`ImageError` as :func:`read_image` does.
    """
    return as_gray_float(read_image(src))


def read_image(src) -> np.ndarray:
    """Read a path (any format OpenCV reads) or take an array; return it checked (:func:`checked_image`)
    and unconverted: (H, W) or (H, W, 3|4) BGR(A), uint8, uint16 or float in [0, 1].

    Raises :class:`ImageError` naming the file for a missing, unreadable (permissions), corrupt,
    truncated or too large (over :func:`max_pixels`) file.
    """
    if isinstance(src, (str, bytes, os.PathLike)):
        path = Path(os.fsdecode(src))
        name = display_name(path)
        data = _read_bytes(path)
        if data.size == 0:
            raise ImageError(f"{name}: empty file")
        raw = data.tobytes()
        if _truncated_jpeg(raw):
            raise ImageError(f"{name}: truncated JPEG (the image data ends without an end-of-image marker)")
        size, cap = image_size_from_header(raw), max_pixels()
        if size is not None and size[0] * size[1] > cap:
            raise ImageError(f"{name}: image of {size[0]}x{size[1]} px is over the limit of {cap / 1e6:g} MP "
                             "(set AICALIB_MAX_PIXELS to allow it)")
        try:
            img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
        except cv2.error as exc:
            raise ImageError(f"{name}: not a readable image ({' '.join(str(exc).split())[-120:]})") from None
        if img is None:
            raise ImageError(f"{name}: not a readable image (corrupt or unsupported format)")
        if img.shape[0] * img.shape[1] > cap:
            raise ImageError(f"{name}: image of {img.shape[1]}x{img.shape[0]} px is over the limit of {cap / 1e6:g} MP")
        return checked_image(img, name)
    return checked_image(src)


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

    An existing file is taken as it is, even when its name holds ``[`` or ``*``; a folder stands
    for the image files in it (by suffix, :data:`IMAGE_SUFFIXES`); a pattern with ``*``, ``?`` or
    ``[`` is globbed (``**`` recurses, each real folder once, so a symbolic-link loop ends:
    :func:`_recursive_glob`); anything else is taken as a path, whether or not it exists (the loader
    reports missing files by name).
    """
    import glob

    out: list[str] = []
    seen: set[str] = set()
    for item in [patterns] if isinstance(patterns, (str, os.PathLike)) else patterns:
        item = os.fspath(item)
        if os.path.isdir(item):
            matches = sorted(str(p) for p in Path(item).iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file())
        elif os.path.isfile(item) or not any(ch in item for ch in "*?["):
            matches = [item]
        elif "**" in Path(item).parts:
            matches = sorted(_recursive_glob(item))
        else:
            matches = sorted(glob.glob(item))
        for m in matches:
            if m not in seen:
                seen.add(m)
                out.append(m)
    return out


def _recursive_glob(pattern: str) -> list[str]:
    """The paths a pattern with a ``**`` component matches, as ``glob.glob(pattern, recursive=True)``
    gives them (``**`` is zero or more folders; wildcards skip hidden names), except that every real
    folder is walked once: the part before the first ``**`` is globbed as usual (no recursion), then
    under each folder it names, first the folders by their own paths, then each linked folder not
    walked yet, by the first link to it (sorted, nearest first). A symbolic-link loop therefore ends
    instead of recursing until the path is too long."""
    import fnmatch
    import glob

    parts = Path(pattern).parts
    k = parts.index("**")
    prefix, pats = (os.path.join(*parts[:k]) if k else ""), [_part_matcher(p, fnmatch) for p in parts[k:]]
    tops = sorted(glob.glob(prefix)) if any(ch in prefix for ch in "*?[") else [prefix]
    out: list[str] = []
    seen: set = set()  # (device, inode) of the folders walked or about to be
    for top in tops:
        _walk_once(top, pats, seen, out)
    return out


def _walk_once(root: str, pats: list, seen: set, out: list) -> None:
    """Append to ``out`` the paths under ``root`` ("" for the current folder) whose components below it
    match ``pats``, entering only folders a match can lie under, none in ``seen``, and adding each one
    entered (:func:`_recursive_glob`). Iterative (any depth); an unreadable folder is skipped, as glob
    skips it."""
    end = len(pats)
    links = [(root or os.curdir, [], _closure({0}, pats))]  # (folder, its components under root, pattern states)
    while links:
        start, above, states = links.pop(0)
        key = _folder_key(start)
        if key is None or key in seen:
            continue
        seen.add(key)
        stack = [(start, above, states)]
        while stack:
            folder, base, states = stack.pop()
            try:
                with os.scandir(folder) as it:
                    entries = sorted(it, key=lambda e: e.name)
            except OSError:
                continue
            inner = []
            for e in entries:
                after = _step(states, e.name, pats)
                if end in after:
                    out.append(os.path.join(root, *base, e.name))
                if not any(s < end for s in after):
                    continue  # nothing below can match
                if e.is_symlink():
                    if e.is_dir():
                        links.append((e.path, [*base, e.name], after))
                elif e.is_dir(follow_symlinks=False) and (k := _folder_key(e.path)) is not None and k not in seen:
                    seen.add(k)
                    inner.append((e.path, [*base, e.name], after))
            stack.extend(reversed(inner))


def _folder_key(path) -> tuple[int, int] | None:
    """(device, inode) of a folder, None when it cannot be read."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


def _part_matcher(part: str, fnmatch):
    """A pattern component as ``"**"`` or a predicate on one name (hidden names only for a pattern starting with '.')."""
    if part == "**":
        return part
    if not any(ch in part for ch in "*?["):
        return lambda name: name == part
    rx = re.compile(fnmatch.translate(part))
    return lambda name: (part.startswith(".") or not name.startswith(".")) and rx.match(name) is not None


def _closure(states: set, pats: list) -> frozenset:
    """Pattern positions ``states`` and those a ``**`` matching no folder leads to."""
    out = set(states)
    for s in states:
        while s < len(pats) and pats[s] == "**":
            s += 1
            out.add(s)
    return frozenset(out)


def _step(states: frozenset, name: str, pats: list) -> frozenset:
    """The pattern positions after one more path component ``name`` (``**`` takes any non-hidden name and stays)."""
    nxt = set()
    for s in states:
        if s < len(pats):
            if pats[s] == "**":
                if not name.startswith("."):
                    nxt.add(s)
            elif pats[s](name):
                nxt.add(s + 1)
    return _closure(nxt, pats)


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


