import importlib.util
from pathlib import Path

import numpy as np
import pytest

_spec = importlib.util.spec_from_file_location("tilt_families_bench",
                                               Path(__file__).parents[2] / "benchmarks" / "tilt_families.py")
tf = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tf)


def test_each_family_pins_its_law_and_the_split_pins_the_lens_family():
    tune, size, pattern, tilt = tf.family_preset("dof", "tune")
    assert tune.lens == "pinhole" and size == (640, 480) and pattern == (9, 6) and tilt == (55.0, 80.0)
    assert "depth_blur" in [r.name for r in tune.rules] and "gaussian_noise" in [r.name for r in tune.rules]
    held, _, _, tilt = tf.family_preset("tilt-62-70", "held-out")
    assert held.lens == ("pinhole", "fisheye") and held.distortion == ("strong",) and tilt == (62.0, 70.0)
    assert held.pose.tilt_max_deg == 70.0 and held.pose.fill == tune.pose.fill
    assert tf.family_preset("hd", "tune")[1] == (1280, 960) and tf.family_preset("board-11x8", "tune")[2] == (11, 8)
    assert tf.family_preset("fill-small", "tune")[0].pose.fill == (0.25, 0.45)


def test_a_family_keeps_only_boards_in_its_tilt_bin():
    index, s = next(tf.samples("tilt-70-80", "tune", 301, 1))
    assert 70.0 <= tf.board_tilt_deg(s.label) <= 80.0 and s.label["pattern_size"] == [9, 6]


def test_a_squares_thickness_is_its_height_across_its_longest_side():
    # a lattice sheared along x: steps (10, 0) and (8, 2): each square a parallelogram 2 px thick across (10, 0)
    c, r = np.meshgrid(np.arange(3), np.arange(2))
    corners = np.stack([10.0 * c + 8.0 * r, 2.0 * r], -1).reshape(-1, 2)
    assert tf.thinnest_px(corners, (3, 2)) == pytest.approx(2.0)  # area 20 over the longest side 10
