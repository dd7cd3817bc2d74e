from dataclasses import replace

import cv2
import numpy as np
import pytest

from data_gen.degrade import PIPELINE_ORDER, depth_blur, glare
from data_gen.presets import Rule, get_preset
from data_gen.sample import make_sample


def _edge_slope(img: np.ndarray, x: int) -> float:
    """The steepest step (grey per px) of a row of vertical stripes near column x."""
    return float(np.abs(np.diff(img[10, x - 6:x + 6])).max())


def test_depth_blur_is_sharp_at_the_focus_and_blurs_towards_both_ends_of_the_board():
    stripes = np.tile(((np.arange(120) // 4) % 2).astype(np.float32), (20, 1))  # an edge every 4 px
    # inverse depth 1/z falls from 0.02 (near, x = 0) to 0.01 (far, x = 119); the focus half way in 1/z
    wu = -0.01 / 119.0
    out = depth_blur(stripes, None, focus=0.5, sigma_min=0.5, sigma_max=2.5, w0=0.02, wu=wu, wv=0.0,
                     w_near=0.02, w_far=0.01)
    near, mid, far = _edge_slope(out, 8), _edge_slope(out, 60), _edge_slope(out, 110)
    assert mid > 2 * near and mid > 2 * far
    # the focus at the far end: the near end blurs most
    out = depth_blur(stripes, None, focus=0.0, sigma_min=0.5, sigma_max=2.5, w0=0.02, wu=wu, wv=0.0,
                     w_near=0.02, w_far=0.01)
    assert _edge_slope(out, 110) > _edge_slope(out, 60) > _edge_slope(out, 8)
    assert PIPELINE_ORDER.index("depth_blur") < PIPELINE_ORDER.index("gaussian_noise")  # optics before the sensor


def test_a_scene_gives_depth_blur_the_boards_inverse_depth_plane():
    rule = Rule.of("depth_blur", focus=0.5, sigma_min=0.5, sigma_max=2.0)
    preset = replace(get_preset("tilt_steep"), distortion=("none",), rules=(rule,))
    s = make_sample(preset, 3, 0, size=(320, 240), pattern=(5, 4))
    step = [d for d in s.label["degradations"] if d["name"] == "depth_blur"][0]
    R = cv2.Rodrigues(np.asarray(s.label["rvec"]).reshape(3, 1))[0]
    cols, rows = s.label["pattern_size"]
    c, r = np.meshgrid(np.arange(cols), np.arange(rows))
    obj = np.stack([c.ravel(), r.ravel(), np.zeros(c.size)], 1) * s.label["square_size"]
    inv = 1.0 / (obj @ R[2] + s.label["tvec"][2])  # 1/z of each inner corner, OpenCV order as the labels
    xy = s.corners
    # a pinhole lens without distortion: 1/z is exactly a plane of the pixel
    assert step["w0"] + step["wu"] * xy[:, 0] + step["wv"] * xy[:, 1] == pytest.approx(inv, rel=1e-6)
    assert step["w_near"] == pytest.approx(inv.max()) and step["w_far"] == pytest.approx(inv.min())


def test_glare_adds_light_that_lifts_black_and_white_alike():
    img = np.tile(np.array([0.1, 0.8], np.float32), (40, 30))
    out = glare(img, np.random.default_rng(0), strength=0.4, radius=0.2)
    lift = out - img
    assert lift.max() == pytest.approx(0.4, abs=0.02) and lift.min() >= 0.0
    # at the sheen's peak, the black and white pixels beside each other are lifted by the same light
    y, x = np.unravel_index(int(np.argmax(lift)), lift.shape)
    x -= x % 2
    assert lift[y, x] == pytest.approx(lift[y, x + 1], abs=0.01)
