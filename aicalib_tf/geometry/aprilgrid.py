"""Kalibr's AprilGrid: one description for detection, calibration, printing and rendered test data.

An AprilGrid is ``cols × rows`` AprilTags of side ``tag`` (the outer edge of the black border),
``gap = spacing · tag`` apart, with a black square of side ``gap`` at every tag corner (Kalibr's
"symmetric corners"), so each tag corner is an X-junction: the tag's black border and the small
square meet there. Tags carry Kalibr's two-bit black border. Tag ``first + k`` sits at column
``k % cols`` and, counted from the bottom as Kalibr numbers them, row ``k // cols``.

Frame. Kalibr puts its origin at the bottom-left corner of tag 0 with y up. Ours follows
:mod:`aicalib_tf.geometry.pattern` (x right, y down the printed page): the origin is the top-left
corner of the top-left tag, so a Kalibr point (x, y) is ours at (x, H − y), H the height from the
bottom edge of the bottom tags to the top edge of the top tags.

The corners are not evenly spaced (x = (c // 2)·(tag + gap) + (c % 2)·tag), yet the calibration
code places corner ids on a uniform lattice, (c·s, r·s, 0). With ``spacing = a / b`` in lowest
terms, every corner lies on the lattice of unit ``u = tag / b``: corner column c sits at lattice
column ``(c // 2)·(a + b) + (c % 2)·b``. A corner's id is its lattice position, ``square_size`` is
u and ``pattern_size`` is the lattice's extent; most lattice points hold no corner. ``spacing``
takes at most three decimals and the lattice at most ``MAX_LATTICE`` points a side.

Text forms: ``aprilgrid:6x6,tag=88mm,spacing=0.3[,family=tag36h11][,first=0]`` and Kalibr's
target YAML (``target_type: aprilgrid`` with ``tagCols``, ``tagRows``, ``tagSize`` in metres,
``tagSpacing``; ``target_type: checkerboard`` reads as a chessboard, :class:`Checkerboard`).
Pure numpy and OpenCV.
"""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np

from aicalib_tf.geometry.charuco import parse_length
from aicalib_tf.geometry.pattern import board_points, check_pattern

__all__ = ["AprilGrid", "Checkerboard", "FAMILIES", "PREFIX", "MAX_LATTICE", "PRINT_ROTATION", "is_aprilgrid",
           "parse_board", "read_kalibr_target", "load_board", "corner_count", "tag_image", "layout_image", "render_view"]

PREFIX = "aprilgrid:"
FAMILIES = {"tag36h11": "DICT_APRILTAG_36h11", "tag36h10": "DICT_APRILTAG_36h10",
            "tag25h9": "DICT_APRILTAG_25h9", "tag16h5": "DICT_APRILTAG_16h5"}
BORDER_BITS = 2  # Kalibr's tags: a black border two bits wide
MAX_LATTICE = 2000  # lattice points along one side (spacing 0.3: 13 a tag)
# Counter-clockwise quarter turns of OpenCV's marker image as printed. Kalibr prints each code upright
# (most significant bit top-left, a set bit white), which is OpenCV's image turned half a turn.
PRINT_ROTATION = 2


@functools.lru_cache(maxsize=None)
def dictionary(family: str):
    """The ``cv2.aruco.Dictionary`` of an AprilTag family (``tag36h11``, ...)."""
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, FAMILIES[family]))


def _spacing_fraction(spacing: float) -> Fraction:
    f = Fraction(spacing).limit_denominator(1000)
    if abs(float(f) - spacing) > 1e-9:
        raise ValueError(f"spacing {spacing!r} needs at most three decimals (e.g. 0.3 or 0.25)")
    return f


@dataclass(frozen=True)
class AprilGrid:
    """An AprilGrid (see the module docstring).

    tags : (cols, rows) tags across and up. tag : the tag's side, in ``unit``. spacing : the gap
    between tags over the tag's side, in (0, 1). family : an AprilTag family of :data:`FAMILIES`.
    first_id : the first tag's id. unit : "mm", "cm", "m", "in" or "" (unitless).
    """

    tags: tuple[int, int]
    tag: float
    spacing: float
    family: str = "tag36h11"
    first_id: int = 0
    unit: str = "mm"

    def __post_init__(self):
        cols, rows = (int(v) for v in self.tags)
        object.__setattr__(self, "tags", (cols, rows))
        object.__setattr__(self, "family", str(self.family).lower().replace("t36", "tag36").replace("tagtag", "tag"))
        if cols < 2 or rows < 2:
            raise ValueError(f"tags: an AprilGrid needs at least 2x2 tags, got {cols}x{rows}")
        if not (0 < self.tag < 1e6):
            raise ValueError(f"tag: the tag size must be > 0 and under 1e6, got {self.tag!r}")
        if not 0 < self.spacing < 1:
            raise ValueError(f"spacing: the gap between tags over the tag size must be in (0, 1), got {self.spacing!r}")
        if self.family not in FAMILIES:
            raise ValueError(f"family: unknown tag family {self.family!r}; choose from {', '.join(FAMILIES)}")
        _spacing_fraction(float(self.spacing))
        if max(self.pattern_size) > MAX_LATTICE:
            raise ValueError(f"spacing: {self.spacing:g} puts {max(self.pattern_size)} lattice points on a side "
                             f"(at most {MAX_LATTICE}); choose a simpler fraction such as 0.3 or 0.25")
        size = int(dictionary(self.family).bytesList.shape[0])
        if self.first_id < 0 or self.first_id + cols * rows > size:
            raise ValueError(f"first: {self.family} holds {size} tags; this grid needs ids "
                             f"{self.first_id}..{self.first_id + cols * rows - 1}")

    # --- the lattice ------------------------------------------------------------------------
    @property
    def fraction(self) -> tuple[int, int]:
        """(a, b): spacing = a / b in lowest terms."""
        f = _spacing_fraction(float(self.spacing))
        return f.numerator, f.denominator

    def lattice_of(self, k) -> np.ndarray:
        """Lattice position of corner column (or row) ``k`` (int array), counted from the left (top)."""
        a, b = self.fraction
        k = np.asarray(k, np.int64)
        return (k // 2) * (a + b) + (k % 2) * b

    @property
    def pattern_size(self) -> tuple[int, int]:
        """(cols, rows) of the lattice: 1 + the last corner's lattice position along each axis."""
        cols, rows = self.tags
        return int(self.lattice_of(2 * cols - 1)) + 1, int(self.lattice_of(2 * rows - 1)) + 1

    @property
    def square_size(self) -> float:
        """The lattice unit ``tag / b``, in ``unit``."""
        return float(self.tag) / self.fraction[1]

    @property
    def bits(self) -> int:
        """n: a tag has n × n data bits inside its border."""
        return int(dictionary(self.family).markerSize)

    # --- the tags ---------------------------------------------------------------------------
    def tag_ids(self) -> np.ndarray:
        """(cols·rows,) int64 tag ids, Kalibr's order (row-major from the bottom-left)."""
        return np.arange(self.first_id, self.first_id + self.tags[0] * self.tags[1], dtype=np.int64)

    def tag_cell(self, tag_id) -> np.ndarray:
        """(..., 2) int64 (column from the left, row from the top) of tags ``tag_id``."""
        k = np.asarray(tag_id, np.int64) - self.first_id
        cols, rows = self.tags
        return np.stack([k % cols, rows - 1 - k // cols], axis=-1)

    def tag_corner_ids(self, tag_id, rotation: int = PRINT_ROTATION) -> np.ndarray:
        """(..., 4, 2) int64 lattice ids of the corners of tags ``tag_id``, in the order OpenCV's
        aruco reports them for a tag printed ``rotation`` quarter turns counter-clockwise from its marker image
        (0: top-left, top-right, bottom-right, bottom-left on the page)."""
        cell = self.tag_cell(tag_id)
        x0, y0 = self.lattice_of(2 * cell[..., 0]), self.lattice_of(2 * cell[..., 1])
        b = self.fraction[1]
        offs = np.array([[0, 0], [b, 0], [b, b], [0, b]], np.int64)
        offs = np.roll(offs, int(rotation) % 4, axis=0)  # np.rot90 turns the code counter-clockwise on the page
        return np.stack([x0, y0], axis=-1)[..., None, :] + offs

    def tag_of(self, ids) -> np.ndarray:
        """(N,) int64 id of the tag whose corner each lattice id of ``ids`` (N, 2) is (every corner is one tag's)."""
        a, b = self.fraction
        cell = np.asarray(ids, np.int64).reshape(-1, 2) // (a + b)  # a corner's lattice offset in its tag is 0 or b < a + b
        cols, rows = self.tags
        return self.first_id + (rows - 1 - cell[:, 1]) * cols + cell[:, 0]

    def corner_ids(self) -> np.ndarray:
        """(4·cols·rows, 2) int64 lattice ids of every corner, row-major from the top-left."""
        cols, rows = self.tags
        r, c = np.mgrid[0: 2 * rows, 0: 2 * cols]
        return np.stack([self.lattice_of(c.ravel()), self.lattice_of(r.ravel())], axis=1)

    def object_points(self, ids=None) -> np.ndarray:
        """(N, 3) float64 corner positions in our frame, in ``unit`` (all corners by default)."""
        return board_points(self.corner_ids() if ids is None else np.asarray(ids), self.square_size)

    # --- text -------------------------------------------------------------------------------
    def describe(self) -> str:
        """The text form, which :func:`parse_board` reads back."""
        text = f"{PREFIX}{self.tags[0]}x{self.tags[1]},tag={self.tag:g}{self.unit},spacing={self.spacing:g}"
        return text + (f",family={self.family}" if self.family != "tag36h11" else "") + (
            f",first={self.first_id}" if self.first_id else "")

    def to_dict(self) -> dict:
        return {"type": "aprilgrid", "description": self.describe(), "tags": list(self.tags), "tag": self.tag,
                "spacing": self.spacing, "family": self.family, "first_id": self.first_id, "unit": self.unit,
                "pattern_size": list(self.pattern_size), "square_size": self.square_size}


@dataclass(frozen=True)
class Checkerboard:
    """A chessboard read from a Kalibr target YAML: pattern (cols, rows) inner corners, square, unit."""

    pattern_size: tuple[int, int]
    square: float
    unit: str = "m"


def is_aprilgrid(text) -> bool:
    """Whether ``text`` names an AprilGrid or a Kalibr target: ``aprilgrid:...`` or a .yaml/.yml file."""
    t = str(text).strip().lower() if isinstance(text, str) else ""
    return t.startswith(PREFIX) or t.endswith((".yaml", ".yml"))


def parse_board(text: str) -> AprilGrid:
    """Parse ``aprilgrid:6x6,tag=88mm,spacing=0.3[,family=tag36h11][,first=0]``.

    Raises ValueError naming the field (missing, spacing outside (0, 1), unknown family, ...).
    """
    if not (isinstance(text, str) and text.strip().lower().startswith(PREFIX)):
        raise ValueError(f"an AprilGrid must look like aprilgrid:6x6,tag=88mm,spacing=0.3, got {text!r}")
    parts = [p.strip() for p in text.strip()[len(PREFIX):].split(",") if p.strip()]
    if not parts or not re.fullmatch(r"\d+\s*[xX×]\s*\d+", parts[0]):
        raise ValueError(f"board {text!r}: first give the tags as COLSxROWS, e.g. 6x6")
    cols, rows = (int(v) for v in re.split(r"[xX×]", parts[0]))
    fields = {}
    for p in parts[1:]:
        key, eq, value = p.partition("=")
        key = key.strip().lower()
        if not eq or key not in ("tag", "spacing", "family", "first") or key in fields:
            raise ValueError(f"board {text!r}: unexpected {p!r} (fields: tag=, spacing=, family=, first=)")
        fields[key] = value.strip()
    missing = [k + "=" for k in ("tag", "spacing") if k not in fields]
    if missing:
        raise ValueError(f"board {text!r}: missing {', '.join(missing)}")
    tag, unit = parse_length(fields["tag"], "tag=", "88mm, 8.8cm or 0.088m")
    try:
        spacing = float(fields["spacing"])
    except ValueError:
        raise ValueError(f"board {text!r}: spacing= must be a number in (0, 1), got {fields['spacing']!r}") from None
    if not fields.get("first", "0").isdigit():
        raise ValueError(f"board {text!r}: first= must be a whole number >= 0")
    try:
        return AprilGrid((cols, rows), tag, spacing, fields.get("family", "tag36h11"), int(fields.get("first", "0")), unit)
    except ValueError as e:
        raise ValueError(f"board {text!r}: {e}") from None


def _flat_yaml(path: str) -> dict[str, str]:
    """The ``key: value`` lines of a flat YAML file (Kalibr's target files), comments dropped."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"{path}: cannot read the target file ({e})") from None
    out = {}
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line or line in ("---", "..."):
            continue
        key, colon, value = line.partition(":")
        if not colon:
            raise ValueError(f"{path}: expected 'key: value' lines, got {line!r}")
        out[key.strip()] = value.strip().strip("'\"")
    return out


def _field(d: dict, path: str, key: str, kind=float):
    if key not in d:
        raise ValueError(f"{path}: {key} is missing")
    try:
        return kind(d[key])
    except ValueError:
        raise ValueError(f"{path}: {key} must be a {'whole ' if kind is int else ''}number, got {d[key]!r}") from None


_KALIBR_FIELDS = {"tags": "tagCols, tagRows", "tag": "tagSize", "spacing": "tagSpacing"}


def _kalibr_names(message: str) -> str:
    """An :class:`AprilGrid` message with its field named as Kalibr's target file names it."""
    field, colon, rest = message.partition(":")
    return f"{_KALIBR_FIELDS[field]}:{rest}" if colon and field in _KALIBR_FIELDS else message


def read_kalibr_target(path: str) -> AprilGrid | Checkerboard:
    """A Kalibr target YAML: ``target_type: aprilgrid`` (tagCols, tagRows, tagSize m, tagSpacing)
    or ``checkerboard`` (targetCols, targetRows inner corners, rowSpacingMeters = colSpacingMeters)."""
    d = _flat_yaml(path)
    kind = d.get("target_type", "")
    if kind == "aprilgrid":
        try:
            return AprilGrid((_field(d, path, "tagCols", int), _field(d, path, "tagRows", int)),
                             _field(d, path, "tagSize"), _field(d, path, "tagSpacing"), unit="m")
        except ValueError as e:
            raise ValueError(str(e) if str(e).startswith(path) else f"{path}: {_kalibr_names(str(e))}") from None
    if kind == "checkerboard":
        pattern = (_field(d, path, "targetCols", int), _field(d, path, "targetRows", int))
        rs, cs = _field(d, path, "rowSpacingMeters"), _field(d, path, "colSpacingMeters")
        if not (rs > 0 and cs > 0) or abs(rs - cs) > 1e-9 * max(rs, cs):
            raise ValueError(f"{path}: rowSpacingMeters ({rs:g}) and colSpacingMeters ({cs:g}) must be equal and > 0")
        try:
            return Checkerboard(check_pattern(pattern), rs, "m")
        except ValueError as e:
            raise ValueError(f"{path}: targetCols, targetRows: {e}") from None
    raise ValueError(f"{path}: target_type {kind or '(missing)'!r} is not read here; "
                     "give target_type: aprilgrid or checkerboard")


def load_board(text: str) -> AprilGrid | Checkerboard:
    """:func:`parse_board` for ``aprilgrid:...``, else :func:`read_kalibr_target` for a YAML file."""
    return parse_board(text) if text.strip().lower().startswith(PREFIX) else read_kalibr_target(text.strip())


def corner_count(description) -> int | None:
    """Corners of the AprilGrid that ``description`` names (its text or a Kalibr file), else None
    (another board, or a file no longer readable): a view with fewer is partial."""
    if not is_aprilgrid(description):
        return None
    try:
        board = load_board(description)
    except ValueError:
        return None
    return 4 * board.tags[0] * board.tags[1] if isinstance(board, AprilGrid) else None


def tag_image(board: AprilGrid, tag_id: int, side_px: int) -> np.ndarray:
    """(side, side) uint8 tag as printed (border included, turned ``PRINT_ROTATION`` quarter turns)."""
    img = cv2.aruco.generateImageMarker(dictionary(board.family), int(tag_id), int(side_px), borderBits=BORDER_BITS)
    return np.ascontiguousarray(np.rot90(img, PRINT_ROTATION))


def layout_image(board: AprilGrid, px_per_unit: int, margin_px: int = 0) -> np.ndarray:
    """(rows_lattice·q + 2·margin, cols_lattice·q + 2·margin) uint8 board, q = ``px_per_unit`` px
    per lattice unit (a tag is b·q px; make it a multiple of n + 4 for whole bits). Lattice point
    (X, Y) lies at pixel coordinates (margin − ½ + X·q, margin − ½ + Y·q). Black 0, white 255; the
    corner squares reach ``gap`` beyond the outer tags, so keep ``margin_px`` ≥ a·q."""
    q, m = int(px_per_unit), int(margin_px)
    a, b = board.fraction
    w, h = (int(board.lattice_of(2 * n - 1)) * q for n in board.tags)
    img = np.full((h + 2 * m, w + 2 * m), 255, np.uint8)
    g, t = a * q, b * q
    for k in board.tag_ids():
        c, r = board.tag_cell(int(k))
        x0, y0 = m + c * (a + b) * q, m + r * (a + b) * q
        img[y0: y0 + t, x0: x0 + t] = tag_image(board, int(k), t)
        for dx, dy in ((-g, -g), (t, -g), (t, t), (-g, t)):  # the squares at the tag's corners
            ys, xs = max(y0 + dy, 0), max(x0 + dx, 0)
            img[ys: max(y0 + dy + g, 0), xs: max(x0 + dx + g, 0)] = 0
    return img


def render_view(layout: np.ndarray, px_per_unit: float, margin_px: float, H: np.ndarray, size: tuple[int, int],
                supersample: int = 4) -> np.ndarray:
    """(h, w) float32 image in [0, 1] of the layout seen through the homography H (3, 3) from
    lattice units to image px (pixel centres at integers), area-averaged over ``supersample``² samples
    a pixel, white (1.0) outside the layout. For test data with exact truth."""
    s = int(supersample)
    q, m = float(px_per_unit), float(margin_px)
    from_layout = np.array([[1 / q, 0, -(m - 0.5) / q], [0, 1 / q, -(m - 0.5) / q], [0, 0, 1]])
    to_super = np.array([[s, 0, (s - 1) / 2.0], [0, s, (s - 1) / 2.0], [0, 0, 1]])
    M = to_super @ np.asarray(H, np.float64) @ from_layout
    w, h = size
    big = cv2.warpPerspective(layout.astype(np.float32) / 255.0, M, (w * s, h * s), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=1.0)
    return cv2.resize(big, (w, h), interpolation=cv2.INTER_AREA)
