"""The detector's result: :class:`Detection`, and why no board came back (``REASONS``).

Every chessboard search (:func:`aicalib_tf.detect.pipeline.detect_corners`, the tracker, the
AprilGrid detector) returns a :class:`Detection`; a ChArUco board found by its markers becomes one
with :func:`from_charuco`. ``REASONS`` orders the ways a search can end without a board, from the
least to the furthest it got, so that the furthest over all scales is the one reported.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aicalib_tf.detect.chessboard.grid import MIN_CORNERS

__all__ = ["Detection", "NO_CANDIDATES", "NO_GRID", "NO_MATCH", "UNDECIDED", "REASONS", "from_charuco"]


@dataclass(frozen=True)
class Detection:
    """A detected chessboard.

    corners : (N, 2) float32 (x, y) px, in OpenCV order when ``complete``; a partial board's are
        ordered by id (row-major), with the unseen corners left out.
    ids : (N, 2) int32, (col, row) of each corner on the board (see :mod:`aicalib_tf.detect.pipeline`'s
        docstring for a partial board's).
    scores : (N,) float32 CNN corner weights in [0, 1]; 0 for a corner the CNN missed that was
        recovered where the grid predicts one (saddle fit and ring test on the image).
    pattern_size : (cols, rows) inner corners (the found grid's size when none was given).
    complete : every corner of ``pattern_size`` is present.
    image_size : (width, height) px.
    reason : why no board came back ("" when one did): one of ``REASONS``, the furthest the
        search got on any scale.
    relative : the ids are relative to the visible grid, not fixed on the pattern (asked for with
        ``detect_corners(..., relative=True)``; a board larger than the frame, say).
    sigmas : (N,) float32 px, each corner's expected error, one standard deviation per axis
        (:mod:`aicalib_tf.detect.corners.sigma`); None from a detector that does not give it.
    """

    corners: np.ndarray
    ids: np.ndarray
    scores: np.ndarray
    pattern_size: tuple[int, int] | None
    complete: bool
    image_size: tuple[int, int]
    reason: str = ""
    relative: bool = False
    sigmas: np.ndarray | None = None

    @property
    def found(self) -> bool:
        return len(self.corners) > 0


NO_CANDIDATES = f"fewer than {MIN_CORNERS} corner candidates"
NO_GRID = "no grid of chessboard corners"
NO_MATCH = "grids of corners, but none fits the pattern as a board"
UNDECIDED = ("part of a board is in view, but the image leaves open where it lies on the pattern "
             "(e.g. one corner of the board, its other two sides cut by the frame)")
REASONS = (NO_CANDIDATES, NO_GRID, NO_MATCH, UNDECIDED)  # from the least to the furthest the search got


def from_charuco(det, board, size: tuple[int, int], why: str | None = None) -> Detection:
    """A ChArUco detection (or None, ``why`` when known) as a :class:`Detection` of the board's inner corners."""
    if det is None:
        return Detection(np.zeros((0, 2), np.float32), np.zeros((0, 2), np.int32), np.zeros(0, np.float32),
                         board.pattern_size, False, size, why or "no ChArUco board whose markers decide its corners")
    return Detection(det.corners, det.ids, np.ones(len(det.corners), np.float32), board.pattern_size, det.complete, size)
