"""python -m aicalib_tf.compare: two calibration files of one camera -> figures, heat map, exit codes."""

from __future__ import annotations

import dataclasses
import json
import os

import pytest

from aicalib_tf import compare
from aicalib_tf.calib.files import save_calibration
from aicalib_tf.calib.fit import fit_views
from aicalib_tf.geometry import lens as L
from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views

SIZE = (640, 480)
LENS = L.Lens("plumb_bob", [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]], [-0.25, 0.08, 0.001, -0.0005, 0.0], SIZE)


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    views = synthetic_views(LENS, 12, 0.2, seed=3)
    root = tmp_path_factory.mktemp("cals")
    cals = [fit_views(v, PATTERN, SQUARE, SIZE, "plumb_bob") for v in (views[0::2], views[1::2])]
    cals.append(dataclasses.replace(cals[1], image_size=(800, 600)))
    out = []
    for name, cal in zip(("a", "b", "big"), cals):
        (root / name).mkdir()
        save_calibration(cal, root / name)
        out.append(root / name)
    return out


def test_compare_prints_figures_and_writes_the_heat_map(folders, tmp_path, capsys):
    a, b, _ = folders
    png, js = tmp_path / "diff.png", tmp_path / "diff.json"
    assert compare.main([str(a / "camera.json"), str(b), "--out", str(png), "--json", str(js)]) == 0
    out = capsys.readouterr().out
    assert "rotation fitted out" in out and "area both calibrations' boards covered" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    doc = json.loads(js.read_text())
    assert 0 < doc["covered_stats"]["median"] <= doc["covered_stats"]["p95"] < 2.0 and doc["coverage"] == "both"
    assert sorted(os.listdir(tmp_path)) == ["diff.json", "diff.png"]  # no temporary files left
    assert compare.main([str(a), str(b / "camera.yaml"), "--no-plot", "--no-rotation"]) == 0
    out = capsys.readouterr().out
    assert "no rotation fitted" in out and "whole image (a file holds no board poses" not in out


def test_different_image_sizes_exit_2_naming_both_files(folders, tmp_path, capsys):
    a, _, big = folders
    assert compare.main([str(a), str(big), "--out", str(tmp_path / "d.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(a) in err[0] and str(big) in err[0] and "640x480 and 800x600" in err[0]
    assert not (tmp_path / "d.png").exists()


def test_the_heat_map_is_replaced_atomically(folders, tmp_path, monkeypatch, capsys):
    a, b, _ = folders
    png = tmp_path / "diff.png"
    png.write_bytes(b"old")

    def fail(*_args):
        raise OSError(28, "No space left on device", str(png))

    monkeypatch.setattr("aicalib_tf.io.os.replace", fail)
    assert compare.main([str(a), str(b), "--out", str(png)]) == 2
    assert png.read_bytes() == b"old" and os.listdir(tmp_path) == ["diff.png"]
    assert "No space left" in capsys.readouterr().err
