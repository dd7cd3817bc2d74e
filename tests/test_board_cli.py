"""python -m aicalib_tf.board: a printable ChArUco board, bad input one line and exit 2."""

import cv2

from aicalib_tf.board import main

B = "charuco:7x5,square=25mm,marker=18mm,dict=DICT_4X4_50"


def test_writes_png_and_pdf(tmp_path, capsys):
    assert main([B, "--out", str(tmp_path / "b.png"), "--dpi", "100"]) == 0
    img = cv2.imread(str(tmp_path / "b.png"), cv2.IMREAD_GRAYSCALE)
    assert img.shape == (827, 1169)  # A4 landscape at 100 dpi
    assert main([B, "--out", str(tmp_path / "b.pdf"), "--paper", "letter"]) == 0
    assert (tmp_path / "b.pdf").read_bytes().startswith(b"%PDF")
    assert "print at 100 %" in capsys.readouterr().out


def test_bad_input_is_one_line(tmp_path, capsys):
    assert main(["charuco:7x5,square=25mm,marker=30mm,dict=DICT_4X4_50", "--out", str(tmp_path / "b.png")]) == 2
    assert main(["charuco:12x9,square=30mm,marker=22mm,dict=DICT_5X5_100", "--out", str(tmp_path / "b.pdf")]) == 2
    assert main([B, "--out", str(tmp_path / "b.svg")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(line.startswith("error: ") for line in err)
    assert "does not fit" in err[1]
    assert not list(tmp_path.iterdir())
