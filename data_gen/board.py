"""A printed chessboard: pattern, square size, white margin and paper grey levels.

Board frame: inner corner (c, r) is at (c·s, r·s, 0), s the square size (any unit, the same
unit as the pose translation). Squares span X in [-s, cols·s] and Y in [-s, rows·s]; the paper
adds a white margin m around them. The top-left square (the one touching inner corner (0, 0)
from above-left) is black, as on OpenCV's sample board.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aicalib_tf.geometry.board_shape import SHAPE_TERMS, shape_height, shaped_points
from aicalib_tf.geometry.pattern import board_points, check_pattern, pattern_ids

__all__ = ["Board", "sample_board"]


def paper_bounds(cols: int, rows: int, square: float, margin: float) -> tuple[float, float, float, float]:
    """(x0, y0, x1, y1) of the paper, board units, for ``cols`` × ``rows`` inner corners (the squares
    run from −square to cols·square) and a white ``margin`` in squares around them."""
    m = margin * square
    return (-square - m, -square - m, cols * square + m, rows * square + m)


def grid_centre(cols: int, rows: int, square: float) -> np.ndarray:
    """(3,) centre of the inner-corner grid, board units."""
    return np.array([(cols - 1) * square / 2.0, (rows - 1) * square / 2.0, 0.0])


def paper_masks(X: np.ndarray, Y: np.ndarray, cols: int, rows: int, square: float,
                margin: float) -> tuple[np.ndarray, np.ndarray]:
    """(on the paper, on the squares) boolean masks of board-plane points X, Y (...) in board units
    (NaN: not on the plane, in neither)."""
    x0, y0, x1, y1 = paper_bounds(cols, rows, square, margin)
    with np.errstate(invalid="ignore"):
        on_paper = (X >= x0) & (X < x1) & (Y >= y0) & (Y < y1)
        on_squares = on_paper & (X >= -square) & (X < cols * square) & (Y >= -square) & (Y < rows * square)
    return on_paper, on_squares


@dataclass(frozen=True)
class Board:
    """A chessboard target.

    Attributes
    ----------
    pattern_size : (cols, rows) inner corners.
    square_size : side of one square (board units, e.g. mm).
    margin : white paper border around the outer squares, in squares (0.25 = a quarter square).
    black, white : printed grey levels in [0, 1] (paper is never pure 0/1).
    flex : (w_x, w_y) the board's parabolic sag in squares (:mod:`aicalib_tf.geometry.board_flex`):
        a board point (X, Y) lies at z = s·(w_x·(1 − u²) + w_y·(1 − v²)); (0, 0) is a flat board.
    shape : () or the first K terms of a board shape in squares (:mod:`aicalib_tf.geometry.board_shape`:
        sag_x, sag_y, twist, cubic_x, ...), added to the flex's z; () is no shape.
    """

    pattern_size: tuple[int, int]
    square_size: float = 1.0
    margin: float = 0.5
    black: float = 0.1
    white: float = 0.85
    flex: tuple[float, float] = (0.0, 0.0)
    shape: tuple[float, ...] = ()

    def __post_init__(self):
        object.__setattr__(self, "pattern_size", check_pattern(self.pattern_size))
        flex = tuple(float(v) for v in np.asarray(self.flex, np.float64).ravel())
        if len(flex) != 2 or not np.all(np.isfinite(flex)):
            raise ValueError(f"flex must be two finite numbers (w_x, w_y) in squares, got {self.flex!r}")
        object.__setattr__(self, "flex", flex)
        shape = tuple(float(v) for v in np.asarray(self.shape, np.float64).ravel())
        if len(shape) > len(SHAPE_TERMS) or not np.all(np.isfinite(shape)):
            raise ValueError(f"shape must be at most {len(SHAPE_TERMS)} finite numbers (squares), got {self.shape!r}")
        object.__setattr__(self, "shape", shape)
        if not self.square_size > 0:
            raise ValueError(f"square_size must be > 0, got {self.square_size}")
        if self.margin < 0:
            raise ValueError(f"margin must be >= 0, got {self.margin}")
        if not (0.0 <= self.black < self.white <= 1.0):
            raise ValueError(f"need 0 <= black < white <= 1, got black={self.black}, white={self.white}")

    @property
    def cols(self) -> int:
        return self.pattern_size[0]

    @property
    def rows(self) -> int:
        return self.pattern_size[1]

    def object_points(self) -> np.ndarray:
        """(cols·rows, 3) float64 inner-corner positions, OpenCV order (index = r·cols + c), flexed by ``flex``
        and shaped by ``shape``."""
        return shaped_points(board_points(pattern_ids(self.pattern_size), self.square_size), self.pattern_size,
                             self._terms(), self.square_size)

    @property
    def bent(self) -> bool:
        """Is the board out of its plane (a nonzero ``flex`` or ``shape``)?"""
        return any(self.flex) or any(self.shape)

    def height(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """(...) z of the flexed (and shaped) board at board-plane positions X, Y (..., board units)."""
        s = self.square_size
        x, y = np.asarray(X) / s, np.asarray(Y) / s
        return s * shape_height(x, y, self.pattern_size, self._terms())

    def _terms(self) -> np.ndarray:
        """(max(2, K),) squares: the board shape's terms with the flex (w_x, w_y) added to its two sags."""
        w = np.zeros(max(2, len(self.shape)))
        w[:len(self.shape)] = self.shape
        w[:2] += self.flex
        return w

    def paper_bounds(self) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1) of the paper in board units."""
        return paper_bounds(self.cols, self.rows, self.square_size, self.margin)

    def centre(self) -> np.ndarray:
        """(3,) centre of the inner-corner grid, board units."""
        return grid_centre(self.cols, self.rows, self.square_size)

    def classify(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """Class of board-plane points: 0 black square, 1 white (square or margin), 2 off the paper.

        X, Y : (...) float arrays in board units (NaN = not on the plane). Returns (...) uint8.
        """
        s = self.square_size
        on_paper, in_squares = paper_masks(X, Y, self.cols, self.rows, s, self.margin)
        with np.errstate(invalid="ignore"):
            # Square (floor(X/s), floor(Y/s)); the one at (-1, -1) is black, so black <=> even sum.
            parity = (np.floor(X / s) + np.floor(Y / s))[in_squares].astype(np.int64) & 1
        out = np.full(np.shape(X), 2, dtype=np.uint8)
        out[on_paper] = 1
        out[in_squares] = parity.astype(np.uint8)
        return out

    def to_dict(self) -> dict:
        return {
            "pattern_size": list(self.pattern_size),
            "square_size": self.square_size,
            "margin": self.margin,
            "black": self.black,
            "white": self.white,
            **({"flex": list(self.flex)} if any(self.flex) else {}),  # squares; absent: a flat board
            **({"shape": list(self.shape)} if any(self.shape) else {}),  # squares, geometry.board_shape's terms
        }


def sample_board(
    rng: np.random.Generator,
    *,
    pattern_size: tuple[int, int] | None = None,
    cols_range: tuple[int, int] = (3, 20),
    rows_range: tuple[int, int] = (3, 15),
    margin_range: tuple[float, float] = (0.15, 1.0),
    black_range: tuple[float, float] = (0.04, 0.22),
    white_range: tuple[float, float] = (0.7, 0.95),
    square_size: float = 25.0,
) -> Board:
    """Draw a board; ``pattern_size`` fixes (cols, rows), otherwise they are drawn from the ranges."""
    if pattern_size is None:
        cols = int(rng.integers(cols_range[0], cols_range[1] + 1))
        rows = int(rng.integers(rows_range[0], rows_range[1] + 1))
        if rows > cols:  # landscape boards are the common case, like the 20x15 maximum
            cols, rows = rows, cols
        pattern_size = (cols, rows)
    return Board(
        pattern_size=pattern_size,
        square_size=square_size,
        margin=float(rng.uniform(*margin_range)),
        black=float(rng.uniform(*black_range)),
        white=float(rng.uniform(*white_range)),
    )
