"""ArUco markers of a ChArUco board, read two ways: OpenCV's marker detector, and the marker's bits
sampled through the board's lattice where that detector reads nothing.

Lattice coordinates: a found grid of chessboard corners with integer ids (a, b) per corner (any
of the board's eight readings: the ids need not be the board's). Cell (a, b) is the square between
corners (a, b) and (a + 1, b + 1). A marker placed on the lattice is a :class:`Placed`: its cell,
its id and ``A``, the 2×2 signed permutation that turns lattice steps into board steps
(board (c, r) = A·(a, b) + t); t follows from the marker's square.

The decoder maps the cell's four corners to a unit square by a homography, samples each of the
marker's (n + 2)² bits (border included) at 4×4 points in the middle of the bit, sets the
threshold halfway between the border (black) and the white margin around the marker, and matches
the n × n inner bits against the board's markers in the eight readings. A match needs every
border bit black, a Hamming distance of at most :data:`MAX_BIT_ERRORS` and every other marker or
reading at least :data:`MIN_BIT_MARGIN` bits further.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from aicalib_tf.detect.corners.sampling import sample_bilinear
from aicalib_tf.geometry.charuco import CharucoBoard, dictionary

__all__ = ["Placed", "READINGS", "aruco_markers", "noise_sigma", "lattice_coords", "place_marker", "decode_cells", "verify_cells", "MAX_BIT_ERRORS", "MIN_BIT_MARGIN"]

MAX_BIT_ERRORS = 1
MIN_BIT_MARGIN = 4
MIN_CONTRAST = 0.06  # white margin minus border, on the [0, 1] scale
MAX_OFF_CENTRE = 0.25
READ_SIGMA = 1.0
MAX_VERIFY_ERRORS = 3  # bit errors (border included) allowed when a named lattice predicts the marker  # a marker's centre within this of its cell's centre (in cells)


def _readings() -> tuple[np.ndarray, ...]:
    """The eight 2×2 signed permutations (rotations and reflections of the lattice axes)."""
    out = []
    for perm in ((0, 1), (1, 0)):
        for sx in (1, -1):
            for sy in (1, -1):
                A = np.zeros((2, 2), np.int64)
                A[0, perm[0]], A[1, perm[1]] = sx, sy
                out.append(A)
    return tuple(out)


READINGS = _readings()


@dataclass(frozen=True)
class Placed:
    """A marker on the lattice. id : marker id. cell : (a, b) lattice cell. A : (2, 2) int lattice ->
    board steps. corners : (4, 2) px, OpenCV's corner order. source : "aruco" or "lattice".
    errors : bit errors of a lattice read (0 for OpenCV's)."""

    id: int
    cell: tuple[int, int]
    A: np.ndarray
    corners: np.ndarray
    source: str
    errors: int = 0


def _read(det, img: np.ndarray, board: CharucoBoard) -> tuple[np.ndarray, np.ndarray]:
    corners, ids, rejected = det.detectMarkers(img)
    if ids is not None and len(ids) >= 2:  # the board's layout finds markers among the rejected outlines
        corners, ids, _, _ = det.refineDetectedMarkers(img, board.to_opencv(), corners, ids, rejected)
    if ids is None or len(ids) == 0:
        return np.zeros(0, np.int64), np.zeros((0, 4, 2))
    ids = ids.ravel().astype(np.int64)
    corners = np.asarray(corners, np.float64).reshape(-1, 4, 2)
    keep = (ids >= board.first_id) & (ids < board.first_id + board.n_markers)
    return ids[keep], corners[keep]


def noise_sigma(gray_u8: np.ndarray) -> float:
    """The image noise's standard deviation in grey levels, from the absolute response to a
    Laplacian-difference mask that cancels edges of first and second order (Immerkær, "Fast noise
    variance estimation", 1996). gray_u8 : (H, W) uint8, at least 3 × 3."""
    k = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)
    r = cv2.filter2D(gray_u8.astype(np.float32), -1, k)[1:-1, 1:-1]
    return float(np.sqrt(np.pi / 2.0) * np.abs(r).mean() / 6.0)


def aruco_markers(gray_u8: np.ndarray, board: CharucoBoard) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's marker detector (sub-pixel corners; more thresholds, smaller markers and rounder
    outlines than its defaults; outlines it rejected looked at again where the read markers and the
    board's layout put a marker) on the board's dictionary. On a noisy image (:func:`noise_sigma`
    above the adaptive threshold's constant, where noise breaks the markers' outlines apart) also on
    the image smoothed (Gaussian σ :data:`READ_SIGMA` px): a marker read in both keeps the first
    reading.

    Returns ids (M,) int64 inside the board's id range and corners (M, 4, 2) float64 px.
    """
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    params.adaptiveThreshWinSizeMax = 53  # more thresholds, smaller and rounder markers than the defaults
    params.minMarkerPerimeterRate = 0.01
    params.polygonalApproxAccuracyRate = 0.05
    det = cv2.aruco.ArucoDetector(dictionary(board.dictionary), params)
    ids, corners = _read(det, gray_u8, board)
    if len(ids) == board.n_markers or noise_sigma(gray_u8) <= params.adaptiveThreshConstant:
        return ids, corners
    ids2, corners2 = _read(det, cv2.GaussianBlur(gray_u8, (0, 0), READ_SIGMA), board)
    centres = corners.mean(axis=1)
    new = [k for k in range(len(ids2))
           if not len(ids) or np.linalg.norm(centres - corners2[k].mean(axis=0), axis=1).min() > 2.0]
    return np.concatenate([ids, ids2[new]]), np.concatenate([corners, corners2[new]])


def lattice_coords(ids: np.ndarray, pts: np.ndarray, xy: np.ndarray, k: int = 12) -> np.ndarray | None:
    """Image points xy (M, 2) -> lattice coordinates (M, 2), by a homography of the k corners nearest
    their mean; None when fewer than 4 corners or a degenerate fit."""
    if len(ids) < 4:
        return None
    near = np.argsort(np.linalg.norm(pts - xy.mean(axis=0), axis=1))[:k]
    H, _ = cv2.findHomography(pts[near].astype(np.float64), ids[near].astype(np.float64), 0)
    if H is None:
        return None
    return cv2.perspectiveTransform(xy.reshape(-1, 1, 2).astype(np.float64), H).reshape(-1, 2)


def place_marker(ids: np.ndarray, pts: np.ndarray, marker_id: int, corners: np.ndarray,
                 board: CharucoBoard) -> Placed | None:
    """A marker OpenCV read (corners (4, 2) px) placed on the lattice (ids (N, 2), pts (N, 2) px).

    None when it does not sit in the middle of one cell with its sides along the lattice.
    """
    lat = lattice_coords(ids, pts, corners)
    if lat is None:
        return None
    centre = lat.mean(axis=0)
    cell = np.floor(centre)
    if np.abs(centre - cell - 0.5).max() > MAX_OFF_CENTRE:
        return None
    side = board.marker / board.square
    dx, dy = (lat[1] - lat[0]) / side, (lat[3] - lat[0]) / side  # lattice steps of board +x, +y
    Ainv = np.rint(np.column_stack([dx, dy]))
    if np.abs(np.column_stack([dx, dy]) - Ainv).max() > 0.3 or not any((Ainv == A.T).all() for A in READINGS):
        return None
    return Placed(int(marker_id), (int(cell[0]), int(cell[1])), Ainv.T.astype(np.int64), np.asarray(corners, np.float64), "aruco")


def _cell_quads(ids: np.ndarray, pts: np.ndarray) -> dict[tuple[int, int], np.ndarray]:
    """{(a, b): (4, 2) px corners (a, b), (a+1, b), (a+1, b+1), (a, b+1)} for every cell whose four corners are found."""
    at = {(int(i), int(j)): p for (i, j), p in zip(ids, pts)}
    out = {}
    for (a, b) in at:
        quad = [at.get(k) for k in ((a, b), (a + 1, b), (a + 1, b + 1), (a, b + 1))]
        if all(q is not None for q in quad):
            out[(a, b)] = np.array(quad, np.float64)
    return out


def _bit_positions(board: CharucoBoard, sub: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Unit-cell sample points: (n+2, n+2, sub², 2) inside the bits and (R, 2) on the white margin."""
    n = board.bits + 2
    lo, w = (1.0 - board.marker / board.square) / 2.0, board.marker / board.square / n
    f = (np.arange(sub) + 0.5) / sub * 0.6 + 0.2  # the middle 60 % of a bit
    by, bx, fy, fx = np.meshgrid(np.arange(n), np.arange(n), f, f, indexing="ij")
    bits = np.stack([lo + (bx + fx) * w, lo + (by + fy) * w], axis=-1).reshape(n, n, sub * sub, 2)
    t = np.linspace(lo, 1.0 - lo, 4 * n)
    edge = lo / 2.0
    ring = np.concatenate([np.stack([t, np.full_like(t, e)], 1) for e in (edge, 1 - edge)]
                          + [np.stack([np.full_like(t, e), t], 1) for e in (edge, 1 - edge)])
    return bits, ring


def _sample(gray: np.ndarray, quad: np.ndarray, unit: np.ndarray) -> np.ndarray:
    """Bilinear samples of gray at unit-cell points (..., 2) mapped through the cell's homography."""
    H = cv2.getPerspectiveTransform(np.float32([[0, 0], [1, 0], [1, 1], [0, 1]]), quad.astype(np.float32))
    xy = cv2.perspectiveTransform(unit.reshape(-1, 1, 2).astype(np.float64), H).reshape(-1, 2).astype(np.float32)
    return sample_bilinear(gray, xy).reshape(unit.shape[:-1])


def _board_codes(board: CharucoBoard) -> tuple[np.ndarray, np.ndarray]:
    """The board's markers as (M, n, n) inner bits and their ids (M,)."""
    ids = board.marker_ids()
    return np.stack([board.square_bits(int(k))[1:-1, 1:-1] for k in ids]), ids


def _match(bits: np.ndarray, board: CharucoBoard, max_errors: int = MAX_BIT_ERRORS,
           margin: int = MIN_BIT_MARGIN) -> tuple[int, np.ndarray, int] | None:
    """Inner bits (n, n) sampled in lattice axes (rows along b) -> (marker id, A, errors) or None."""
    codes, ids = _board_codes(board)
    n = bits.shape[0]
    k = np.arange(n) - (n - 1) / 2.0
    ky, kx = np.meshgrid(k, k, indexing="ij")
    scored = []
    for A in READINGS:  # board bit (kx, ky) sits at lattice offset Aᵀ(kx, ky)
        u = A[0, 0] * kx + A[1, 0] * ky
        v = A[0, 1] * kx + A[1, 1] * ky
        seen = bits[np.rint(v + (n - 1) / 2.0).astype(int), np.rint(u + (n - 1) / 2.0).astype(int)]
        d = np.count_nonzero(codes != seen[None], axis=(1, 2))
        scored += [(int(d[m]), int(ids[m]), A) for m in range(len(ids))]
    scored.sort(key=lambda s: s[0])
    best, second = scored[0], scored[1]
    if best[0] > max_errors or second[0] < best[0] + margin:
        return None
    return best[1], best[2], best[0]


def _cell_bits(gray: np.ndarray, quad: np.ndarray, board: CharucoBoard, bit_pts, ring_pts) -> np.ndarray | None:
    """(n + 2, n + 2) uint8 bits of a cell's marker (1 white), lattice axes; None without contrast."""
    vals = _sample(gray, quad, bit_pts).mean(axis=-1)  # (n, n)
    border = np.concatenate([vals[0], vals[-1], vals[1:-1, 0], vals[1:-1, -1]])
    white = float(np.median(_sample(gray, quad, ring_pts)))
    black = float(np.median(border))
    if white - black < MIN_CONTRAST:
        return None
    return (vals > (white + black) / 2.0).astype(np.uint8)


def _border_errors(bits: np.ndarray) -> int:
    return int(bits[0].sum() + bits[-1].sum() + bits[1:-1, 0].sum() + bits[1:-1, -1].sum())


def decode_cells(gray: np.ndarray, ids: np.ndarray, pts: np.ndarray, board: CharucoBoard,
                 skip: set | None = None) -> list[Placed]:
    """Read the markers in the lattice's cells (those with four corners found, not in ``skip``).

    gray : (H, W) float32 in [0, 1]. ids (N, 2) int lattice coordinates, pts (N, 2) px.
    """
    bit_pts, ring_pts = _bit_positions(board)
    out = []
    for cell, quad in _cell_quads(ids, pts).items():
        if skip and cell in skip:
            continue
        bits = _cell_bits(gray, quad, board, bit_pts, ring_pts)
        if bits is None or _border_errors(bits):
            continue
        hit = _match(bits[1:-1, 1:-1], board)
        if hit is not None:
            out.append(Placed(hit[0], cell, hit[1], _sample_corners(quad, board, hit[1]), "lattice", hit[2]))
    return out


def verify_cells(gray: np.ndarray, ids: np.ndarray, pts: np.ndarray, board: CharucoBoard, A: np.ndarray,
                 t: np.ndarray, skip: set | None = None) -> list[Placed]:
    """The markers a named lattice (board (c, r) = A·(a, b) + t) predicts in its cells, where the bits
    seen are that marker, in that reading, within :data:`MAX_VERIFY_ERRORS` of the marker's
    (n + 2)² bits, and every other marker or reading at least :data:`MIN_BIT_MARGIN` − 1 bits further.
    A check of one expected marker, so it holds where a blind reading (:func:`decode_cells`) cannot."""
    bit_pts, ring_pts = _bit_positions(board)
    square_of = {v: k for k, v in board.marker_square_of().items()}
    out = []
    for cell, quad in _cell_quads(ids, pts).items():
        c, r = A @ (np.asarray(cell, np.float64) + 0.5) + t  # the square's centre, (i − ½, j − ½)
        expected = square_of.get((int(round(c + 0.5)), int(round(r + 0.5))))
        if expected is None or (skip and cell in skip):
            continue
        bits = _cell_bits(gray, quad, board, bit_pts, ring_pts)
        if bits is None:
            continue
        hit = _match(bits[1:-1, 1:-1], board, MAX_VERIFY_ERRORS - min(_border_errors(bits), MAX_VERIFY_ERRORS),
                     MIN_BIT_MARGIN - 1)
        if hit is not None and hit[0] == expected and (hit[1] == A).all():
            out.append(Placed(expected, cell, A, _sample_corners(quad, board, A), "verified", hit[2]))
    return out


def _sample_corners(quad: np.ndarray, board: CharucoBoard, A: np.ndarray) -> np.ndarray:
    """(4, 2) px: a lattice-read marker's corners in OpenCV's order, through the cell's homography."""
    h = board.marker / board.square / 2.0
    board_offsets = np.array([[-h, -h], [h, -h], [h, h], [-h, h]])
    unit = 0.5 + board_offsets @ A  # lattice offset = Aᵀ·board offset, as rows
    H = cv2.getPerspectiveTransform(np.float32([[0, 0], [1, 0], [1, 1], [0, 1]]), quad.astype(np.float32))
    return cv2.perspectiveTransform(unit.reshape(-1, 1, 2), H).reshape(4, 2)
