import importlib.util
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

_bench = Path(__file__).parents[2] / "benchmarks"
sys.path.insert(0, str(_bench))
_spec = importlib.util.spec_from_file_location("board_shape_bench", _bench / "board_shape.py")
bs = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bs)


def _cal(flex, se):
    return SimpleNamespace(flex=None if flex is None else np.asarray(flex, float),
                           flex_covariance=None if flex is None else np.diag(np.square(se)))


def test_a_flat_or_flexed_result_counts_as_a_shape_with_zeros_beyond_its_terms():
    assert bs.shape_of(_cal(None, None)).tolist() == [0.0] * 7
    assert bs.shape_of(_cal([0.01, 0.02], [1e-3, 1e-3])).tolist() == [0.01, 0.02] + [0.0] * 5


def test_term_errors_are_the_mean_error_in_mean_standard_errors():
    truth = np.array([0.0, 0.0, 0.01, 0, 0, 0, 0])
    fits = [_cal(truth + [0, 0, 0.002, 0, 0, 0, 0], [1e-3] * 7), _cal(truth, [1e-3] * 7)]
    err = bs.term_errors(fits, truth)
    assert err[2] == pytest.approx(1.0) and np.count_nonzero(err) == 1
    assert bs.term_errors([_cal(None, None)], truth)[2] == np.inf  # a flat result misses a real term: no SE to hide it
