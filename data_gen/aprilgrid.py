"""A printed Kalibr AprilGrid for the renderer, with exact truth for every tag corner.

The layout is :class:`aicalib_tf.geometry.aprilgrid.AprilGrid`'s (our frame, x right and y down the
page; lattice unit u = ``square_size``): tag (c, r) (column from the left, row from the top) covers
[c·P, c·P + t] × [r·P, r·P + t], P = t + g the pitch, t the tag's side and g the gap; a black square
of side g fills every gap crossing, from −g to cols·P (rows·P) along each axis. The tags' bits are
OpenCV's AprilTag dictionary's (:func:`aicalib_tf.geometry.aprilgrid.tag_image`, the code turned as
printed), with Kalibr's two-bit black border.

Along each axis the plane is cut at every pitch, at the tag's n + 4 bit edges inside it and at the
tag's far edge; between two cuts the print is one colour. :meth:`AprilGridTarget.axis_cells` numbers
those 1-D cells, so the renderer's exactness argument for chessboards (a pixel whose four corners share
a cell on both axes is one colour) carries over: the cuts are the same in every pitch, and the printed
area's edges (−g and cols·P) are cuts too.

Corners: :meth:`AprilGridTarget.object_points` gives all 4·cols·rows tag corners in
:meth:`~aicalib_tf.geometry.aprilgrid.AprilGrid.corner_ids` order (row-major from the top-left),
their lattice ids in :meth:`AprilGridTarget.corner_ids`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aicalib_tf.geometry.aprilgrid import AprilGrid, tag_image
from aicalib_tf.geometry.pose import project_points

from .marker_print import MarkerPrint, sample_paper

__all__ = ["AprilGridTarget", "sample_aprilgrid", "tag_truth"]


@dataclass(frozen=True)
class AprilGridTarget(MarkerPrint):
    """An AprilGrid as the renderer and the pose sampler see it.

    board : the description. margin : white paper beyond the corner squares, in tag sides.
    black, white : printed grey levels in [0, 1].
    """

    board: AprilGrid
    margin: float = 0.25

    @property
    def period(self) -> float:
        """The pitch P: the print repeats every tag."""
        return self.pitch

    def _cut_positions(self) -> np.ndarray:
        """n + 1 cuts in [0, t], n = bits + 4 bit cells across a tag (its border included)."""
        n = self.board.bits + 4
        return self.tag_side * np.arange(n + 1) / n

    # --- sizes, board units ------------------------------------------------------------------
    @property
    def tag_side(self) -> float:
        """t: a tag's side (its black border's outer edge)."""
        return self.board.fraction[1] * self.square_size

    @property
    def pitch(self) -> float:
        """P = t + g: from one tag's left edge to the next one's."""
        a, b = self.board.fraction
        return (a + b) * self.square_size

    # --- the Board interface (data_gen.board.Board) ------------------------------------------
    @property
    def pattern_size(self) -> tuple[int, int]:
        """(cols, rows) of the id lattice (most lattice points hold no corner)."""
        return self.board.pattern_size

    @property
    def square_size(self) -> float:
        """The lattice unit u, board units."""
        return float(self.board.square_size)

    @property
    def cols(self) -> int:
        return self.board.tags[0]

    @property
    def rows(self) -> int:
        return self.board.tags[1]

    def corner_ids(self) -> np.ndarray:
        """(4·cols·rows, 2) int64 lattice ids of the corners, :meth:`object_points`' order."""
        return self.board.corner_ids()

    def object_points(self) -> np.ndarray:
        """(4·cols·rows, 3) float64 tag corners, board units, row-major from the top-left."""
        return self.board.object_points()

    def printed_bounds(self) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1) of the printed area (the outer corner squares' outer edges), board units."""
        g = self.pitch - self.tag_side
        return (-g, -g, self.cols * self.pitch, self.rows * self.pitch)

    def paper_bounds(self) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1) of the paper, board units."""
        m = self.margin * self.tag_side
        x0, y0, x1, y1 = self.printed_bounds()
        return (x0 - m, y0 - m, x1 + m, y1 + m)

    def centre(self) -> np.ndarray:
        """(3,) centre of the corners' extent, board units."""
        return np.array([(self.pattern_size[0] - 1) * self.square_size / 2.0,
                         (self.pattern_size[1] - 1) * self.square_size / 2.0, 0.0])

    # --- colours ----------------------------------------------------------------------------
    def _colour_table(self) -> np.ndarray:
        """((rows + 1)·k, (cols + 1)·k) uint8, k cells per pitch per axis, pitch −1 first: 0 black, 1 white."""
        k, n = self._per_period, self.board.bits + 4
        lut = np.ones(((self.rows + 1) * k, (self.cols + 1) * k), np.uint8)
        gap = np.arange(self.rows + 1) * k + k - 1, np.arange(self.cols + 1) * k + k - 1
        lut[np.ix_(*gap)] = 0  # the squares at every gap crossing
        for tag_id in self.board.tag_ids():
            c, r = (int(v) + 1 for v in self.board.tag_cell(int(tag_id)))
            lut[r * k + 1: r * k + 1 + n, c * k + 1: c * k + 1 + n] = tag_image(self.board, int(tag_id), n) > 127
        return lut

    def _masks(self, X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x0, y0, x1, y1 = self.paper_bounds()
        p0, q0, p1, q1 = self.printed_bounds()
        with np.errstate(invalid="ignore"):
            on_paper = (X >= x0) & (X < x1) & (Y >= y0) & (Y < y1)
            return on_paper, on_paper & (X >= p0) & (X < p1) & (Y >= q0) & (Y < q1)

    def to_dict(self) -> dict:
        return {**self.board.to_dict(), "margin": self.margin, "black": self.black, "white": self.white}


def sample_aprilgrid(rng: np.random.Generator, board: AprilGrid, *,
                     margin_range: tuple[float, float] = (0.1, 0.6), **ranges) -> AprilGridTarget:
    """Draw the paper (margin, grey levels) of an AprilGrid (:func:`data_gen.marker_print.sample_paper`)."""
    return sample_paper(AprilGridTarget, rng, board, margin_range, **ranges)


def tag_truth(target: AprilGridTarget, rvec, tvec, camera) -> dict:
    """The tags' exact image positions: {"ids": (K,), "corners": (K, 4, 2) px, "centres": (K, 2) px}
    as lists for a label, corners in the order OpenCV's aruco reports them for the printed tag."""
    board = target.board
    ids = board.tag_ids()
    obj = board.object_points(board.tag_corner_ids(ids).reshape(-1, 2))
    px = project_points(obj, rvec, tvec, camera).reshape(-1, 4, 2)
    centres = project_points(obj.reshape(-1, 4, 3).mean(axis=1), rvec, tvec, camera)
    return {"ids": ids.tolist(), "corners": px.tolist(), "centres": centres.tolist()}
