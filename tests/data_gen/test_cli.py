"""python -m data_gen: the dataset format, determinism, and clear errors for bad arguments."""

import csv
import json
import subprocess
import sys

import cv2
import pytest

from data_gen.__main__ import main


def _files(root):
    return {p.relative_to(root): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_writes_the_dataset_format(tmp_path):
    out = tmp_path / "ds"
    assert main(["--out", str(out), "--count", "3", "--preset", "noisy", "--seed", "4", "--size", "320x240", "--pattern", "5x4", "--no-progress"]) == 0
    rows = list(csv.DictReader((out / "index.csv").open()))
    assert [r["file"] for r in rows] == ["images/000000.png", "images/000001.png", "images/000002.png"]
    assert set(rows[0]) == {"file", "label", "condition", "camera_id", "seed", "index", "width", "height"}
    for r in rows:
        img = cv2.imread(str(out / r["file"]), cv2.IMREAD_UNCHANGED)
        assert img.shape == (240, 320) and img.dtype == "uint8"
        lab = json.loads((out / r["label"]).read_text())
        assert lab["pattern_size"] == [5, 4] and lab["image_size"] == [320, 240]
        assert lab["condition"] == "noisy" and len(lab["corners"]) == 20
        assert any(d["name"] == "gaussian_noise" for d in lab["degradations"])
    meta = json.loads((out / "meta.json").read_text())
    assert meta["preset"] == "noisy" and meta["seed"] == 4 and "preset_config" in meta


def test_same_seed_same_bytes_whatever_the_workers(tmp_path):
    args = ["--count", "6", "--preset", "train", "--seed", "11", "--no-progress"]
    assert main(["--out", str(tmp_path / "a"), *args, "--workers", "1"]) == 0
    assert main(["--out", str(tmp_path / "b"), *args, "--workers", "2"]) == 0
    assert main(["--out", str(tmp_path / "c"), "--count", "6", "--preset", "train", "--seed", "12", "--no-progress"]) == 0
    a, b, c = (_files(tmp_path / n) for n in "abc")
    assert a == b
    key = next(k for k in a if k.name == "000000.png")
    assert a[key] != c[key]


@pytest.mark.parametrize(
    "args, message",
    [
        (["--count", "2", "--preset", "clean", "--pattern", "1x5"], "pattern_size"),
        (["--count", "2", "--preset", "clean", "--size", "0x0"], "--size"),
        (["--count", "2", "--preset", "nope"], "unknown --preset"),
        (["--count", "-3", "--preset", "clean"], "--count"),
        (["--count", "2", "--preset", "clean", "--workers", "0"], "--workers"),
    ],
)
def test_bad_arguments_exit_2_and_write_nothing(tmp_path, capsys, args, message):
    out = tmp_path / "ds"
    assert main(["--out", str(out), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_out_under_a_file_is_unwritable(tmp_path, capsys):
    f = tmp_path / "file.txt"
    f.write_text("x")
    assert main(["--out", str(f / "ds"), "--count", "1", "--preset", "clean"]) == 2
    assert "cannot write" in capsys.readouterr().err
    assert [p.name for p in tmp_path.iterdir()] == ["file.txt"]


def test_out_that_is_a_file_or_non_empty_is_refused(tmp_path, capsys):
    f = tmp_path / "file.txt"
    f.write_text("x")
    assert main(["--out", str(f), "--count", "1", "--preset", "clean"]) == 2
    assert "not a folder" in capsys.readouterr().err
    assert main(["--out", str(tmp_path), "--count", "1", "--preset", "clean"]) == 2
    assert "not empty" in capsys.readouterr().err
    assert f.read_text() == "x"


def test_module_runs_as_a_command(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "data_gen", "--out", str(tmp_path / "x"), "--count", "1", "--preset", "bogus"],
        capture_output=True, text=True,
    )
    assert proc.returncode == 2 and "unknown --preset" in proc.stderr
