"""ChArUco boards: one description for data_gen, detection, calibration and printing.

A ChArUco board is a chessboard whose white squares hold ArUco markers. Squares are counted as
``cv2.aruco.CharucoBoard((X, Y), ...)`` counts them: X across, Y down. Its inner (chessboard)
corners form the pattern ``(X − 1, Y − 1)`` with the conventions of
:mod:`aicalib_tf.geometry.pattern`: corner (c, r) at (c·s, r·s, 0), index r·(X − 1) + c, which is
OpenCV's ChArUco corner id. OpenCV's board frame is ours shifted by one square: its corner k sits
at ((c + 1)·s, (r + 1)·s, 0).

Square (i, j) (column i, row j, i < X, j < Y) covers x ∈ [(i − 1)·s, i·s], y ∈ [(j − 1)·s, j·s] in
our frame. The marker squares are those with i + j odd; with the legacy layout and an even Y,
those with i + j even (OpenCV ≤ 4.5 boards). Markers are numbered row-major over the marker
squares from ``first_id``; each is centred in its square, side ``marker``, corners in OpenCV's
order (top-left, top-right, bottom-right, bottom-left as x right, y down).

Text form: ``charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100[,legacy][,first=0]``.
Pure numpy and OpenCV.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

import cv2
import numpy as np

from aicalib_tf.geometry.pattern import board_points, check_pattern, pattern_ids

__all__ = ["CharucoBoard", "parse_board", "is_charuco", "DICTIONARIES", "dictionary", "marker_bits", "layout_image",
           "parse_length", "UNIT_MM"]

MAX_BOARD_EXTENT = 1e6  # board units (1 km in mm); OpenCV's board geometry is float32

UNIT_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4, "": None}  # a board length unit -> mm ("" unitless)
PREFIX = "charuco:"


def _dictionary_names() -> dict[str, str]:
    """Upper-case name -> the attribute of cv2.aruco (every predefined dictionary)."""
    return {n.upper(): n for n in dir(cv2.aruco) if n.startswith("DICT_") and isinstance(getattr(cv2.aruco, n), int)}


DICTIONARIES = tuple(sorted(_dictionary_names()))


@functools.lru_cache(maxsize=None)
def dictionary(name: str):
    """The ``cv2.aruco.Dictionary`` called ``name`` (any case, e.g. ``DICT_5X5_100``)."""
    attr = _dictionary_names().get(str(name).upper())
    if attr is None:
        raise ValueError(f"unknown ArUco dictionary {name!r}; choose from {', '.join(DICTIONARIES)}")
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, attr))


@functools.lru_cache(maxsize=4096)
def marker_bits(name: str, marker_id: int) -> np.ndarray:
    """(n + 2, n + 2) uint8 bits of marker ``marker_id`` of dictionary ``name``, border included:
    1 white, 0 black, rows top to bottom as printed."""
    d = dictionary(name)
    n = int(d.markerSize)
    bits = (cv2.aruco.generateImageMarker(d, int(marker_id), n + 2, borderBits=1) > 127).astype(np.uint8)
    bits.setflags(write=False)
    return bits


@dataclass(frozen=True)
class CharucoBoard:
    """A ChArUco board (see the module docstring).

    squares : (X, Y) squares across and down. square, marker : side lengths, in ``unit``.
    dictionary : the cv2.aruco predefined dictionary's name. legacy : OpenCV's legacy layout.
    first_id : the first marker's id. unit : "mm", "cm", "m", "in" or "" (unitless).
    """

    squares: tuple[int, int]
    square: float
    marker: float
    dictionary: str
    legacy: bool = False
    first_id: int = 0
    unit: str = "mm"

    def __post_init__(self):
        X, Y = (int(v) for v in self.squares)
        object.__setattr__(self, "squares", (X, Y))
        object.__setattr__(self, "dictionary", _dictionary_names().get(str(self.dictionary).upper(), self.dictionary).upper())
        check_pattern((X - 1, Y - 1))
        if not (self.square > 0 and self.marker > 0):
            raise ValueError(f"square and marker must be > 0, got square={self.square}, marker={self.marker}")
        if not self.square * max(X, Y) <= MAX_BOARD_EXTENT:  # NaN and infinity too
            raise ValueError(f"square={self.square:g} is too large: the board would be {self.square * max(X, Y):g} "
                             f"units wide (at most {MAX_BOARD_EXTENT:g})")
        if self.marker >= self.square:
            raise ValueError(f"marker ({self.marker:g}) must be smaller than square ({self.square:g})")
        size = int(dictionary(self.dictionary).bytesList.shape[0])
        if self.first_id < 0 or self.first_id + self.n_markers > size:
            raise ValueError(f"{self.dictionary} holds {size} markers; this board needs ids "
                             f"{self.first_id}..{self.first_id + self.n_markers - 1}")

    # --- the pattern of inner corners -------------------------------------------------------
    @property
    def pattern_size(self) -> tuple[int, int]:
        """(cols, rows) inner corners = (X − 1, Y − 1)."""
        return self.squares[0] - 1, self.squares[1] - 1

    @property
    def square_size(self) -> float:
        return float(self.square)

    def object_points(self) -> np.ndarray:
        """(cols·rows, 3) float64 inner-corner positions, our frame, index = OpenCV's ChArUco id."""
        return board_points(pattern_ids(self.pattern_size), self.square)

    # --- the markers -----------------------------------------------------------------------
    @property
    def bits(self) -> int:
        """n: a marker has n × n data bits inside a one-bit black border."""
        return int(dictionary(self.dictionary).markerSize)

    def _parity(self) -> int:
        return 0 if (self.legacy and self.squares[1] % 2 == 0) else 1

    def is_marker_square(self, i, j) -> np.ndarray:
        """Whether square (i, j) (int arrays) holds a marker."""
        return (np.asarray(i) + np.asarray(j)) % 2 == self._parity()

    @property
    def n_markers(self) -> int:
        X, Y = self.squares
        j, i = np.mgrid[0:Y, 0:X]
        return int(np.count_nonzero(self.is_marker_square(i, j)))

    def marker_squares(self) -> np.ndarray:
        """(M, 2) int64 (i, j) square of each marker, in marker order (id = first_id + index)."""
        X, Y = self.squares
        j, i = np.mgrid[0:Y, 0:X]
        keep = self.is_marker_square(i, j).ravel()
        return np.stack([i.ravel()[keep], j.ravel()[keep]], axis=1).astype(np.int64)

    def marker_ids(self) -> np.ndarray:
        """(M,) int64 marker ids, in marker order."""
        return np.arange(self.first_id, self.first_id + self.n_markers, dtype=np.int64)

    def marker_square_of(self) -> Mapping[int, tuple[int, int]]:
        """{marker id: (i, j) square}, read-only (made once per board: the detector asks often)."""
        return _square_of(self)

    def marker_corners(self) -> np.ndarray:
        """(M, 4, 3) float64 marker corners in our frame (top-left, top-right, bottom-right, bottom-left)."""
        s, h = float(self.square), float(self.marker) / 2.0
        centre = (self.marker_squares() - 0.5) * s  # square (i, j) is centred at ((i − ½)·s, (j − ½)·s)
        offs = np.array([[-h, -h], [h, -h], [h, h], [-h, h]])
        xy = centre[:, None, :] + offs[None]
        return np.concatenate([xy, np.zeros(xy.shape[:2] + (1,))], axis=2)

    def square_bits(self, marker_id: int) -> np.ndarray:
        """(n + 2, n + 2) uint8 bits of one of this board's markers (1 white), as printed."""
        return marker_bits(self.dictionary, int(marker_id))

    # --- OpenCV and text --------------------------------------------------------------------
    def to_opencv(self):
        """The same board as ``cv2.aruco.CharucoBoard`` (its frame is ours shifted by one square)."""
        b = cv2.aruco.CharucoBoard(self.squares, float(self.square), float(self.marker),
                                   dictionary(self.dictionary), self.marker_ids().astype(np.int32))
        b.setLegacyPattern(bool(self.legacy))
        return b

    def describe(self) -> str:
        """The text form, which :func:`parse_board` reads back."""
        u = self.unit
        text = (f"{PREFIX}{self.squares[0]}x{self.squares[1]},square={self.square:g}{u},"
                f"marker={self.marker:g}{u},dict={self.dictionary}")
        return text + (",legacy" if self.legacy else "") + (f",first={self.first_id}" if self.first_id else "")

    def to_dict(self) -> dict:
        return {"type": "charuco", "description": self.describe(), "squares": list(self.squares),
                "square": self.square, "marker": self.marker, "dictionary": self.dictionary,
                "legacy": self.legacy, "first_id": self.first_id, "unit": self.unit,
                "pattern_size": list(self.pattern_size)}


@functools.lru_cache(maxsize=64)
def _square_of(board: CharucoBoard) -> Mapping[int, tuple[int, int]]:
    return MappingProxyType({int(k): (int(i), int(j)) for k, (i, j) in zip(board.marker_ids(), board.marker_squares())})


def is_charuco(text) -> bool:
    """Whether ``text`` is a ChArUco board description (starts with ``charuco:``)."""
    return isinstance(text, str) and text.strip().lower().startswith(PREFIX)


def parse_length(text: str, what: str, example: str = "30mm, 3cm or 0.03m") -> tuple[float, str]:
    """A board description's length field: ``"30mm"`` -> (30.0, "mm"); a unit of :data:`UNIT_MM` or none.
    ValueError naming ``what`` (e.g. ``square``) otherwise."""
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*([a-zA-Z]*)\s*", text)
    if not m or m.group(2).lower() not in UNIT_MM:
        raise ValueError(f"{what} must be a length such as {example}, got {text!r}")
    return float(m.group(1)), m.group(2).lower()


def _lengths(square: str, marker: str) -> tuple[float, float, str]:
    """Square and marker lengths in the square's unit (a unitless marker shares it)."""
    s, su = parse_length(square, "square")
    m, mu = parse_length(marker, "marker")
    if mu and su and mu != su:
        m = m * UNIT_MM[mu] / UNIT_MM[su]
    elif mu and not su:
        raise ValueError(f"marker has a unit ({mu}) but square has none")
    return s, m, su


def parse_board(text: str) -> CharucoBoard:
    """Parse ``charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100[,legacy][,first=0]``.

    Raises ValueError naming the problem (missing field, marker ≥ square, unknown dictionary,
    more markers than the dictionary holds).
    """
    if not is_charuco(text):
        raise ValueError(f"a board must look like charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100, got {text!r}")
    parts = [p.strip() for p in text.strip()[len(PREFIX):].split(",") if p.strip()]
    if not parts or not re.fullmatch(r"\d+\s*[xX×]\s*\d+", parts[0]):
        raise ValueError(f"board {text!r}: first give the squares as XxY, e.g. 11x8")
    X, Y = (int(v) for v in re.split(r"[xX×]", parts[0]))
    fields, legacy = {}, False
    for p in parts[1:]:
        key, eq, value = p.partition("=")
        key = key.strip().lower()
        if key == "legacy" and not eq:
            legacy = True
        elif eq and key in ("square", "marker", "dict", "first") and key not in fields:
            fields[key] = value.strip()
        else:
            raise ValueError(f"board {text!r}: unexpected {p!r} (fields: square=, marker=, dict=, legacy, first=)")
    missing = [k for k in ("square", "marker", "dict") if k not in fields]
    if missing:
        raise ValueError(f"board {text!r}: missing {', '.join(m + '=' for m in missing)}")
    if not fields.get("first", "0").isdigit():
        raise ValueError(f"board {text!r}: first= must be a whole number >= 0")
    s, m, unit = _lengths(fields["square"], fields["marker"])
    return CharucoBoard((X, Y), s, m, fields["dict"], legacy, int(fields.get("first", "0")), unit)


def layout_image(board: CharucoBoard, px_per_square: int, margin_px: int = 0) -> np.ndarray:
    """(Y·p + 2·margin, X·p + 2·margin) uint8 image of the board drawn from this module's layout
    (p = ``px_per_square``; black 0, white 255); the marker bits must tile the marker exactly:
    ``px_per_square · marker / square`` a multiple of n + 2 px, and the marker centred on whole px."""
    X, Y = board.squares
    p = int(px_per_square)
    img = np.full((Y * p + 2 * margin_px, X * p + 2 * margin_px), 255, np.uint8)
    j, i = np.mgrid[0:Y, 0:X]
    for ii, jj in zip(i[~board.is_marker_square(i, j)], j[~board.is_marker_square(i, j)]):
        img[margin_px + jj * p: margin_px + (jj + 1) * p, margin_px + ii * p: margin_px + (ii + 1) * p] = 0
    mpx = int(round(p * board.marker / board.square))
    off = (p - mpx) // 2
    for k, (ii, jj) in zip(board.marker_ids(), board.marker_squares()):
        bits = cv2.resize(board.square_bits(int(k)) * 255, (mpx, mpx), interpolation=cv2.INTER_NEAREST)
        y0, x0 = margin_px + jj * p + off, margin_px + ii * p + off
        img[y0: y0 + mpx, x0: x0 + mpx] = bits
    return img
