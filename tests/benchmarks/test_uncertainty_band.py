import importlib.util
from pathlib import Path

_spec = importlib.util.spec_from_file_location("uncertainty_band_bench", Path(__file__).parents[2] / "benchmarks" / "uncertainty_band.py")
ub = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ub)


def _row(measured, formal, honest, kappa=(1.0, 1.0)):
    band = lambda lo, hi: {"p10": lo, "p90": hi, "mean": 0.5 * (lo + hi)}  # noqa: E731
    return {"measured": measured, "kappa": list(kappa), "formal": band(*formal), "honest": band(*honest)}


def test_the_summary_counts_each_band_holding_missing_below_and_above():
    rows = [_row(0.5, (0.1, 0.3), (0.2, 0.8), (4.0, 5.0)), _row(0.2, (0.1, 0.3), (0.3, 0.9), (4.0, 6.0)),
            _row(0.25, (0.1, 0.3), (0.2, 0.8))]
    lines = ub.summary("set", rows)
    assert lines[0].startswith("set (3 splits; measured mean 0.317 px; κ median 4.00")
    assert lines[1].startswith("  formal  inside 67% (below 0%, above 33%)")
    assert lines[2].startswith("  honest  inside 67% (below 33%, above 0%)")
