import numpy as np
import pytest

from aicalib_tf.detect.chessboard.grid_growth import GrowingGrid
from aicalib_tf.detect.chessboard.grid_seeds import double_step, place_bent_seed, place_seed

# A close-up board's corner (6, 3) 200° off a EUCM fisheye's axis and its 12 nearest candidates (px), with their
# edge contrasts: towards the rim (+x) the steps shrink 53, 36, then 22 px and the light falls, so that the
# step to (7, 3) is too dim to seed with, and the parallelogram of the step to (5, 3) lands nearer (8, 3).
_RIM = np.array([[455.1, 212.6],  # (6, 3)
                 [489.7, 205.7], [403.5, 222.3], [511.3, 202.0], [435.8, 156.5], [471.4, 154.7], [460.3, 274.3],
                 [495.4, 262.1], [495.2, 156.0], [516.3, 251.8], [387.1, 165.2], [409.9, 285.1], [472.7, 120.0]])
_RIM_CONTRAST = np.array([0.093, 0.242, 0.041, 0.201, 0.043, 0.087, 0.011, 0.04, 0.069, 0.168, 0.076, 0.039])


def test_double_step_finds_a_corner_between_two_cells_of_a_block():
    ii, jj = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    pts = np.stack([ii.ravel() * 20.0, jj.ravel() * 15.0], 1)  # a 3x3 lattice, index 3 * i + j
    block = {(int(i), int(j)): 3 * int(i) + int(j) for i, j in zip(ii.ravel(), jj.ravel())}
    assert not double_step(pts, block)
    between = np.concatenate([pts, [[50.0, 15.5]]])  # half-way from (2, 1) to a cell one step further on
    far = np.concatenate([between, [[60.0, 15.0]]])
    assert not double_step(between, block)
    assert double_step(far, {**block, (2, 1): 10})  # (2, 1) taken 2 steps on: the point between is stepped over
    assert not double_step(far + [0.0, 0.0], {(0, 0): 0, (0, 1): 1})  # steps of a block alone are tested


@pytest.mark.parametrize("seed", [place_seed, place_bent_seed])
def test_a_seed_does_not_step_over_a_corner_at_a_fisheyes_rim(seed):
    lat = GrowingGrid(_RIM, np.ones(len(_RIM), bool))
    assert not seed(lat, 0, np.arange(1, 13), _RIM_CONTRAST)
    assert not lat.cells and lat.free.all()
    # without the corners between (column 7), the same block is the lattice's: it seeds
    column = [1, 5, 7]  # (7, 3), (7, 2), (7, 4)
    rest = np.delete(_RIM, column, axis=0)
    lat = GrowingGrid(rest, np.ones(len(rest), bool))
    assert seed(lat, 0, np.arange(1, 10), np.delete(_RIM_CONTRAST, np.array(column) - 1))
    assert len(lat.cells) == 9 and lat.cells[(-1, 0)] == 2  # (8, 3), now the next corner along the line
