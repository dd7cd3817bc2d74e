"""What the printed marker boards (:mod:`data_gen.charuco`, :mod:`data_gen.aprilgrid`) share for the renderer.

A marker board's print repeats with a period p along each axis (a ChArUco board's square, an
AprilGrid's tag pitch); inside each period the plane is cut at fixed offsets (``_cuts``: marker-bit
and tag edges), and between two cuts the print is one colour. :meth:`MarkerPrint.axis_cells`
numbers those 1-D cells, cell ``q·k + i`` for the i-th cut interval of period q (k cells a period,
cell 0 the stretch before the first cut); a colour table indexed by (row cell, column cell), period
−1 first, holds each cell's colour. So the renderer's exactness argument for chessboards (a pixel
whose four corners share a cell on both axes is one colour) carries over unchanged.

A subclass gives the period (:attr:`MarkerPrint.period`), the cuts (``_cut_positions``), the colour
table (``_colour_table``) and the paper's extent (``_masks``). :func:`sample_paper` draws the paper
(margin, grey levels) of either.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["MarkerPrint", "sample_paper"]


@dataclass(frozen=True)
class MarkerPrint:
    """A marker board on paper. board : the description. margin : white paper around the print,
    in the subclass's unit (squares, tag sides). black, white : printed grey levels in [0, 1]."""

    board: object
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
        object.__setattr__(self, "_cuts", self._cut_positions())
        object.__setattr__(self, "_lut", self._colour_table())

    # --- what a board gives ------------------------------------------------------------------
    @property
    def period(self) -> float:
        """p, board units: the print repeats every p along each axis."""
        raise NotImplementedError

    def _cut_positions(self) -> np.ndarray:
        """(n,) float64 increasing offsets in [0, p) (or [0, p]) where the print changes colour."""
        raise NotImplementedError

    def _colour_table(self) -> np.ndarray:
        """(rows·k, cols·k) uint8, k = :attr:`_per_period` cells a period, period −1 first: 0 black, 1 white."""
        raise NotImplementedError

    def _masks(self, X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(on the paper, inside the printed area), each (...) bool, of board-plane points X, Y."""
        raise NotImplementedError

    # --- shared ----------------------------------------------------------------------------
    @property
    def _per_period(self) -> int:
        return len(self._cuts) + 1

    def axis_cells(self, A: np.ndarray) -> np.ndarray:
        """(...) float board coordinate (X or Y, NaN allowed) -> (...) float64 index of its 1-D cell:
        the print is one colour between neighbouring cuts."""
        p = self.period
        with np.errstate(invalid="ignore"):
            q = np.floor(A / p)
            within = np.searchsorted(self._cuts, np.nan_to_num(A - q * p, nan=0.0), side="right")
        return np.where(np.isnan(A), -1e9, q * self._per_period + within)

    def _table_index(self, A: np.ndarray) -> np.ndarray:
        """(M,) finite board coordinates -> (M,) int64 colour-table index: :meth:`axis_cells` without
        its NaN handling (points inside the print are finite), shifted by a period (period −1 first)."""
        p, k = self.period, self._per_period
        q = np.floor(A / p)
        return (q * k + np.searchsorted(self._cuts, A - q * p, side="right") + k).astype(np.int64)

    def classify(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """Class of board-plane points: 0 black, 1 white, 2 off the paper.

        X, Y : (...) float arrays in board units (NaN = not on the plane). Returns (...) uint8.
        """
        on_paper, inside = self._masks(X, Y)
        cx, cy = self._table_index(X[inside]), self._table_index(Y[inside])
        out = np.full(np.shape(X), 2, dtype=np.uint8)
        out[on_paper] = 1
        out[inside] = self._lut[cy, cx]
        return out


def sample_paper(kind: type, rng: np.random.Generator, board, margin_range: tuple[float, float],
                 black_range: tuple[float, float] = (0.04, 0.22),
                 white_range: tuple[float, float] = (0.7, 0.95)) -> MarkerPrint:
    """``kind(board, ...)`` (a :class:`MarkerPrint` subclass) on a drawn paper: margin, then black,
    then white, each uniform in its range (as :func:`data_gen.board.sample_board` draws a chessboard's)."""
    return kind(board, margin=float(rng.uniform(*margin_range)), black=float(rng.uniform(*black_range)),
                white=float(rng.uniform(*white_range)))
