"""A printed ChArUco board for the renderer: the chessboard :class:`~data_gen.board.Board`'s face
with the markers' bits inside the white squares.

The layout is :class:`aicalib_tf.geometry.charuco.CharucoBoard`'s (our frame: inner corner (c, r) at
(c·s, r·s, 0); square (i, j) covers [(i − 1)·s, i·s] × [(j − 1)·s, j·s]). The board plane is cut,
along each axis, at every square edge and every marker-bit edge; between two cuts the print is
one colour. :meth:`CharucoTarget.axis_cells` numbers those 1-D cells, so the renderer's exactness
argument for chessboards (a pixel whose four corners share a cell on both axes is one colour)
carries over unchanged: the cuts are the same at every square.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from aicalib_tf.geometry.charuco import CharucoBoard
from aicalib_tf.geometry.pose import project_points

from .board import grid_centre, paper_bounds, paper_masks

__all__ = ["CharucoTarget", "sample_charuco", "marker_truth"]


@dataclass(frozen=True)
class CharucoTarget:
    """A ChArUco board as the renderer and the pose sampler see it.

    board : the description. margin : white border around the squares, in squares.
    black, white : printed grey levels in [0, 1].
    """

    board: CharucoBoard
    margin: float = 0.5
    black: float = 0.1
    white: float = 0.85
    _cuts: np.ndarray = field(init=False, repr=False, compare=False)
    _lut: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        if self.margin < 0:
            raise ValueError(f"margin must be >= 0, got {self.margin}")
        if not (0.0 <= self.black < self.white <= 1.0):
            raise ValueError(f"need 0 <= black < white <= 1, got black={self.black}, white={self.white}")
        s, m, n = float(self.board.square), float(self.board.marker), self.board.bits + 2
        cuts = (s - m) / 2.0 + np.arange(n + 1) * (m / n)  # n + 1 cuts inside each square
        object.__setattr__(self, "_cuts", cuts)
        object.__setattr__(self, "_lut", self._colour_table())

    # --- the Board interface (data_gen.board.Board) ------------------------------------------
    @property
    def pattern_size(self) -> tuple[int, int]:
        return self.board.pattern_size

    @property
    def square_size(self) -> float:
        return float(self.board.square)

    @property
    def cols(self) -> int:
        return self.pattern_size[0]

    @property
    def rows(self) -> int:
        return self.pattern_size[1]

    def object_points(self) -> np.ndarray:
        """(cols·rows, 3) float64 inner corners, OpenCV's ChArUco id order."""
        return self.board.object_points()

    def paper_bounds(self) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1) of the paper in board units."""
        return paper_bounds(self.cols, self.rows, self.square_size, self.margin)

    def centre(self) -> np.ndarray:
        """(3,) centre of the inner-corner grid, board units."""
        return grid_centre(self.cols, self.rows, self.square_size)

    # --- colours ----------------------------------------------------------------------------
    @property
    def _per_square(self) -> int:
        return len(self._cuts) + 1

    def _colour_table(self) -> np.ndarray:
        """(Y·k, X·k) uint8, k cells per square per axis: 0 black, 1 white."""
        X, Y = self.board.squares
        k, n = self._per_square, self.board.bits + 2
        lut = np.zeros((Y * k, X * k), np.uint8)
        for j in range(Y):
            for i in range(X):
                if self.board.is_marker_square(i, j):
                    lut[j * k: (j + 1) * k, i * k: (i + 1) * k] = 1
        for mid, (i, j) in zip(self.board.marker_ids(), self.board.marker_squares()):
            lut[j * k + 1: j * k + 1 + n, i * k + 1: i * k + 1 + n] = self.board.square_bits(int(mid))
        return lut

    def axis_cells(self, A: np.ndarray) -> np.ndarray:
        """(...) float board coordinate (X or Y, NaN allowed) -> (...) float64 index of its 1-D cell:
        the print is one colour between neighbouring cuts (square and marker-bit edges)."""
        s = self.square_size
        with np.errstate(invalid="ignore"):
            sq = np.floor(A / s)
            within = np.searchsorted(self._cuts, np.nan_to_num(A - sq * s, nan=0.0), side="right")
        return np.where(np.isnan(A), -1e9, sq * self._per_square + within)

    def classify(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """Class of board-plane points: 0 black (square or marker bit), 1 white, 2 off the paper.

        X, Y : (...) float arrays in board units (NaN = not on the plane). Returns (...) uint8.
        """
        on_paper, inside = paper_masks(X, Y, self.cols, self.rows, self.square_size, self.margin)
        k = self._per_square
        cx = (self.axis_cells(X[inside]) + k).astype(np.int64)  # square −1 is the table's column 0
        cy = (self.axis_cells(Y[inside]) + k).astype(np.int64)
        out = np.full(np.shape(X), 2, dtype=np.uint8)
        out[on_paper] = 1
        out[inside] = self._lut[cy, cx]
        return out

    def to_dict(self) -> dict:
        return {**self.board.to_dict(), "square_size": self.square_size, "margin": self.margin,
                "black": self.black, "white": self.white}


def sample_charuco(rng: np.random.Generator, board: CharucoBoard, *,
                   margin_range: tuple[float, float] = (0.15, 1.0),
                   black_range: tuple[float, float] = (0.04, 0.22),
                   white_range: tuple[float, float] = (0.7, 0.95)) -> CharucoTarget:
    """Draw the paper (margin, grey levels) of a ChArUco board, as :func:`data_gen.board.sample_board`."""
    return CharucoTarget(board, margin=float(rng.uniform(*margin_range)), black=float(rng.uniform(*black_range)),
                         white=float(rng.uniform(*white_range)))


def marker_truth(target: CharucoTarget, rvec, tvec, camera) -> dict:
    """The markers' exact image positions: {"ids": (M,), "corners": (M, 4, 2) px, "centres": (M, 2) px},
    as lists for a label (corners in OpenCV's order: top-left, top-right, bottom-right, bottom-left)."""
    obj = target.board.marker_corners().reshape(-1, 3)
    px = project_points(obj, rvec, tvec, camera).reshape(-1, 4, 2)
    ctr = project_points(target.board.marker_corners().mean(axis=1), rvec, tvec, camera)
    return {"ids": target.board.marker_ids().tolist(), "corners": px.tolist(), "centres": ctr.tolist()}
