import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

_spec = importlib.util.spec_from_file_location("closeup_families_bench",
                                               Path(__file__).parents[2] / "benchmarks" / "closeup_families.py")
cf = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(cf)


def test_a_board_facing_the_lens_has_its_corners_and_squares_off_axis_as_their_rays():
    # a 9×6 board of 25 mm squares, 100 mm in front of the lens, its corner (4, 0) on the optical axis
    label = {"pattern_size": [9, 6], "square_size": 25.0, "rvec": [0.0, 0.0, 0.0], "tvec": [-100.0, 0.0, 100.0]}
    deg = cf.off_axis_deg(label).reshape(6, 9)
    assert deg[0, 4] == pytest.approx(0.0) and deg[0, 8] == pytest.approx(45.0)
    assert deg[5, 8] == pytest.approx(math.degrees(math.atan(math.hypot(100.0, 125.0) / 100.0)))
    squares = cf.off_axis_deg(label, squares=True)  # the outer squares' outer corners reach further
    assert len(squares) == 11 * 8 and squares.max() == pytest.approx(math.degrees(math.atan(math.hypot(125.0, 150.0) / 100.0)))


def test_each_family_pins_its_law_and_the_split_pins_the_lens_family():
    tune = cf.family_condition("vig-hard", "tune", 5)
    held = cf.family_condition("cover-30-50", "held-out", 5)
    assert tune.preset.lens == "fisheye" and held.preset.lens == ("ds", "eucm")
    vig = [dict(r.params) for r in tune.preset.rules if r.name == "rim_vignetting"][0]
    assert vig["law"] == "hard" and held.preset.pose.circle_fill == (0.3, 0.5) and tune.seed == 5
    assert cf.family_condition("rim-reach-hd", "tune", 5).size == (1280, 960)
    assert set(np.unique([cf.family_condition(n, "tune", 1).preset.name for n in cf.families()]).tolist()) == \
        {f"{n}-tune" for n in cf.families()}


def test_the_image_law_families_are_rim_reach_with_one_law_added():
    from data_gen.sample import draw_steps

    ref = cf.family_condition("rim-reach", "held-out", 7).preset
    for name in cf.image_laws():
        p = cf.family_condition(name, "held-out", 7).preset
        assert (p.lens, p.fisheye_fov_deg, p.pose, p.sizes) == (ref.lens, ref.fisheye_fov_deg, ref.pose, ref.sizes)
        assert cf.families()[name]["rim"]  # the same scenes kept, image by image
    ca = cf.family_condition("ca-lateral", "tune", 7).preset.rules
    assert ca[:len(ref.rules)] == ref.rules and ca[-1].name == "lateral_ca"
    plain = draw_steps(ref.rules, np.random.default_rng(3))
    disc = draw_steps(cf.family_condition("defocus-disc", "tune", 7).preset.rules, np.random.default_rng(3))
    blur = next(s for s in plain if s["name"] == "field_blur")
    pill = next(s for s in disc if s["name"] == "field_defocus")
    assert pill["radius_rim"] == pytest.approx(2 * blur["sigma_rim"]) and pill["power"] == blur["power"]
    assert plain[-1] == disc[-1]  # the noise after it drawn alike
