"""A board's outer ring squeezed and darkened at a fisheye's rim: its last corners placed, or none."""

import numpy as np
import pytest

from aicalib_tf.bench.conditions import PATTERN, select_conditions
from aicalib_tf.detect.chessboard.grid import MIN_CORNERS, Grid
from aicalib_tf.detect.chessboard.rim import complete_rim
from aicalib_tf.detect.corners.junctions import typical_amplitude
from aicalib_tf.detect.corners.refine import Smoothed
from data_gen.sample import make_sample


def _scene(name: str, index: int):
    cond = select_conditions(name)[0]
    s = make_sample(cond.preset, cond.seed, index, size=cond.size, pattern=PATTERN)
    gray = s.image.astype(np.float32)
    smoothed = Smoothed(gray)
    smooth = smoothed.sigma(1.0)
    return s.corners, smoothed, smooth, typical_amplitude(smooth, s.corners, MIN_CORNERS)


def _grid(truth: np.ndarray, drop: list[int]) -> Grid:
    """The true 9×6 lattice as a grid of (i = row, j = col) without the corners ``drop``."""
    keep = np.setdiff1d(np.arange(len(truth)), drop)
    return Grid(index=keep, ij=np.stack([keep // 9, keep % 9], 1), points=truth[keep])


@pytest.mark.parametrize("name, index, drop", [
    ("closeup-eq", 20, [8]),       # a board corner at the rim, squeezed 12 × 19 px: the fit needs a narrower window
    ("closeup-eq", 6, [53, 44]),   # two rim corners darkened to 12 grey levels (ring 0.13 of a typical corner's)
])
def test_squeezed_dark_outer_ring_corners_are_placed_on_the_truth(name, index, drop):
    truth, smoothed, smooth, ref = _scene(name, index)
    full = complete_rim(_grid(truth, drop), (6, 9), smoothed, smooth, ref)
    assert full is not None and len(full) == 54
    placed = full.index < 0
    assert placed.sum() == len(drop)
    ij = full.ij[placed]
    err = np.hypot(*(full.points[placed] - truth[ij[:, 0] * 9 + ij[:, 1]]).T)
    assert err.max() < 0.5


def test_no_corner_is_placed_where_the_image_has_none():
    truth, smoothed, smooth, ref = _scene("closeup-eq", 20)
    flat = Smoothed(np.full(smoothed.sigma(1.0).shape, 128.0, np.float32))
    assert complete_rim(_grid(truth, [8]), (6, 9), flat, flat.sigma(1.0), ref) is None
    # a hole inside the outer ring, too many holes, or the wrong extent: left to the other stages
    assert complete_rim(_grid(truth, [20]), (6, 9), smoothed, smooth, ref) is None
    assert complete_rim(_grid(truth, [0, 1, 2, 3]), (6, 9), smoothed, smooth, ref) is None
    assert complete_rim(_grid(truth, [8]), (9, 6), smoothed, smooth, ref) is None
