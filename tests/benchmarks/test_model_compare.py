import importlib.util
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("keras")

_spec = importlib.util.spec_from_file_location(
    "model_compare", Path(__file__).parents[2] / "benchmarks" / "model_compare.py")
mc = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(mc)


def test_recall_by_spacing_counts_each_true_corner_once_in_its_bin():
    truth = np.array([[0.0, 0.0], [3.0, 0.0], [20.0, 0.0], [40.0, 0.0]])
    spacing = np.array([3.0, 3.0, 17.0, 20.0])
    # one prediction serves both close corners: one-to-one matching gives it to the nearer one
    pred = np.array([[2.6, 0.0], [20.5, 0.0], [45.0, 0.0]])
    cells = mc.recall_by_spacing([(pred, truth), (np.zeros((0, 2)), truth[:1])], [spacing, spacing[:1]])
    assert cells == [(1, 3), (0, 0), (0, 0), (0, 0), (1, 2)]


def test_spacings_are_those_of_the_visible_corners():
    from data_gen import make_sample

    s = make_sample("occluded", 21, 3, size=(320, 240))
    sp = mc._spacings(s)
    assert sp.shape == (int(s.visible.sum()),) and np.all(sp > 0)


def test_refine_scores_the_detectors_candidates(capsys):
    assert mc.main(["--images", "2", "--conditions", "clean", "--models", "default", "--refine"]) == 0
    out = capsys.readouterr().out
    assert "network + refinement ms/image" in out
    row = next(line for line in out.splitlines() if line.startswith("| clean | default"))
    precision, recall, _, loc = (float(v) for v in row.split("|")[4:8])
    assert recall > 0.95 and precision > 0.9 and loc < 0.05  # the saddle fit's accuracy, not the map's
