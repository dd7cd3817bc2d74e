import importlib.util
from pathlib import Path

import numpy as np
import pytest

_spec = importlib.util.spec_from_file_location(
    "board_flex_bench", Path(__file__).parents[2] / "benchmarks" / "board_flex.py")
bf = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bf)


def test_the_bias_is_the_mean_over_sequences_with_its_standard_error_against_one_fits_sigma():
    b = bf.fx_bias([0.1, 0.3, 0.2, 0.4], [0.2, 0.25, 0.3, 0.2])
    assert b["mean"] == pytest.approx(0.25) and b["se"] == pytest.approx(np.std([0.1, 0.3, 0.2, 0.4], ddof=1) / 2)
    assert b["sigma"] == pytest.approx(0.225) and b["ratio"] == pytest.approx(0.25 / 0.225)


def test_one_sequence_is_a_draw_not_a_bias():
    # one rendered sequence's fx error (+0.46 px at sigma 0.25) read as a bias once; it is one draw
    with pytest.raises(ValueError, match="at least 3 sequences"):
        bf.fx_bias([0.457], [0.253])
    with pytest.raises(SystemExit) as exc:
        bf.main(["--rendered", "1"])
    assert exc.value.code == 2


def test_the_sag_target_is_ten_percent_or_two_thousandths_of_a_square():
    assert bf.within_target(0.0043, 0.005) and bf.within_target(0.0185, 0.02) and bf.within_target(0.0015, 0.0)
    assert not bf.within_target(0.0175, 0.02) and not bf.within_target(0.0025, 0.0)
