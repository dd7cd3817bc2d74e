import importlib.util
from pathlib import Path

import numpy as np

_spec = importlib.util.spec_from_file_location("faint_corners_bench", Path(__file__).parents[2] / "benchmarks" / "faint_corners.py")
fc = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(fc)


def test_each_floor_counts_the_full_boards_it_would_refuse(capsys):
    ones = np.ones(54)
    boards = [("a", 0, 0.1 * ones, 20.0 * ones, 0.02 * ones, 1e-4, 80.0 * ones),  # a clear hit
              ("a", 1, np.r_[2.07, 0.1 * ones[1:]], np.r_[1.9, 20.0 * ones[1:]], 0.02 * ones, 1e-4,
               np.r_[-7.5, 80.0 * ones[1:]]),  # wrong: a faint corner of the other colour order
              ("b", 2, 0.1 * ones, np.r_[np.nan, 0.9, 20.0 * ones[2:]], 0.02 * ones, 1e-4,
               np.r_[np.nan, 3.5, 80.0 * ones[2:]])]  # a hit with a faint corner
    fc.report("tune", boards, [0.5, 1.0, 2.0], show=True)
    out = capsys.readouterr().out
    assert "3 full boards (1 wrong), 162 corners (1 unmeasured)" in out
    assert "| 0.5 | 0 | 0 |" in out and "| 1 | 1 | 0 |" in out and "| 2 | 1 | 1 |" in out
    assert "wrong a #1: corner 0 2.07 px off, cnr 1.90" in out
    assert "least z of a corner: hits 3.50; wrong boards -7.50" in out


def test_bad_arguments_exit_2_with_one_line(capsys):
    assert fc.main(["--families", "no-such"]) == 2
    assert fc.main(["--floors", "x"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and err[0].startswith("faint_corners: unknown families") and "--floors" in err[1]
