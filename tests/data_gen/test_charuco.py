"""data_gen renders ChArUco boards exactly, with markers in the labels; chessboard datasets are unchanged."""

import numpy as np
import pytest

from aicalib_tf.geometry.camera import Camera
from aicalib_tf.geometry.charuco import CharucoBoard, layout_image, parse_board
from data_gen.charuco import CharucoTarget
from data_gen.presets import get_preset
from data_gen.render import render_board
from data_gen.sample import make_sample
from tests.data_gen.brute_force import BACKGROUND, brute_force_render

B = "charuco:5x4,square=30mm,marker=22mm,dict=DICT_4X4_50"


def test_classify_is_the_printed_layout():
    board = CharucoBoard((5, 4), 36.0, 28.0, "DICT_5X5_100")
    t = CharucoTarget(board, margin=0.5, black=0.0, white=1.0)
    p = 36  # one board unit per px: sample every pixel centre of the layout image
    yy, xx = np.mgrid[0:4 * p, 0:5 * p] + 0.5
    cls = t.classify(xx - 36.0, yy - 36.0)  # our frame starts one square in
    assert np.array_equal(cls, (layout_image(board, p) > 127).astype(np.uint8))
    assert t.classify(np.array([-40.0, -60.0]), np.array([0.0, 0.0])).tolist() == [1, 2]  # margin, off the paper


def test_render_matches_brute_force():
    cam = Camera(np.array([[110.0, 0, 47.5], [0, 110.0, 35.5], [0, 0, 1]]), np.array([-0.2, 0.05, 0.0, 0.0, 0.0]), (96, 72))
    t = CharucoTarget(parse_board(B), margin=0.3)
    rvec, tvec = np.array([0.3, -0.2, 0.1]), np.array([-55.0, -40.0, 190.0])
    img = render_board(cam, t, rvec, tvec, np.full((72, 96), BACKGROUND, np.float32))
    ref = brute_force_render(cam, t, rvec, tvec, 24)
    assert np.abs(img - ref).max() < 0.035 and np.abs(img - ref).mean() < 2e-3


def test_preset_board_labels_markers():
    s = make_sample(get_preset("occluded", board=B), 3, 0, size=(320, 240))
    lab = s.label
    assert lab["pattern_size"] == [4, 3] and lab["board"]["description"] == B
    m = lab["markers"]
    assert m["ids"] == list(range(10)) and np.asarray(m["corners"]).shape == (10, 4, 2)
    assert len(m["visible"]) == 10 and s.visible.shape == (12,)


def test_chessboard_presets_are_unchanged():
    assert get_preset("clean").board is None
    s = make_sample("clean", 0, 0, size=(160, 120))
    assert "markers" not in s.label and s.label["board"].get("type") is None


def test_bad_board_in_a_preset_is_an_error():
    with pytest.raises(ValueError, match="smaller than square"):
        get_preset("clean", board="charuco:5x4,square=30mm,marker=40mm,dict=DICT_4X4_50")


def test_data_gen_cli_takes_a_board(tmp_path, capsys):
    import json

    from data_gen.__main__ import main

    out = tmp_path / "ds"
    assert main(["--out", str(out), "--count", "2", "--preset", "clean", "--size", "160x120", "--board", B,
                 "--no-progress"]) == 0
    label = json.loads((out / "labels" / "000001.json").read_text())
    assert label["board"]["description"] == B and "markers" in label
    assert json.loads((out / "meta.json").read_text())["preset_config"]["board"] == B
    assert main(["--out", str(tmp_path / "x"), "--count", "1", "--preset", "clean",
                 "--board", "charuco:5x4,square=30mm,marker=30mm,dict=DICT_4X4_50"]) == 2
    assert "smaller than square" in capsys.readouterr().err
