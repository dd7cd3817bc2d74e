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
