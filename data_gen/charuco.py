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

from dataclasses import dataclass

import numpy as np

from aicalib_tf.geometry.charuco import CharucoBoard
from aicalib_tf.geometry.pose import project_points

from .board import grid_centre, paper_bounds, paper_masks
from .marker_print import MarkerPrint, sample_paper

__all__ = ["CharucoTarget", "sample_charuco", "marker_truth"]


@dataclass(frozen=True)
class CharucoTarget(MarkerPrint):
    """A ChArUco board as the renderer and the pose sampler see it.

    board : the description. margin : white border around the squares, in squares.
    black, white : printed grey levels in [0, 1].
    """

    board: CharucoBoard
    margin: float = 0.5

    @property
    def period(self) -> float:
        """The square: the print repeats every square."""
        return self.square_size

    def _cut_positions(self) -> np.ndarray:
        """n + 1 cuts inside each square: the marker's bit edges."""
        s, m, n = float(self.board.square), float(self.board.marker), self.board.bits + 2
        return (s - m) / 2.0 + np.arange(n + 1) * (m / n)

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
    def _colour_table(self) -> np.ndarray:
        """(Y·k, X·k) uint8, k cells per square per axis: 0 black, 1 white."""
        X, Y = self.board.squares
        k, n = self._per_period, self.board.bits + 2
        lut = np.zeros((Y * k, X * k), np.uint8)
        for j in range(Y):
            for i in range(X):
                if self.board.is_marker_square(i, j):
                    lut[j * k: (j + 1) * k, i * k: (i + 1) * k] = 1
        for mid, (i, j) in zip(self.board.marker_ids(), self.board.marker_squares()):
            lut[j * k + 1: j * k + 1 + n, i * k + 1: i * k + 1 + n] = self.board.square_bits(int(mid))
        return lut

    def _masks(self, X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return paper_masks(X, Y, self.cols, self.rows, self.square_size, self.margin)

    def to_dict(self) -> dict:
        return {**self.board.to_dict(), "square_size": self.square_size, "margin": self.margin,
                "black": self.black, "white": self.white}


def sample_charuco(rng: np.random.Generator, board: CharucoBoard, *,
                   margin_range: tuple[float, float] = (0.15, 1.0), **ranges) -> CharucoTarget:
    """Draw the paper (margin, grey levels) of a ChArUco board (:func:`data_gen.marker_print.sample_paper`)."""
    return sample_paper(CharucoTarget, rng, board, margin_range, **ranges)


def marker_truth(target: CharucoTarget, rvec, tvec, camera) -> dict:
    """The markers' exact image positions: {"ids": (M,), "corners": (M, 4, 2) px, "centres": (M, 2) px},
    as lists for a label (corners in OpenCV's order: top-left, top-right, bottom-right, bottom-left)."""
    obj = target.board.marker_corners().reshape(-1, 3)
    px = project_points(obj, rvec, tvec, camera).reshape(-1, 4, 2)
    ctr = project_points(target.board.marker_corners().mean(axis=1), rvec, tvec, camera)
    return {"ids": target.board.marker_ids().tolist(), "corners": px.tolist(), "centres": ctr.tolist()}
