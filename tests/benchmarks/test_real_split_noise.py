import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

_bench = Path(__file__).parents[2] / "benchmarks"
sys.path.insert(0, str(_bench))
_spec = importlib.util.spec_from_file_location("real_split_noise_bench", _bench / "real_split_noise.py")
sn = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(sn)


def test_the_medians_gap_has_an_interval_over_the_splits():
    rng = np.random.default_rng(3)
    a = rng.lognormal(np.log(0.2), 0.6, 200)
    same = rng.lognormal(np.log(0.2), 0.6, 200)
    gap, lo, hi = sn.median_gap(a, same)
    assert gap == pytest.approx(np.median(a) - np.median(same)) and lo < gap < hi
    assert lo < 0.0 < hi  # the same spread of splits: not ranked
    gap, lo, hi = sn.median_gap(a, 1.5 * a)
    assert hi < 0.0  # lower on every split: ranked
    b = 1.5 * a
    b[:150] = np.nan  # a column on the first 50 splits only is compared on those
    assert sn.median_gap(a, b)[0] == pytest.approx(np.median(a[150:]) - np.median(b[150:]))


def _row(seed, flat, anchors, flex=None):
    row = {"seed": seed, "flat": {"median": flat}, "flat_classic": {"median": flat + 0.05},
           "predicted": {"median_covered": 0.2, "p10_covered": 0.05, "p90_covered": 0.4}}
    if flex is not None:
        row.update(sag={"median": flex}, flex={"median": flex})
    row.update({k: {"median": v} for k, v in zip(("cv_plumb_bob", "cv_rational", "cv_fisheye"), anchors)})
    return row


def test_the_flex_columns_count_over_the_splits_that_ran_them():
    rows = [_row(0, 0.1, (0.2, 0.3, 0.4), flex=0.15), _row(1, 0.3, (0.2, 0.25, 0.4), flex=0.5),
            *(_row(s, 0.2, (0.25, 0.3, 0.1)) for s in range(2, 6))]
    lines = sn.summary({"set": "x", "photos": 6, "model": "plumb_bob", "splits": rows})
    text = "\n".join(lines)
    assert "flex ≤ the best anchor on 1 of 2 splits" in text
    assert "flat ≤ the best anchor on 1 of 6 splits" in text
    assert any("OpenCV 5-coef" in ln and "≤ it on 5 of 6" in ln for ln in lines)
    assert any("aicalib_tf sag" in ln and "2 splits" in ln for ln in lines)


def test_the_shape_column_is_compared_with_flat_and_the_best_anchor_on_its_splits():
    rows = [_row(s, 0.3, (0.25, 0.4, 0.5)) for s in range(8)]
    for s, r in enumerate(rows[:4]):
        r["shape"] = {"median": 0.1 + 0.01 * s}
    text = "\n".join(sn.summary({"set": "x", "photos": 8, "model": "plumb_bob", "splits": rows}))
    assert "shape ≤ the best anchor on 4 of 4 splits" in text
    line = next(ln for ln in text.splitlines() if ln.strip().startswith("shape: medians' gap"))
    assert "to flat -0.185 px" in line and "to the best anchor -0.135 px" in line


def test_per_split_counts_the_splits_at_or_below_each_anchor_and_the_best_with_an_interval():
    rows = [_row(s, 0.2, (0.25, 0.3, 0.1 if s < 2 else 0.4)) for s in range(8)]
    for r in rows:
        r["auto"] = dict(r["flat"])
    rows[0]["auto"] = {"median": 0.35}
    lines, share = sn.per_split({"set": "x", "photos": 8, "model": "plumb_bob", "splits": rows})
    text = "\n".join(lines)
    assert "x: auto per split" in text
    assert "≤ OpenCV 5-coef    on 7 of 8" in text and "≤ OpenCV fisheye   on 6 of 8" in text
    assert share == pytest.approx(6 / 8) and "≤ the best anchor   on 6 of 8 (75%" in text
    lo, hi = sn.wilson(6, 8)
    assert 0.4 < lo < 0.75 < hi < 0.95 and np.isnan(sn.wilson(0, 0)).all()  # NaN without splits
    assert sn.wilson(8, 8)[1] == 1.0 and sn.wilson(0, 8)[0] == 0.0
