"""The printed marker boards' shared part (data_gen.marker_print): paper checks, cells, drawn paper."""

import numpy as np
import pytest

from aicalib_tf.geometry.aprilgrid import parse_board as parse_aprilgrid
from aicalib_tf.geometry.charuco import parse_board as parse_charuco
from data_gen.aprilgrid import AprilGridTarget, sample_aprilgrid
from data_gen.charuco import CharucoTarget, sample_charuco

BOARDS = [(AprilGridTarget, sample_aprilgrid, parse_aprilgrid("aprilgrid:3x2,tag=60mm,spacing=0.3")),
          (CharucoTarget, sample_charuco, parse_charuco("charuco:5x4,square=40mm,marker=30mm,dict=DICT_4X4_50"))]


@pytest.mark.parametrize("kind, sample, board", BOARDS)
def test_paper_is_checked_and_drawn_alike(kind, sample, board):
    with pytest.raises(ValueError, match="margin"):
        kind(board, margin=-0.1)
    with pytest.raises(ValueError, match="black"):
        kind(board, black=0.9, white=0.8)
    a, b = sample(np.random.default_rng(3), board), sample(np.random.default_rng(3), board)
    assert a == b and isinstance(a, kind) and 0.04 <= a.black <= 0.22 and 0.7 <= a.white <= 0.95


@pytest.mark.parametrize("kind, sample, board", BOARDS)
def test_cells_change_only_at_the_cuts(kind, sample, board):
    t = kind(board)
    p, cuts = t.period, t._cuts
    x = np.linspace(-p, 3 * p, 4001)
    cells = t.axis_cells(x)
    assert np.all(np.diff(cells) >= 0)  # numbered along the axis
    changes = x[1:][np.diff(cells) > 0]
    at_cut = np.min(np.abs((changes - np.floor(changes / p) * p)[:, None] - np.r_[0.0, cuts, p][None]), axis=1)
    assert np.all(at_cut <= x[1] - x[0] + 1e-9)  # a new cell only where a cut (or a period) was crossed
    assert t.axis_cells(np.array([np.nan]))[0] < -1e8  # not on the plane
    X, Y = np.array([np.nan, -1e6, p / 2]), np.array([0.0, 0.0, p / 2])
    assert list(t.classify(X, Y)[:2]) == [2, 2] and t.classify(X, Y)[2] in (0, 1)  # off the paper; printed
