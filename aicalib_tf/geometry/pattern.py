"""Board patterns: parsing, validation, board-frame points and the board's symmetries.

``pattern_size = (cols, rows)`` counts inner corners. Inner corner (c, r) sits at (c·s, r·s, 0) in the
board frame, s the square size; its index is r·cols + c (OpenCV's order). Pure numpy.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MIN_PATTERN", "MAX_PATTERN", "MAX_LATTICE_SIDE", "parse_pattern", "check_pattern", "check_lattice",
           "board_points", "board_symmetries", "pattern_ids"]

MIN_PATTERN = (3, 3)


MAX_PATTERN = (20, 15)


MAX_LATTICE_SIDE = 10_000  # ids along one side of a board's lattice (a camera file's limit)


def check_lattice(pattern_size) -> tuple[int, int]:
    """Validate ``(cols, rows)`` of a board's id lattice for calibration: each side in
    [3, ``MAX_LATTICE_SIDE``]. A chessboard's lattice is its pattern; a board whose corners sit on a
    sparse lattice (an AprilGrid, :mod:`aicalib_tf.geometry.aprilgrid`) may exceed ``MAX_PATTERN``."""
    try:
        cols, rows = (int(v) for v in pattern_size)
    except (TypeError, ValueError):
        raise ValueError(f"pattern_size must be (cols, rows), got {pattern_size!r}") from None
    if min(cols, rows) < min(MIN_PATTERN) or max(cols, rows) > MAX_LATTICE_SIDE:
        raise ValueError(f"pattern_size must have sides in [{min(MIN_PATTERN)}, {MAX_LATTICE_SIDE}], got {cols}x{rows}")
    return cols, rows


def parse_pattern(text: str) -> tuple[int, int]:
    """Parse ``"9x6"`` into ``(9, 6)`` = (cols, rows) of inner corners."""
    parts = str(text).lower().replace("×", "x").split("x")
    if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
        raise ValueError(f"pattern must look like COLSxROWS, e.g. 9x6, got {text!r}")
    return int(parts[0]), int(parts[1])


def check_pattern(pattern_size) -> tuple[int, int]:
    """Validate ``(cols, rows)`` inner corners against the supported range; returns it as ints."""
    try:
        cols, rows = (int(v) for v in pattern_size)
    except (TypeError, ValueError):
        raise ValueError(f"pattern_size must be (cols, rows), got {pattern_size!r}") from None
    lo_c, lo_r = MIN_PATTERN
    hi_c, hi_r = MAX_PATTERN
    # Accept either orientation of the largest pattern (20x15 or 15x20).
    if min(cols, rows) < min(lo_c, lo_r) or max(cols, rows) > max(hi_c, hi_r) or min(cols, rows) > min(hi_c, hi_r):
        raise ValueError(
            f"pattern_size must be between {lo_c}x{lo_r} and {hi_c}x{hi_r} inner corners, got {cols}x{rows}"
        )
    return cols, rows


def pattern_ids(pattern_size: tuple[int, int]) -> np.ndarray:
    """(cols·rows, 2) int64 (col, row) ids of every inner corner, in OpenCV's order (index = r·cols + c)."""
    cols, rows = (int(v) for v in pattern_size)
    c, r = np.meshgrid(np.arange(cols), np.arange(rows))
    return np.stack([c.ravel(), r.ravel()], axis=1)


def board_points(ids: np.ndarray, square_size: float) -> np.ndarray:
    """(N, 2) int (col, row) ids -> (N, 3) float64 board-frame points (c·s, r·s, 0), s = ``square_size``.

    >>> board_points([[2, 1]], 25.0).tolist()
    [[50.0, 25.0, 0.0]]
    """
    ids = np.asarray(ids, dtype=np.float64).reshape(-1, 2)
    return np.concatenate([ids * float(square_size), np.zeros((len(ids), 1))], axis=1)


def board_symmetries(pattern_size: tuple[int, int]) -> list[np.ndarray]:
    """Index permutations that map a board onto itself: identity and 180° (and 90°/270° if square).

    Returns a list of (cols·rows,) int arrays ``perm`` such that ``corners[perm]`` is the same
    physical board read in another admissible order.
    """
    cols, rows = (int(v) for v in pattern_size)
    idx = np.arange(cols * rows).reshape(rows, cols)
    perms = [idx.ravel(), idx[::-1, ::-1].ravel()]
    if cols == rows:
        perms += [np.rot90(idx, 1).ravel(), np.rot90(idx, 3).ravel()]
    return perms


