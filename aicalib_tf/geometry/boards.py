"""One reader for every ``--board``: a ChArUco board, a Kalibr AprilGrid (its description or target
YAML, whose checkerboard is a chessboard) or an OpenCV circle grid.

``read_board(text)`` dispatches on the text's form; each kind's parser raises ValueError naming the
field (or the file) and the problem. A command that does not read circle grids names that with
``circles_refused``: a bad circle grid still names its bad field first, a good one gets one line
saying where circle grids are read.
"""

from __future__ import annotations

from aicalib_tf.geometry.aprilgrid import AprilGrid, Checkerboard, is_aprilgrid, load_board
from aicalib_tf.geometry.charuco import CharucoBoard
from aicalib_tf.geometry.charuco import parse_board as parse_charuco
from aicalib_tf.geometry.circles import CircleGrid, is_circles
from aicalib_tf.geometry.circles import parse_board as parse_circles

__all__ = ["read_board", "CIRCLES_READ_BY"]

CIRCLES_READ_BY = "calibrate reads them from photos"


def read_board(text: str, circles_refused: str | None = None) -> CharucoBoard | AprilGrid | Checkerboard | CircleGrid:
    """The board ``text`` describes. circles_refused : the command's name when it does not read circle
    grids (a good one is then refused: ValueError, one line)."""
    if is_circles(text):
        grid = parse_circles(text)
        if circles_refused:
            raise ValueError(f"board {grid.describe()}: {circles_refused} does not read circle grids; {CIRCLES_READ_BY}")
        return grid
    return load_board(text) if is_aprilgrid(text) else parse_charuco(text)
