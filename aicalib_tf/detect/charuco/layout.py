"""Whether the markers read in an image agree with a ChArUco board's layout, and which size they fit.

A board description with the wrong number of squares still names markers the image holds (its
ids overlap the printed board's), but puts them in other squares: a calibration from it has
wrong corner ids. The markers themselves tell. Each marker's four corners give the board's axes
where it lies (top-left → top-right runs along the board's +x, top-left → bottom-left along +y,
each side ``marker`` long), so the centre of a neighbouring marker, read in the mean of the two
markers' axes, says how many squares apart the two are along x and y. The layout says how many
they should be: their squares' difference. Only diagonal neighbours are compared (centres at most
:data:`NEIGHBOUR_SQUARES` apart): a steeply tilted marker's quad comes out up to a fifth short along
the tilt (its border thins), so an offset of two squares read from it can be off by half a square;
and a diagonal pair spans two rows, where a wrong number of squares across shows.

On the benchmark's ChArUco conditions (``aicalib_tf.bench.charuco``, 6 renders each of 8 conditions,
two boards) no true description was refused; an 11x8 board read as 10x8, 12x9 or 9x8 was refused in
48 of 54 renders and gave no corner in the others (0 wrong ids), and read as 11x9 (one row more than
printed, the same layout for every id seen) it gave 1009 corners, all right.

When enough pairs disagree (:func:`layout_mismatch`), the board is refused in that image, and the
sizes whose layouts every pair agrees with are named (:func:`fitting_sizes`).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from aicalib_tf.geometry.charuco import CharucoBoard

__all__ = ["NEIGHBOUR_SQUARES", "OFFSET_TOLERANCE", "pair_offsets", "disagreements", "fitting_sizes",
           "layout_mismatch"]

NEIGHBOUR_SQUARES = 1.6  # markers compared when their centres are at most this many squares apart (diagonal neighbours)
OFFSET_TOLERANCE = 0.45  # squares: a pair agrees with a layout when each axis's offset is this close
MIN_DISAGREEING = 2  # pairs: fewer never refuse a board (one misread marker)
DISAGREEING_SHARE = 0.2  # of the pairs compared
_MAX_SQUARES = 40  # the largest board side tried when naming the sizes that fit


def pair_offsets(board: CharucoBoard, corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Measured offsets between neighbouring markers.

    corners : (M, 4, 2) float64 px, each marker's corners (top-left, top-right, bottom-right,
    bottom-left, as OpenCV reads them). Returns pairs (P, 2) int64 indices (a, b) into the markers
    and offsets (P, 2) float64: b's centre minus a's, in squares along the board's (x, y).
    """
    corners = np.asarray(corners, np.float64).reshape(-1, 4, 2)
    centres = corners.mean(axis=1)
    ex = (corners[:, 1] - corners[:, 0] + corners[:, 2] - corners[:, 3]) / 2.0  # px per marker side along x
    ey = (corners[:, 3] - corners[:, 0] + corners[:, 2] - corners[:, 1]) / 2.0
    axes = np.stack([ex, ey], axis=2) * (board.square / board.marker)  # (M, 2, 2): px per square, columns x, y
    a, b = np.triu_indices(len(corners), k=1)
    local = (axes[a] + axes[b]) / 2.0  # (P, 2, 2)
    det = local[:, 0, 0] * local[:, 1, 1] - local[:, 0, 1] * local[:, 1, 0]
    d = centres[b] - centres[a]
    with np.errstate(divide="ignore", invalid="ignore"):  # 2x2 solves in closed form
        off = np.stack([local[:, 1, 1] * d[:, 0] - local[:, 0, 1] * d[:, 1],
                        local[:, 0, 0] * d[:, 1] - local[:, 1, 0] * d[:, 0]], axis=1) / det[:, None]
    keep = (np.abs(det) > 1e-9) & (np.abs(off) <= NEIGHBOUR_SQUARES).all(axis=1)
    return np.stack([a[keep], b[keep]], axis=1).astype(np.int64), off[keep]


def disagreements(board: CharucoBoard, ids: np.ndarray, pairs: np.ndarray, offsets: np.ndarray) -> int:
    """How many of the pairs (:func:`pair_offsets`) the board's layout puts elsewhere; ids (M,) int64."""
    squares = board.marker_square_of()
    if not len(pairs):
        return 0
    where = np.array([squares.get(int(k), (np.nan, np.nan)) for k in ids], np.float64)
    expected = where[pairs[:, 1]] - where[pairs[:, 0]]
    return int((~(np.abs(expected - offsets) <= OFFSET_TOLERANCE).all(axis=1)).sum())


def fitting_sizes(board: CharucoBoard, ids: np.ndarray, pairs: np.ndarray, offsets: np.ndarray) -> list[tuple[int, int]]:
    """The board sizes (X, Y) squares, with the board's dictionary, first id and pattern rule, whose
    layouts hold every marker read and that :func:`_refused` would not refuse; fewest disagreeing
    pairs first, then the smallest board (rows past the highest id read are not seen)."""
    need = int(np.max(ids)) - board.first_id + 1 if len(ids) else 0
    fits = []
    for X in range(3, _MAX_SQUARES + 1):
        for Y in range(3, _MAX_SQUARES + 1):
            other = _resized(board, X, Y)
            if other is None or other.n_markers < need:
                continue
            bad = disagreements(other, ids, pairs, offsets)
            if not _refused(bad, len(pairs)):
                fits.append((bad, X * Y, (X, Y)))
    return [size for _, _, size in sorted(fits)]


def _refused(bad: int, compared: int) -> bool:
    """Whether ``bad`` disagreeing pairs of ``compared`` refuse a layout."""
    return bad >= MIN_DISAGREEING and bad >= DISAGREEING_SHARE * compared


def layout_mismatch(board: CharucoBoard, ids: np.ndarray, corners: np.ndarray) -> str | None:
    """Why the markers read (ids (M,) int64, corners (M, 4, 2) px) contradict the board's layout,
    naming the sizes they fit; None when they agree (or too few are near each other to tell)."""
    ids = np.asarray(ids, np.int64).ravel()
    pairs, offsets = pair_offsets(board, corners)
    bad = disagreements(board, ids, pairs, offsets)
    if not _refused(bad, len(pairs)):
        return None
    fits = fitting_sizes(board, ids, pairs, offsets)
    X, Y = board.squares
    said = f"the markers contradict {X}x{Y} squares ({bad} of {len(pairs)} neighbouring pairs lie elsewhere)"
    if not fits:
        return said + "; they fit no board size of this dictionary and first id: check dict= and first="
    X, Y = fits[0]
    more = [f"{x}x{y}" for x, y in fits[1:4]]
    return said + f"; they fit {X}x{Y} squares" + (f" (or {', '.join(more)})" if more else "") + \
        f": check the board's size, e.g. {_resized(board, X, Y).describe()}"


@functools.lru_cache(maxsize=4096)
def _resized(board: CharucoBoard, X: int, Y: int) -> CharucoBoard | None:
    try:
        return dataclasses.replace(board, squares=(X, Y))
    except ValueError:  # more markers than the dictionary holds
        return None
