"""The training presets of the corner network: equidistant fisheyes only (DS and EUCM stay held out for
evaluation), close-ups reaching the rim, and tilts beyond evaluate's tilt60."""

import cv2
import numpy as np

from data_gen import get_preset, make_sample


def _tilt_deg(label: dict) -> float:
    r = cv2.Rodrigues(np.array(label["rvec"], np.float64))[0]
    return float(np.degrees(np.arccos(abs(r[2, 2]))))


def test_train_fisheye_draws_equidistant_lenses_only_with_randomised_rim_laws():
    preset = get_preset("train_fisheye")
    assert preset.lens == "fisheye"  # the unified (DS, EUCM) family is never trained on
    labels = [make_sample(preset, 0, i, size=(320, 240)).label for i in range(8)]
    assert {lab["distortion_model"] for lab in labels} == {"equidistant"}
    laws = {d["name"] for lab in labels for d in lab["degradations"]}
    assert {"field_blur", "gaussian_noise"} <= laws and laws & {"circle_falloff", "rim_vignetting"}


def test_train_steep_reaches_tilts_beyond_70_degrees():
    tilts = [_tilt_deg(make_sample("train_steep", 0, i, size=(320, 240)).label) for i in range(12)]
    assert max(tilts) > 70.0 and max(tilts) <= 80.01


def test_train_fisheye_adds_the_map_gap_laws_now_and_then():
    rules = {r.name: r for r in get_preset("train_fisheye").rules if r.p <= 0.1}
    assert {"unsharp", "shot_noise"} <= set(rules) and dict(rules["shot_noise"].params)["photons"][0] <= 20.0


def test_train_rim_aims_its_close_ups_at_the_rim_and_past_it():
    from dataclasses import replace

    from data_gen.sample import draw_scene

    def paper_deg(sc) -> float:  # the paper's farthest corner off the optical axis
        r = cv2.Rodrigues(np.asarray(sc.rvec, np.float64))[0]
        x0, y0, x1, y1 = sc.board.paper_bounds()
        p = np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x0, y1, 0.0], [x1, y1, 0.0]]) @ r.T + sc.tvec
        return float(np.degrees(np.arctan2(np.hypot(p[:, 0], p[:, 1]), p[:, 2])).max())

    rim = get_preset("train_rim")
    assert rim.lens == "fisheye" and rim.pose.rim_share > 0.5 and rim.pose.rim_reach[1] > 1.0
    plain = replace(rim, pose=replace(rim.pose, rim_share=0.0))
    deep = [paper_deg(draw_scene(rim, 3, i, size=(160, 120))) for i in range(10)]
    usual = [paper_deg(draw_scene(plain, 3, i, size=(160, 120))) for i in range(10)]
    assert np.median(deep) >= 84.0 and np.median(deep) > np.median(usual) + 3.0  # 84.6 against 77.5
    laws = {r.name for r in rim.rules}
    assert {"astigmatism", "bayer_demosaic", "tone_curve", "lateral_ca", "field_defocus", "circle_edge"} <= laws
