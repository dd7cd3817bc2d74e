"""ChArUco boards: the chessboard pipeline's lattice, named by the markers in its white squares.

The X-junctions of a ChArUco board are chessboard corners: the CNN, the saddle refinement and the
grid assembly of :mod:`aicalib_tf.detect.pipeline` find them as on a chessboard (the markers are
clutter the grid leaves out), with lattice ids (a, b) that keep the grid's shape but not its
place on the board. The markers then fix the place. Each marker, read by OpenCV's detector or
from its bits sampled through the lattice (:mod:`aicalib_tf.detect.charuco.markers`), lies in one lattice
cell and says which board square that cell is and how the board's axes run: one hypothesis
board (c, r) = A·(a, b) + t. The hypothesis with the most markers wins when it has at least two,
or one with none against it, and no more than a third as many against it.

Every returned corner carries its board id, and an id must be decided: a corner is kept only
when a marker of the winning hypothesis lies within :data:`SUPPORT` squares of it, no marker of
another hypothesis lies within twice that, and its id falls on the board. So a corner whose
markers are all unreadable (hidden, far out of focus) is left out rather than guessed.

Several boards in one image are several grids of corners, each named on its own. Boards with
different dictionaries or id ranges are told apart by their markers; two boards with the same ids come back as two detections,
both flagged ``duplicate``, never merged.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass

import numpy as np

from aicalib_tf.detect.charuco.markers import Placed, aruco_markers, decode_cells, place_marker, verify_cells
from aicalib_tf.detect.charuco.grow import SUPPORT
from aicalib_tf.detect.charuco.layout import layout_mismatch
from aicalib_tf.geometry.charuco import CharucoBoard

__all__ = ["CharucoDetection", "SUPPORT", "name_lattice", "detect_charuco_boards", "square_lattice"]



@dataclass(frozen=True)
class CharucoDetection:
    """One ChArUco board found in an image.

    board : its description. corners : (N, 2) float32 (x, y) px, ordered by id (row-major).
    ids : (N, 2) int32 (col, row) on the board; ``charuco_ids`` (N,) = row·cols + col (OpenCV's).
    marker_ids : (M,) int64 markers that named the board; marker_corners (M, 4, 2) float64 px.
    complete : every inner corner found. duplicate : another board in the image has the same ids.
    image_size : (width, height) px.
    """

    board: CharucoBoard
    corners: np.ndarray
    ids: np.ndarray
    marker_ids: np.ndarray
    marker_corners: np.ndarray
    complete: bool
    image_size: tuple[int, int]
    duplicate: bool = False

    @property
    def charuco_ids(self) -> np.ndarray:
        return (self.ids[:, 1] * self.board.pattern_size[0] + self.ids[:, 0]).astype(np.int64)

    @property
    def found(self) -> bool:
        return len(self.corners) > 0


def _hypothesis(m: Placed, board: CharucoBoard) -> tuple[tuple, np.ndarray]:
    """(key, t) of board (c, r) = A·(a, b) + t: the marker's cell centre goes to its square's centre."""
    i, j = board.marker_square_of()[m.id]
    t = np.array([i - 0.5, j - 0.5]) - m.A @ (np.asarray(m.cell, np.float64) + 0.5)
    t = np.rint(t).astype(np.int64)
    return (tuple(m.A.ravel()), tuple(t)), t


def _markers(gray: np.ndarray, gray_u8: np.ndarray, ids: np.ndarray, pts: np.ndarray,
             board: CharucoBoard, read: tuple[np.ndarray, np.ndarray]) -> list[Placed]:
    """The board's markers on this lattice: OpenCV's where it read them, the lattice decoder's elsewhere."""
    placed = []
    for mid, corners in zip(*read):
        m = place_marker(ids, pts, int(mid), corners, board)
        if m is not None:
            placed.append(m)
    taken = {m.cell for m in placed}
    return placed + decode_cells(gray, ids, pts, board, skip=taken)


def _winner(markers: list[Placed], board: CharucoBoard):
    """(key, A, t, supporting markers, opposing markers) of the best hypothesis, or None."""
    votes = defaultdict(list)
    for m in markers:
        key, t = _hypothesis(m, board)
        votes[key].append(m)
    if not votes:
        return None
    key = max(votes, key=lambda k: (len(votes[k]), -sum(m.errors for m in votes[k])))
    support = votes[key]
    against = [m for k, ms in votes.items() if k != key for m in ms]
    if len(support) < 2 and against or 3 * len(against) > len(support):
        return None
    A = np.array(key[0], np.int64).reshape(2, 2)
    return A, np.array(key[1], np.int64), support, against


def name_lattice(gray: np.ndarray, gray_u8: np.ndarray, ids: np.ndarray, pts: np.ndarray,
                 board: CharucoBoard, read=None) -> CharucoDetection | None:
    """Board ids for a lattice of corners (ids (N, 2) lattice coordinates, pts (N, 2) px), or None.

    gray : (H, W) float32 in [0, 1]; gray_u8 the same as uint8. read : OpenCV's markers
    (:func:`aicalib_tf.detect.charuco.markers.aruco_markers`) when the caller has them.
    """
    ids = np.asarray(ids, np.int64).reshape(-1, 2)
    pts = np.asarray(pts, np.float64).reshape(-1, 2)
    read = aruco_markers(gray_u8, board) if read is None else read
    win = _winner(_markers(gray, gray_u8, ids, pts, board, read), board)
    if win is None:
        return None
    A, t, support, against = win
    support = support + verify_cells(gray, ids, pts, board, A, t, skip={m.cell for m in support + against})
    named = ids @ A.T + t
    cols, rows = board.pattern_size
    keep = (named[:, 0] >= 0) & (named[:, 0] < cols) & (named[:, 1] >= 0) & (named[:, 1] < rows)
    keep &= _near(ids, support, SUPPORT) & ~_near(ids, against, 2 * SUPPORT)
    if not keep.any():
        return None
    order = np.lexsort((named[keep, 0], named[keep, 1]))
    h, w = gray.shape
    mk = sorted(support, key=lambda m: m.id)
    return CharucoDetection(board, pts[keep][order].astype(np.float32), named[keep][order].astype(np.int32),
                            np.array([m.id for m in mk], np.int64),
                            np.array([m.corners for m in mk], np.float64).reshape(-1, 4, 2),
                            bool(keep.sum() == cols * rows), (w, h))


def _near(ids: np.ndarray, markers: list[Placed], radius: float) -> np.ndarray:
    """(N,) bool: a lattice corner within ``radius`` cells (Chebyshev) of a marker's cell centre."""
    if not markers:
        return np.zeros(len(ids), bool)
    centres = np.array([m.cell for m in markers], np.float64) + 0.5
    d = np.abs(ids[:, None, :].astype(np.float64) - centres[None]).max(axis=2)
    return (d <= radius).any(axis=1)


def detect_charuco_boards(gray: np.ndarray, boards: list[CharucoBoard], model, threshold: float = 0.5,
                          more_lattices=None, refused: dict | None = None) -> list[CharucoDetection]:
    """Every ChArUco board of ``boards`` in the image, largest first.

    gray : (H, W) float32 in [0, 1]. model : the corner network. The grids of corners come from
    :func:`aicalib_tf.detect.charuco.grid.lattices`, with the markers OpenCV reads for every board's
    dictionary left out; each grid is named by the board whose markers decide the most of its
    corners (a grid whose steps are not the squares', as the grid assembly sometimes builds on a
    ChArUco board, is read in squares first: :func:`square_lattice`). Grids of one board
    that share its markers at the same places are merged; corners beside the markers are then
    looked for where the markers put them (:mod:`aicalib_tf.detect.charuco.complete`), and the board
    grown along its own lattice (:mod:`aicalib_tf.detect.charuco.grow`: steep views, the frame's edge).
    more_lattices : ``f(pattern_size) -> [(ids, pts)]``, asked for a board none of these grids
    names (the chessboard pipeline's own search, whose pyramid and partial-board growth reach
    boards whose markers OpenCV cannot read, e.g. under heavy noise).
    refused : a dict that receives {board: why} for each board whose markers contradict its layout
    (:func:`aicalib_tf.detect.charuco.layout.layout_mismatch`: a description of another size); such a
    board is not read in this image, rather than read with ids from the wrong layout.
    """
    from aicalib_tf.detect.charuco.complete import complete_from_markers, merge_same_board, polish
    from aicalib_tf.detect.charuco.grid import lattices
    from aicalib_tf.detect.charuco.grow import grow_along_lattice
    from aicalib_tf.detect.corners.refine import Smoothed
    from aicalib_tf.io import quantize

    u8 = quantize(gray)
    smoothed = Smoothed(gray)  # its smoothed copies, made once for every stage
    reads = {b: aruco_markers(u8, b) for b in dict.fromkeys(boards)}
    for board, (ids, corners) in list(reads.items()):
        why = layout_mismatch(board, ids, corners)
        if why is not None:
            del reads[board]
            if refused is not None:
                refused[board] = why
    if not reads:
        return []
    quads = np.concatenate([r[1] for r in reads.values()])
    ratio = min((b.square - b.marker) / (2.0 * b.marker) for b in reads)
    limit = max(max(b.pattern_size) for b in reads) + 1
    found = _name_all(gray, u8, reads, lattices(model, gray, threshold, quads, ratio, limit, smoothed))
    if more_lattices is not None:
        for board in [b for b in reads if b not in {d.board for d in found}]:
            found += _name_all(gray, u8, {board: reads[board]}, more_lattices(board.pattern_size))
    found = merge_same_board(found)
    found = [grow_along_lattice(gray, complete_from_markers(gray, d, reads[d.board], smoothed), smoothed) for d in found]
    h, w = gray.shape
    for board in (b for b in reads if b not in {d.board for d in found} and len(reads[b][0]) >= 2):
        seed = CharucoDetection(board, np.zeros((0, 2), np.float32), np.zeros((0, 2), np.int32),
                                reads[board][0], reads[board][1], False, (w, h))
        seed = complete_from_markers(gray, seed, reads[board], smoothed)
        if len(seed.corners) >= 4:
            found.append(grow_along_lattice(gray, seed, smoothed))
    found = [d for d in (polish(gray, d, smoothed=smoothed) for d in found) if len(d.corners)]
    return _flag_duplicates(sorted(found, key=lambda d: -len(d.corners)))


def _name_all(gray: np.ndarray, u8: np.ndarray, reads: dict, grids: list) -> list[CharucoDetection]:
    """Each grid [(ids, pts)] named by the board of ``reads`` ({board: OpenCV's markers}) whose
    markers decide the most of its corners; grids no board names are left out."""
    quads = np.concatenate([r[1] for r in reads.values()])
    found = []
    for ids, pts in grids:
        best = None
        lat = square_lattice(ids, pts, quads, min(b.marker / b.square for b in reads))
        for board in reads:
            det = name_lattice(gray, u8, lat, pts, board, reads[board]) if lat is not None and len(ids) >= 4 else None
            if det is not None and (best is None or len(det.corners) > len(best.corners)):
                best = det
        if best is not None:
            found.append(best)
    return found


def square_lattice(ids: np.ndarray, pts: np.ndarray, quads: np.ndarray, side: float) -> np.ndarray | None:
    """Lattice ids (N, 2) in steps of one square: a grid assembled on every other corner (steps of
    two squares, or of a square's diagonal) is turned back, by the markers' sides measured in its own
    steps. side : marker / square. Returns ids (N, 2) int64 (``ids`` when the steps are squares
    already or no marker tells), None when the markers tell no whole-number change of steps.
    """
    from aicalib_tf.detect.charuco.markers import lattice_coords

    axes = []
    for quad in quads:
        lat = lattice_coords(ids, pts, quad)
        if lat is None:
            continue
        centre = lat.mean(axis=0)
        if (centre < ids.min(axis=0) - 1).any() or (centre > ids.max(axis=0) + 1).any():
            continue
        axes.append(np.column_stack([lat[1] - lat[0], lat[3] - lat[0]]) / side)
    if not axes:
        return ids
    steps = np.median(np.array(axes), axis=0)  # columns: one square along board x, y, in grid steps
    if np.abs(np.abs(np.linalg.det(steps)) - 1.0) < 0.25:
        return ids
    M = np.linalg.inv(steps)
    if np.abs(M - np.rint(M)).max() > 0.2:
        return None
    return ids @ np.rint(M).astype(np.int64).T


def _flag_duplicates(found: list[CharucoDetection]) -> list[CharucoDetection]:
    """Flag detections of boards with the same description (same ids): reported, never merged."""
    from dataclasses import replace

    count = defaultdict(int)
    for d in found:
        count[d.board] += 1
    return [replace(d, duplicate=count[d.board] > 1) for d in found]
