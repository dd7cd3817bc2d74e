"""The fisheye_closeup preset: boards close to circular fisheyes, exact labels, the stated fill."""

import math

import cv2
import numpy as np
import pytest

from aicalib_tf.geometry import lens
from data_gen import make_sample
from data_gen.degrade import circle_falloff, field_blur
from data_gen.pose import paper_circle_fill
from data_gen.presets import get_preset
from data_gen.sample import OUTSIDE_CIRCLE, draw_scene

PRESET = get_preset("fisheye_closeup")


@pytest.fixture(scope="module")
def scenes():
    return [draw_scene(PRESET, 3, i, size=(320, 240), pattern=(9, 6)) for i in range(12)]


def test_lenses_are_circular_fisheyes_of_every_family(scenes):
    assert {sc.camera.model for sc in scenes} == {"equidistant", "ds", "eucm"}
    for sc in scenes:
        cam = sc.camera
        assert 150.0 - 1e-9 <= 2 * math.degrees(cam.max_theta) <= 200.0 + 1e-9
        r = cam.circle_radius()
        w, h = cam.image_size
        assert cam.cx - r * cam.fx >= -0.5 and cam.cx + r * cam.fx <= w - 0.5
        assert cam.cy - r * cam.fy >= -0.5 and cam.cy + r * cam.fy <= h - 0.5


def test_boards_fill_the_stated_share_of_the_image_circle(scenes):
    lo, hi = PRESET.pose.circle_fill
    fills = []
    for sc in scenes:
        R = cv2.Rodrigues(np.asarray(sc.rvec))[0]
        fills.append(paper_circle_fill(sc.board, R, sc.tvec, sc.camera))
        assert sc.visible.all()  # the whole board is imaged, inside the circle
    assert lo - 1e-6 <= min(fills) and max(fills) <= hi + 1e-6
    assert max(fills) - min(fills) > 0.15  # drawn over the range, not one size


def test_labels_are_the_lens_projections_of_the_pose():
    for i in range(4):
        s = make_sample(PRESET, 5, i, size=(320, 240), pattern=(9, 6))
        lab = s.label
        R = cv2.Rodrigues(np.array(lab["rvec"]))[0]
        sq = lab["square_size"]
        obj = np.array([(c * sq, r * sq, 0.0) for r in range(6) for c in range(9)])
        uv = lens.project(obj @ R.T + np.array(lab["tvec"]), lab["distortion_model"], np.array(lab["K"]),
                          lab["dist"])
        np.testing.assert_allclose(s.corners, uv, atol=1e-9)
        assert lab["condition"] == "fisheye_closeup" and s.visible.all()


def test_lines_bend_strongly(scenes):
    # the middle corner of a line is far off the chord of its ends: strong bending, on most boards
    bows = []
    for sc in scenes:
        c = sc.corners.reshape(6, 9, 2)
        a, b, m = c[:, 0], c[:, -1], c[:, 4]
        d = b - a
        off = np.abs(d[:, 0] * (m - a)[:, 1] - d[:, 1] * (m - a)[:, 0]) / np.linalg.norm(d, axis=1)
        bows.append(np.max(off / np.linalg.norm(d, axis=1)))
    assert np.median(bows) > 0.03


def test_vignetting_falls_to_black_at_the_circle_and_blur_grows_towards_it():
    s = make_sample(PRESET, 5, 0, size=(320, 240), pattern=(9, 6))
    steps = {d["name"]: d for d in s.label["degradations"]}
    assert {"circle_falloff", "field_blur"} <= set(steps)
    sc = draw_scene(PRESET, 5, 0, size=(320, 240), pattern=(9, 6))
    cam = sc.camera
    circle = steps["circle_falloff"]
    assert circle["cx"] == pytest.approx(cam.cx) and circle["cy"] == pytest.approx(cam.cy)
    assert circle["radius"] == pytest.approx(cam.circle_radius() * math.sqrt(cam.fx * cam.fy))
    assert s.image[0, 0] <= 255 * OUTSIDE_CIRCLE + 8  # outside the circle: dark, noise aside
    flat = np.ones((101, 101), np.float32)
    lit = circle_falloff(flat, None, strength=1.0, power=3.0, cx=50.0, cy=50.0, radius=50.0)
    assert lit[50, 50] == pytest.approx(1.0) and lit[50, 0] == pytest.approx(0.0, abs=1e-6)
    assert lit[50, 25] > lit[50, 10] > lit[50, 2]
    edges = np.zeros((101, 101), np.float32)
    edges[:, 50:] = 1.0  # a vertical edge through the centre
    out = field_blur(edges, None, sigma_centre=0.5, sigma_rim=3.0, power=2.0, cx=50.0, cy=50.0, radius=50.0)
    width = lambda row: int(np.sum((out[row] > 0.05) & (out[row] < 0.95)))  # noqa: E731
    assert width(5) > width(50)  # near the rim (row 5) the edge is wider than at the centre
