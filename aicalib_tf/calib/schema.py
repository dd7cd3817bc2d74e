"""What the calibration loaders accept: the text before OpenCV parses it, and every field after.

Before ``cv2.FileStorage`` sees a YAML file, :func:`read_opencv_yaml` reads it through
:func:`aicalib_tf.jsonio.read_text` (size cap, UTF-8, no NUL bytes), refuses XML, and bounds its
nesting by a text scan (:func:`yaml_depth`: block indentation and ``- `` levels plus flow brackets
outside quoted strings), because OpenCV's parser recurses once per level and a file nested a few
thousand deep crashes the process. It parses from memory (the bytes checked are the bytes parsed),
turns OpenCV's parse errors into a ValueError, and converts only the nodes asked for: a matrix
needs rows × cols values and a known ``dt``; integer ``dt`` values are read exactly (a ``dt: u``
matrix is refused rather than clamped to 255). The only YAML tag read is ``!!opencv-matrix``: a
``!!binary`` (base64) node can send OpenCV's reader into an endless loop.

After parsing, the ``require_*`` helpers check one field each (type, shape, finite values,
ranges) and raise :class:`FieldError` naming it: ``field board.square_size must be a positive
finite number, got -25``; :func:`within` prefixes the field of a nested record
(``cameras[1].board.square_size``). The loaders add the file's name in front.
"""

from __future__ import annotations

import math
import re
from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np

from aicalib_tf.geometry import lens as L
from aicalib_tf.jsonio import MAX_DEPTH, bracket_depth, read_text

__all__ = ["FieldError", "within", "file_errors", "MAX_DEPTH", "MAX_IMAGE_SIDE", "MAX_PATTERN_SIDE", "ROTATION_TOL", "yaml_depth",
           "read_opencv_yaml", "require", "require_mapping", "require_list", "require_str", "require_int",
           "require_number", "require_matrix", "require_vector", "require_camera_matrix", "require_rotation",
           "require_dist", "require_image_size", "require_board", "require_model", "require_item"]

MAX_IMAGE_SIDE = 100_000  # px: the widest or tallest image a calibration file may describe
MAX_PATTERN_SIDE = 10_000  # inner corners along one side of a board
ROTATION_TOL = 1e-6  # max |RᵀR − I| and |det R − 1| of a rotation read from a file (written with 16 digits)
_INT_DTYPES = {"u": (0, 255), "c": (-128, 127), "w": (0, 65535), "s": (-32768, 32767), "i": (-2**31, 2**31 - 1)}
_FLOAT_DTYPES = ("d", "f")
_MAX_ELEMENTWISE = 100_000  # integer (and dt-less ROS) matrices are read value by value; larger ones are refused
_MISSING = object()

# a quoted scalar where YAML lets one start (group 1: line start, a flow indicator, or ": ", "- ", "? "
# before it); an unclosed quote runs to the end of its line
_YAML_QUOTED = re.compile(r"(?m)(^|[,\[{]|[:?\-][ \t])[ \t]*"
                          r"(?:\"(?:[^\"\\\n]+|\\.)*(?:\"|$)|'(?:[^'\n]+|'')*(?:'|$))")
_YAML_LINE = re.compile(r"(?m)^([ \t]*(?:-[ \t]+)*)(\S?)")
_OTHER_TAG = re.compile(r"!!(?!opencv-matrix(?![\w-]))\S*")  # any tag but !!opencv-matrix (e.g. !!binary)


class FieldError(ValueError):
    """A field of a calibration file that is missing or wrong; ``str`` is ``field <name> <problem>``."""

    def __init__(self, field: str, problem: str):
        super().__init__(f"field {field} {problem}")
        self.field, self.problem = field, problem


@contextmanager
def within(prefix: str):
    """Inside, a :class:`FieldError` on field ``x`` becomes one on ``<prefix>.x``."""
    try:
        yield
    except FieldError as exc:
        raise FieldError(f"{prefix}.{exc.field}", exc.problem) from None


@contextmanager
def file_errors(path, what: str):
    """Inside, every ValueError becomes one line that starts with the file: ``<path>: field <name>
    <problem>`` for a :class:`FieldError`, ``<path>: not a valid <what> (<why>)`` for any other
    (one that already starts with the path is kept)."""
    try:
        yield
    except FieldError as exc:
        raise ValueError(f"{path}: {exc}") from None
    except ValueError as exc:
        if str(exc).startswith(f"{path}: "):
            raise
        raise ValueError(f"{path}: not a valid {what} ({exc})") from None


def _short(value, limit: int = 80) -> str:
    text = np.array2string(value, threshold=12, max_line_width=10**6) if isinstance(value, np.ndarray) else repr(value)
    text = " ".join(text.split())
    return text if len(text) <= limit else text[:limit - 3] + "..."


# ----------------------------------------------------------------------------- YAML before OpenCV
def _block_depth(text: str) -> int:
    """Levels of block structure (an upper bound): each deeper indentation and each ``- `` on a line opens one."""
    for bound in (8, 16, 32):  # no line indented by ``bound`` columns of spaces and dashes: at most that many levels
        if not re.search(rf"(?m)^[ \t-]{{{bound}}}", text):
            return bound
    stack, deepest = [], 0
    for prefix, first in _YAML_LINE.findall(text):
        if not first or first == "#":
            continue
        for col in [m.start() for m in re.finditer("-", prefix)] + [len(prefix)]:
            while stack and stack[-1] > col:
                stack.pop()
            if not stack or stack[-1] < col:
                stack.append(col)
        deepest = max(deepest, len(stack))
        if deepest > MAX_DEPTH:
            break
    return deepest


def yaml_depth(text: str) -> int:
    """An upper bound on the nesting depth of YAML (or OpenCV's JSON) text, block levels plus flow
    brackets ``[{`` outside quoted strings, while it is at most :data:`MAX_DEPTH`; past that, some
    number over :data:`MAX_DEPTH` (the block scan stops early)."""
    block = _block_depth(text)
    opens = text.count("[") + text.count("{")
    if opens + block <= MAX_DEPTH or ('"' not in text and "'" not in text):  # no quoted string to skip
        return block + min(opens, bracket_depth(text.encode("utf-8", "surrogatepass")))
    return block + bracket_depth(_YAML_QUOTED.sub(r"\1", text).encode("utf-8", "surrogatepass"))


def _values(data, n: int, field: str) -> np.ndarray:
    """The n numbers of a sequence node, one by one (NaN for a non-number)."""
    if n > _MAX_ELEMENTWISE:
        raise FieldError(field, f"has {n} values; a matrix this large must be written as dt: d")
    items = [data.at(k) for k in range(n)]
    return np.array([v.real() if v.isInt() or v.isReal() else math.nan for v in items], np.float64)


def _matrix(node, field: str) -> np.ndarray:
    """An ``!!opencv-matrix`` node (or ROS's rows/cols/data matrix, without dt) as a (rows, cols) float64 array."""
    rows, cols, dt, data = (node.getNode(k) for k in ("rows", "cols", "dt", "data"))
    if not (rows.isInt() and cols.isInt() and (dt.empty() or dt.isString()) and data.isSeq()):
        raise FieldError(field, "must be an OpenCV matrix (rows, cols, dt, data)")
    r, c, kind = int(rows.real()), int(cols.real()), "" if dt.empty() else dt.string()
    if not (0 <= r <= 10**7 and 0 <= c <= 10**7) or r * c != data.size():
        raise FieldError(field, f"has {data.size()} values for {r}x{c}")
    if r * c == 0:
        return np.zeros((r, c))
    if kind in _FLOAT_DTYPES:
        try:
            return np.asarray(node.mat(), np.float64).reshape(r, c)
        except (cv2.error, SystemError, ValueError, TypeError):
            raise FieldError(field, "must hold numbers") from None
    if kind and kind not in _INT_DTYPES:
        raise FieldError(field, f"has dt {kind!r}; expected d or f (float64 or float32)")
    out = _values(data, r * c, field)
    lo, hi = _INT_DTYPES.get(kind, (-math.inf, math.inf))
    if kind and not np.all((out >= lo) & (out <= hi) & (out == np.round(out))):
        raise FieldError(field, f"has dt {kind!r}, which cannot hold its values exactly (integers {lo}..{hi}); "
                                "write it as dt: d")
    return out.reshape(r, c)


def _node_value(node, field: str):
    """A top-level node as Python: int, float, str, (rows, cols) float64 array, None when empty."""
    if node.empty() or node.isNone():
        return None
    if node.isInt() or node.isReal():
        v = node.real()
        return int(v) if node.isInt() and math.isfinite(v) else v
    if node.isString():
        return node.string()
    if node.isMap() and {"rows", "cols", "data"} <= set(node.keys()):
        return _matrix(node, field)
    raise FieldError(field, "must be a number, a string or an OpenCV matrix")


def _parse_error(exc: BaseException) -> str:
    """"line N: why" from OpenCV's parse error (raised as the cause of a SystemError). Parsing from
    memory, OpenCV puts the text where the file name would be: only what follows it is kept."""
    inner = exc.__cause__ or exc.__context__ or exc
    found = re.search(r"\((\d+)\): ([^\n]*?)'?\s*$", str(getattr(inner, "func", "") or ""))
    return f"line {found[1]}: {found[2][:120]}" if found else "parse error"


def read_opencv_yaml(path, keys) -> dict:
    """{key: value} of the top-level ``keys`` present in an OpenCV FileStorage YAML file (values as in
    :func:`_node_value`). ValueError naming the file when it is too large, too deep, XML or not
    parseable; :class:`FieldError` (a ValueError without the file's name) for a bad node."""
    path = Path(path)
    text = read_text(path)
    if text.lstrip().startswith("<"):
        raise ValueError(f"{path}: XML storage is not read here; expected OpenCV YAML")
    tag = _OTHER_TAG.search(text)
    if tag:  # OpenCV's base64 reader (!!binary) can loop forever on bad input
        raise ValueError(f"{path}: holds the YAML tag {tag[0][:40]!r}; only !!opencv-matrix is read")
    depth = yaml_depth(text)
    if depth > MAX_DEPTH:
        raise ValueError(f"{path}: nested more than {MAX_DEPTH} levels deep; not read (the limit guards the parser)")
    try:
        fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except (SystemError, cv2.error) as exc:
        raise ValueError(f"{path}: not an OpenCV YAML file ({_parse_error(exc)})") from None
    try:
        if not fs.isOpened() or not fs.root().isMap():
            raise ValueError(f"{path}: not an OpenCV YAML file (no top-level map)")
        return {key: _node_value(fs.getNode(key), key) for key in keys if not fs.getNode(key).empty()}
    finally:
        fs.release()


# ----------------------------------------------------------------------------- fields after parsing
def require(d: dict, key: str, default=_MISSING):
    """``d[key]``; FieldError "is missing" when absent and no default is given."""
    if key in d:
        return d[key]
    if default is _MISSING:
        raise FieldError(key, "is missing")
    return default


def require_mapping(d: dict, key: str, default=_MISSING) -> dict:
    """A JSON object (dict with string keys)."""
    value = require(d, key, default)
    if not isinstance(value, dict):
        raise FieldError(key, f"must be an object, got {_short(value)}")
    return value


def require_list(d: dict, key: str, *, min_len: int = 0, default=_MISSING) -> list:
    """A JSON array of at least ``min_len`` items."""
    value = require(d, key, default)
    if not isinstance(value, (list, tuple)) or len(value) < min_len:
        raise FieldError(key, f"must be a list of at least {min_len} items, got {_short(value)}")
    return list(value)


def require_str(d: dict, key: str, default=_MISSING) -> str:
    """A string."""
    value = require(d, key, default)
    if not isinstance(value, str):
        raise FieldError(key, f"must be a string, got {_short(value)}")
    return value


def _as_float(value):
    if isinstance(value, np.ndarray) and value.size == 1:
        value = value.item()
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        return None
    try:
        return float(value)
    except OverflowError:
        return math.inf


def require_int(d: dict, key: str, lo: int, hi: int, default=_MISSING) -> int:
    """An integer in [lo, hi] (an integral float, or a 1×1 matrix, is accepted)."""
    value = require(d, key, default)
    f = _as_float(value)
    if f is None or not math.isfinite(f) or f != int(f) or not lo <= f <= hi:
        raise FieldError(key, f"must be an integer in [{lo}, {hi}], got {_short(value)}")
    return int(f)


def require_number(d: dict, key: str, *, positive: bool = False, nonnegative: bool = False,
                   nullable: bool = False, default=_MISSING) -> float:
    """A finite float (> 0 when ``positive``, ≥ 0 when ``nonnegative``); ``null`` reads as NaN when
    ``nullable`` (a number the writer did not have)."""
    value = require(d, key, default)
    if value is None and nullable:
        return math.nan
    f = _as_float(value)
    ok = f is not None and math.isfinite(f) and (f > 0 or not positive) and (f >= 0 or not nonnegative)
    if not ok:
        kind = "a positive finite number" if positive else "a finite number >= 0" if nonnegative else "a finite number"
        raise FieldError(key, f"must be {kind}{' or null' if nullable else ''}, got {_short(value)}")
    return f


def _has_bool(value) -> bool:
    """Whether a JSON value (nested lists) holds true or false, which numpy would read as 1 or 0."""
    if isinstance(value, (bool, np.bool_)):
        return True
    return isinstance(value, (list, tuple)) and any(_has_bool(v) for v in value)


def _floats(value, key: str, want: str) -> np.ndarray:
    """``value`` (numbers, nested lists of numbers, or an array) as float64; FieldError otherwise
    (true and false are not numbers here)."""
    if _has_bool(value):
        raise FieldError(key, f"must be a {want} matrix of numbers, got {_short(value)}")
    try:
        a = np.asarray(value)
    except (TypeError, ValueError, OverflowError):
        a = None
    if a is None or a.dtype.kind not in "iuf":
        raise FieldError(key, f"must be a {want} matrix of numbers, got {_short(value)}")
    return a.astype(np.float64)


def require_matrix(d: dict, key: str, shape: tuple, *, positive_diag: bool = False, default=_MISSING):
    """A finite float64 array of ``shape`` (-1: any length); a positive diagonal when ``positive_diag``.
    ``default=None`` makes the field optional (absent or null: None)."""
    value = require(d, key, default)
    if value is None and default is None:
        return None
    want = "x".join("N" if n < 0 else str(n) for n in shape)
    a = _floats(value, key, want)
    if a.ndim != len(shape) or any(n >= 0 and m != n for m, n in zip(a.shape, shape)):
        raise FieldError(key, f"must be a {want} matrix, got {f'shape {a.shape}' if a.ndim else _short(value)}")
    if not np.all(np.isfinite(a)):
        raise FieldError(key, f"must be finite, got {_short(a)}")
    if positive_diag and not np.all(np.diagonal(a, axis1=-2, axis2=-1) > 0):
        raise FieldError(key, f"must have a positive diagonal, got {_short(np.diagonal(a, axis1=-2, axis2=-1))}")
    return a


def require_vector(d: dict, key: str, n: int = -1, default=_MISSING):
    """A finite (n,) float64 vector (a 1×n or n×1 matrix is flattened); -1: any length."""
    value = require(d, key, default)
    if value is None and default is None:
        return None
    a = _floats(value, key, "1xN")
    if a.ndim == 2 and 1 in a.shape:
        a = a.reshape(-1)
    return require_matrix({key: a}, key, (n,))


def require_camera_matrix(d: dict, key: str) -> np.ndarray:
    """A (3, 3) K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0 (px)."""
    K = require_matrix(d, key, (3, 3))
    if not (K[0, 0] > 0 and K[1, 1] > 0):
        raise FieldError(key, f"must have focal lengths fx, fy > 0, got fx={K[0, 0]!r}, fy={K[1, 1]!r}")
    if K[0, 1] != 0 or K[1, 0] != 0 or not np.array_equal(K[2], [0.0, 0.0, 1.0]):
        raise FieldError(key, f"must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}")
    return K


def require_rotation(d: dict, key: str, shape: tuple = (3, 3)) -> np.ndarray:
    """Rotation matrices of ``shape`` (..., 3, 3): orthonormal with det +1 within :data:`ROTATION_TOL`."""
    R = require_matrix(d, key, shape)
    Rs = R.reshape(-1, 3, 3)
    err = np.abs(np.einsum("kji,kjl->kil", Rs, Rs) - np.eye(3)).max(initial=0.0)
    det = np.linalg.det(Rs) if len(Rs) else np.ones(0)
    if err > ROTATION_TOL or np.any(np.abs(det - 1) > ROTATION_TOL):
        raise FieldError(key, f"must be a rotation (orthonormal, det +1), off by {max(err, np.abs(det - 1).max()):.3g}")
    return R


MAX_DIST_COEFF = 1e6  # |coefficient| of any lens model's distortion; real lenses stay many decades below


def require_dist(d: dict, key: str, model: str) -> np.ndarray:
    """The (n,) coefficients of lens ``model`` (OpenCV order; extra zero OpenCV coefficients dropped)."""
    dist = require_vector(d, key)
    if dist.size and np.abs(dist).max() > MAX_DIST_COEFF:  # no lens has one; its projection would overflow
        raise FieldError(key, f"holds {_short(dist[np.argmax(np.abs(dist))])}, not a lens coefficient "
                              f"(|value| over {MAX_DIST_COEFF:g})")
    try:
        return L.check_model(model, dist)[1]
    except ValueError as exc:
        raise FieldError(key, f"does not fit the lens model: {exc}") from None


def require_image_size(d: dict, width: str = "image_width", height: str = "image_height") -> tuple[int, int]:
    """(width, height) px, each in [1, :data:`MAX_IMAGE_SIDE`]."""
    return require_int(d, width, 1, MAX_IMAGE_SIDE), require_int(d, height, 1, MAX_IMAGE_SIDE)


def require_board(d: dict, pattern: str, square: str) -> tuple[tuple[int, int], float]:
    """((cols, rows) >= (2, 2) inner corners, square size > 0) from fields ``pattern`` (a [cols, rows]
    list) and ``square``."""
    p = require(d, pattern)
    try:
        cols, rows = (require_int({pattern: v}, pattern, 2, MAX_PATTERN_SIDE) for v in p)
    except (FieldError, TypeError, ValueError):
        raise FieldError(pattern, f"must be [cols, rows] inner corners, each in [2, {MAX_PATTERN_SIDE}], "
                                  f"got {_short(p)}") from None
    return (cols, rows), require_number(d, square, positive=True)


def require_item(items: list, k: int, field: str) -> dict:
    """Item ``k`` of the list ``field``, which must be an object (its field is ``field[k]``)."""
    return require_mapping({f"{field}[{k}]": items[k]}, f"{field}[{k}]")


def require_model(d: dict, n_coeffs: int, key: str | None = "model", ros_key: str = "distortion_model") -> str:
    """Our lens model name: field ``key`` when present (and consistent with ``ros_key``), else from the
    ROS name in ``ros_key`` and the coefficient count (plumb_bob when both are absent, as in older files).
    ``key=None``: the file has only the ROS name (OpenCV YAML)."""
    model = require(d, key, None) if key else None
    ros = require(d, ros_key, None)
    for k, v in ((key, model), (ros_key, ros)):
        if v is not None and not isinstance(v, str):
            raise FieldError(k, f"must be a string, got {_short(v)}")
    if model:
        if model not in L.MODELS:
            raise FieldError(key, f"must be one of {', '.join(L.MODELS)}, got {_short(model)}")
        if ros and L.ROS_NAMES[model] != {"fisheye": "equidistant"}.get(ros.strip().lower(), ros.strip().lower()):
            raise FieldError(ros_key, f"is {ros!r} but {key} is {model!r}")
        return model
    try:
        return L.model_from_ros(ros or "plumb_bob", n_coeffs)
    except ValueError as exc:
        raise FieldError(ros_key, f"does not name a lens model with {n_coeffs} coefficients ({exc})") from None
