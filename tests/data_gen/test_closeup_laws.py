"""closeup_laws and tilt_steep: other light-fall-off laws, the paper's margin and contrast, steep tilts."""

import math

import cv2
import numpy as np
import pytest

from data_gen.degrade import RIM_LAWS, rim_vignetting
from data_gen.presets import get_preset
from data_gen.sample import draw_scene, draw_steps


@pytest.mark.parametrize("law, half", [("cos4", 0.75), ("poly", 0.3 * 0.25 + 0.7 / 64), ("hard", 0.0)])
def test_every_law_keeps_the_centre_and_is_black_at_the_circle(law, half):
    img = np.ones((1, 5), np.float32)
    out = rim_vignetting(img, None, law=law, strength=1.0, edge=0.5, cx=0.0, cy=0.0, radius=4.0)[0]
    assert out[0] == pytest.approx(1.0) and out[4] == pytest.approx(0.0, abs=1e-6)
    assert out[2] == pytest.approx(1.0 - half, abs=1e-5)  # ρ = 0.5
    assert np.all(np.diff(out) <= 1e-7)  # never brighter further out


def test_an_unknown_law_is_refused():
    with pytest.raises(ValueError, match="law must be one of"):
        rim_vignetting(np.ones((2, 2), np.float32), None, law="linear", strength=1.0, edge=0.5, cx=0.0, cy=0.0,
                       radius=1.0)


def test_the_law_is_drawn_among_all_three_and_the_circle_is_filled_in():
    rules = get_preset("closeup_laws").rules
    laws = {draw_steps(rules, np.random.default_rng(k))[0]["law"] for k in range(30)}
    assert laws == set(RIM_LAWS)
    sc = draw_scene("closeup_laws", 41, 0, size=(320, 240), pattern=(9, 6))
    step = next(s for s in sc.steps if s["name"] == "rim_vignetting")
    assert step["radius"] > 0 and 0 <= step["cx"] < 320


def test_close_ups_use_the_preset_margins_and_paper_contrast():
    p = get_preset("closeup_laws")
    boards = [draw_scene(p, 41, i, size=(320, 240), pattern=(9, 6)).board for i in range(8)]
    assert all(p.margin_range[0] <= b.margin <= p.margin_range[1] for b in boards)
    assert all(p.paper_black[0] <= b.black <= p.paper_black[1] for b in boards)
    assert all(p.paper_white[0] <= b.white <= p.paper_white[1] for b in boards)
    assert min(b.margin for b in boards) < 0.15  # narrower than any other preset's


def test_steep_tilts_reach_past_70_degrees():
    tilts = []
    for i in range(12):
        sc = draw_scene("tilt_steep", 41, i, pattern=(9, 6))
        normal = cv2.Rodrigues(np.asarray(sc.rvec, np.float64))[0][:, 2]
        tilts.append(math.degrees(math.acos(min(1.0, abs(normal[2])))))
    assert max(tilts) > 70.0 and max(tilts) <= 80.0 + 1e-6
