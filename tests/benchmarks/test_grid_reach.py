import importlib.util
from pathlib import Path

import numpy as np

from aicalib_tf.detect.chessboard.grid import Grid

_spec = importlib.util.spec_from_file_location("grid_reach_bench", Path(__file__).parents[2] / "benchmarks" / "grid_reach.py")
gr = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(gr)


def _corners():
    """A 9×6 lattice (cols·rows, 2) px whose column steps shrink from 40 px to 5 px (ratio 8)."""
    xs = np.concatenate([[0.0], np.cumsum([40, 34, 28, 22, 16, 11, 8, 5])])
    return np.array([(x, 30.0 * r) for r in range(6) for x in xs])


def test_step_ratio_counts_only_steps_between_visible_corners():
    corners = _corners()
    visible = np.ones(54, bool)
    assert gr.step_ratio(corners, visible) == 40 / 5
    visible[[8, 17, 26, 35, 44, 53]] = False  # the last column out of view: the shortest step is 8 px
    assert gr.step_ratio(corners, visible) == 40 / 8


def test_a_turned_shifted_grid_is_on_the_truth_and_a_cell_one_step_off_is_not():
    corners = _corners()
    ids = np.arange(54)
    ij = np.stack([ids // 9, 8 - ids % 9], 1)  # (row, flipped column): the lattice turned and flipped
    points = corners.copy()
    points[20] = corners[21]  # this cell holds its neighbour's corner
    g = Grid(index=ids, ij=ij, points=points)
    assert gr.grid_on_truth(g, corners) == (53, 1)
