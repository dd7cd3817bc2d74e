"""The benchmark's rig sequences: both pipelines scored against the truth, and the report's section."""

import pandas as pd

from aicalib_tf.bench.detectors import make_detectors
from aicalib_tf.bench.report import _rig_section
from aicalib_tf.bench.rigs import evaluate_rig


def test_a_short_rig_sequence_is_scored_for_both_pipelines(tmp_path):
    detectors, _ = make_detectors(["cnn", "opencv"], (9, 6), relative=True)
    rows = evaluate_rig("pinhole", 0, 6, detectors)
    ours, cv = (next(r for r in rows if r["pipeline"] == p) for p in ("ours", "opencv"))
    assert ours["pair"] == "cam0-cam1" and ours["frames"] >= 5
    assert ours["baseline_err_pct"] < 0.1 and ours["rot_err_deg"] < 0.05 and ours["dy_held_px"] < 0.1
    assert cv["pipeline"] == "opencv" and ("baseline_err_pct" in cv or cv["note"].startswith("failed"))
    md = _rig_section(rows, tmp_path)
    assert (tmp_path / "rigs.csv").is_file() and "Camera rigs against the truth" in md[0]
    assert len(pd.read_csv(tmp_path / "rigs.csv")) == len(rows)
