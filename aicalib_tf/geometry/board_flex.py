"""A printed board's flex: a two-parameter parabolic sag along its two axes.

Board frame as in :mod:`aicalib_tf.geometry.pattern`: inner corner (c, r) of a (cols, rows) pattern
lies at (c·s, r·s, 0) before flexing, s the square size. The flexed board moves each point along
the board's z axis by

    z(x, y) = w_x·(1 − u²) + w_y·(1 − v²),    u = 2·x / (cols − 1) − 1,   v = 2·y / (rows − 1) − 1,

with (x, y) the point's position in squares (x = X / s; for a corner, its id (c, r)), so u and v
run over [−1, 1] across the inner-corner grid. ``flex`` = (w_x, w_y) is the sag at the grid's centre
line along each axis, relative to its edges, in squares (multiply by s for board units); the centre
moves by w_x + w_y. Points beyond the grid (the paper's margin) follow the same parabola. Positive
values move the centre towards the board's +z: away from a camera that sees the board's printed side
(the board frame's z axis points into the scene for a board whose x and y axes run right and down in
the image). This is mrcal's ``calobject_warp`` (4·x_r·(1 − x_r) with x_r ∈ [0, 1] equals 1 − u²).
"""

from __future__ import annotations

import numpy as np

__all__ = ["flex_basis"]


def flex_basis(x, y, pattern_size) -> np.ndarray:
    """(..., 2) float64 [1 − u², 1 − v²] at positions x, y (..., squares) on a (cols, rows) pattern:
    the derivative of the flexed board's z with respect to (w_x, w_y). The board shape of
    :mod:`aicalib_tf.geometry.board_shape` takes these as its first two terms and moves the points
    (:func:`~aicalib_tf.geometry.board_shape.shaped_points` with (w_x, w_y) is the flexed board).

    >>> flex_basis(np.array([0.0, 4.0]), np.array([0.0, 2.5]), (9, 6)).tolist()
    [[0.0, 0.0], [1.0, 1.0]]
    """
    cols, rows = (int(n) for n in pattern_size)
    if cols < 2 or rows < 2:
        raise ValueError(f"pattern_size must be (cols, rows) >= (2, 2), got {pattern_size!r}")
    u = 2.0 * np.asarray(x, np.float64) / (cols - 1) - 1.0
    v = 2.0 * np.asarray(y, np.float64) / (rows - 1) - 1.0
    return np.stack([1.0 - u * u, 1.0 - v * v], axis=-1)
