"""``python -m aicalib_tf.evaluate --board charuco:...``: the ChArUco suite against OpenCV's CharucoDetector."""

import csv

from aicalib_tf.evaluate import main

BOARD = "charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100"


def test_the_charuco_suite_compares_with_opencv_and_writes_its_report(tmp_path, capsys):
    out = tmp_path / "r"
    assert main(["--board", BOARD, "--limit", "1", "--out", str(out)]) == 0
    rows = list(csv.DictReader((out / "results.csv").open()))
    conditions = {r["condition"] for r in rows}
    assert {"clean", "partial", "occluded"} <= conditions
    assert {r["detector"] for r in rows} == {"cnn", "opencv", "opencv-refined"}
    by = {(r["condition"], r["detector"]): r for r in rows}
    assert int(by["clean", "cnn"]["correct"]) >= int(by["clean", "opencv"]["correct"]) > 0
    assert all(int(r["wrong"]) == 0 for r in rows if r["detector"] == "cnn")
    assert "| clean | cnn |" in (out / "report.md").read_text()


def test_a_bad_board_or_a_chessboard_option_is_one_line(tmp_path, capsys):
    assert main(["--board", "charuco:11x8,square=30mm,marker=40mm,dict=DICT_5X5_100", "--out", str(tmp_path / "a")]) == 2
    assert main(["--board", BOARD, "--pattern", "9x6", "--out", str(tmp_path / "b")]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 2 and all(line.startswith("error: ") for line in err), err
    assert "marker" in err[0] and "ChArUco suite" in err[1]
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
