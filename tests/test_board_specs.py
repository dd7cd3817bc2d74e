"""Bad board descriptions and Kalibr target files through every command that reads a board:
calibrate, detect, board, live and handeye each give one line naming the field, and exit 2, before
reading an image."""

import pytest

from aicalib_tf.board import main as board_main
from aicalib_tf.calibrate import main as calibrate_main
from aicalib_tf.detect.__main__ import main as detect_main
from aicalib_tf.handeye import main as handeye_main
from aicalib_tf.live.__main__ import main as live_main

SPECS = [  # (description or a target file's text, the field the line must name)
    ("aprilgrid:6x6,tag=88mm,spacing=1", "spacing"),
    ("aprilgrid:6x6,tag=88mm,spacing=1.5", "spacing"),
    ("aprilgrid:6x6,tag=88mm,spacing=0.3,family=tag99h1", "family"),
    ("aprilgrid:6x6,spacing=0.3", "tag="),
    ("aprilgrid:6x6,tag=88mm", "spacing="),
    ("aprilgrid:6x6,tag=88furlong,spacing=0.3", "tag="),
    ("circles:4x11,spacing=20mm,asymmetric,diameter=30mm", "diameter"),  # touching
    ("circles:7x6,spacing=20mm,symmetric,diameter=20mm", "diameter"),  # touching
    ("circles:4x11,spacing=20mm", "layout"),
    ("circles:4x11,asymmetric", "spacing="),
    ("circles:4x11,spacing=2Ommm,asymmetric", "spacing="),
    ("charuco:11x8,square=30mm,marker=30mm,dict=DICT_5X5_100", "marker"),
    ("charuco:11x8,square=30mm,marker=35mm,dict=DICT_5X5_100", "marker"),
    ("charuco:11x8,square=30mm,dict=DICT_5X5_100", "marker="),
    ("charuco:11x8,square=30mm,marker=22mm,dict=DICT_9X9_1", "dict"),
    ("yaml:target_type: circlegrid\ntargetCols: 4\ntargetRows: 11\n", "target_type"),
    ("yaml:tagCols: 6\ntagRows: 6\n", "target_type"),
    ("yaml:target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 1.2\n", "tagSpacing"),
    ("yaml:target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSpacing: 0.3\n", "tagSize"),
    ("yaml:target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\nrowSpacingMeters: 0.02\ncolSpacingMeters: 0.03\n",
     "rowSpacingMeters"),
]
COMMANDS = {
    "calibrate": lambda board, tmp: calibrate_main([str(tmp / "x.png"), "--board", board, "--out", str(tmp / "cal")]),
    "detect": lambda board, tmp: detect_main([str(tmp / "x.png"), "--board", board, "--out", str(tmp / "det")]),
    "board": lambda board, tmp: board_main([board, "--out", str(tmp / "board.png")]),
    "live": lambda board, tmp: live_main(["--board", board, "--out", str(tmp / "cal"), "--port", "0"]),
    "handeye": lambda board, tmp: handeye_main([str(tmp / "x.png"), "--poses", str(tmp / "poses.csv"), "--board", board,
                                                "--setup", "eye-in-hand", "--out", str(tmp / "cal")]),
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
@pytest.mark.parametrize("spec, field", SPECS, ids=[f"{i}-{f}" for i, (_, f) in enumerate(SPECS)])
def test_a_bad_board_is_one_line_naming_the_field(tmp_path, capsys, command, spec, field):
    board = spec
    if spec.startswith("yaml:"):
        board = str(tmp_path / "target.yaml")
        (tmp_path / "target.yaml").write_text(spec[len("yaml:"):])
    assert COMMANDS[command](board, tmp_path) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert field in err[0].replace(repr(board), "").replace(board, ""), err  # named, not only echoed
    if spec.startswith("yaml:"):
        assert board in err[0]  # the file is named
    assert not (tmp_path / "cal").exists() and not (tmp_path / "det").exists() and not (tmp_path / "board.png").exists()


def test_a_kalibr_checkerboard_reads_as_a_chessboard(tmp_path):
    import json

    import cv2
    import numpy as np

    f = tmp_path / "checker.yaml"
    f.write_text("target_type: checkerboard\ntargetCols: 7\ntargetRows: 5\nrowSpacingMeters: 0.03\ncolSpacingMeters: 0.03\n")
    sq = 40  # px a square: 8x6 squares (7x5 inner corners, Kalibr's count), drawn flat with a square's margin
    img = np.full((8 * sq, 10 * sq), 230, np.uint8)
    for r in range(6):
        for c in range(8):
            if (r + c) % 2 == 0:
                img[sq + r * sq: sq + (r + 1) * sq, sq + c * sq: sq + (c + 1) * sq] = 30
    cv2.imwrite(str(tmp_path / "x.png"), cv2.GaussianBlur(img, (0, 0), 1.0))
    assert detect_main([str(tmp_path / "x.png"), "--board", str(f), "--out", str(tmp_path / "det")]) == 0
    d = json.loads((tmp_path / "det" / "x.json").read_text())
    assert d["pattern_size"] == [7, 5] and d["complete"], d["reason"]
    r, c = np.mgrid[0:5, 0:7]
    truth = np.stack([2 * sq - 0.5 + c.ravel() * sq, 2 * sq - 0.5 + r.ravel() * sq], axis=1)
    found = np.asarray(d["corners"], np.float64)
    assert np.linalg.norm(found[:, None] - truth[None], axis=2).min(axis=0).max() < 0.1


@pytest.mark.parametrize("command", ["detect", "board", "live", "handeye"])
def test_a_good_circle_grid_is_refused_where_it_is_not_read(tmp_path, capsys, command):
    assert COMMANDS[command]("circles:4x11,spacing=20mm,asymmetric", tmp_path) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "circle grids" in err[0]
