import numpy as np
import pytest

from aicalib_tf.metrics import align_to_truth, board_symmetries, corner_error_stats


def _grid(cols, rows):
    c, r = np.meshgrid(np.arange(cols), np.arange(rows))
    return np.stack([c.ravel() * 10.0 + 5, r.ravel() * 10.0 + 7], axis=1)


def test_reversed_order_is_aligned_back():
    gt = _grid(9, 6)
    assert np.array_equal(align_to_truth(gt[::-1], gt, (9, 6)), gt)


def test_square_board_allows_quarter_turns():
    gt = _grid(5, 5)
    assert len(board_symmetries((5, 5))) == 4 and len(board_symmetries((9, 6))) == 2
    idx = np.arange(25).reshape(5, 5)
    turned = gt[np.rot90(idx, 1).ravel()]
    assert np.array_equal(align_to_truth(turned, gt, (5, 5)), gt)


def test_shift_gives_exactly_the_shift():
    gt = _grid(4, 3)
    e = np.linalg.norm(align_to_truth(gt + [0.3, 0.4], gt, (4, 3)) - gt, axis=1)
    st = corner_error_stats(e)
    assert st["median"] == pytest.approx(0.5) and st["rmse"] == pytest.approx(0.5) and st["count"] == 12


def test_wrong_sizes_are_rejected():
    with pytest.raises(ValueError, match="need 12 corners"):
        align_to_truth(np.zeros((11, 2)), np.zeros((12, 2)), (4, 3))
