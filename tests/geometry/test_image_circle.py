"""The image circle: estimated from synthetic photos (drawn disks, data_gen's circular fisheye
renders), None for photos that fill the frame, its field of view and its checks against a lens model."""

import math

import numpy as np
import pytest

from aicalib_tf.geometry.image_circle import (ImageCircle, boards_reach_deg, circle_fov_deg, circle_problem,
                                             estimate_image_circle, find_image_circle, thumbnail)
from aicalib_tf.geometry.lens import Lens


def _disk(size, centre, radius, rng, vignetting=0.6, noise=0.02):
    """(h, w) float32: a textured, vignetted disk (area-antialiased rim) on a black frame with noise."""
    w, h = size
    yy, xx = np.mgrid[:h, :w].astype(np.float64)
    d = np.hypot(xx - centre[0], yy - centre[1])
    scene = 0.5 + 0.3 * np.sin(xx / 17.0) * np.cos(yy / 23.0)
    img = np.clip(radius - d + 0.5, 0, 1) * scene * (1 - vignetting * (d / radius) ** 2)
    return (img + 0.02 + noise * rng.standard_normal((h, w))).astype(np.float32)


@pytest.mark.parametrize("centre, radius", [((640.3, 479.7), 450.0),  # the whole circle in the frame
                                            ((650.0, 470.0), 600.0),  # cut at top and bottom
                                            ((630.0, 490.0), 700.0)])  # cut on all four sides
def test_circle_from_the_mean_of_shrunk_photos(centre, radius):
    rng = np.random.default_rng(1)
    mean = np.mean([thumbnail(_disk((1280, 960), centre, radius, rng)) for _ in range(3)], axis=0)
    c = estimate_image_circle(mean, (1280, 960))
    assert c is not None
    assert c.cx == pytest.approx(centre[0], abs=0.5) and c.cy == pytest.approx(centre[1], abs=0.5)
    assert c.radius == pytest.approx(radius, abs=0.5)


def test_photos_that_fill_the_frame_have_no_circle():
    rng = np.random.default_rng(2)
    textured = np.clip(0.5 + 0.3 * rng.standard_normal((480, 640)), 0, 1).astype(np.float32)
    yy, xx = np.mgrid[:480, :640]
    vignetted = (0.8 * (1 - 0.5 * (np.hypot(xx - 320, yy - 240) / 400) ** 2)).astype(np.float32)  # grey corners
    for img in (textured, vignetted, np.full((480, 640), 0.4, np.float32), np.zeros((480, 640), np.float32)):
        assert estimate_image_circle(img) is None

        assert find_image_circle(img) == (None, "")  # photos that fill the frame: nothing to say


def test_dark_corners_that_no_circle_fits_are_said_so():
    rng = np.random.default_rng(3)
    yy, xx = np.mgrid[:480, :640]
    frame = (0.6 + 0.05 * rng.standard_normal((480, 640))).astype(np.float32)
    box = np.where((abs(xx - 320) <= 230) & (abs(yy - 240) <= 200), frame, 0.01).astype(np.float32)  # a lit rectangle
    circle, why = find_image_circle(box)
    assert circle is None and why.startswith("the frame's corners are dark but the bright area's boundary is no circle")
    assert estimate_image_circle(box) is None
    circle, why = find_image_circle(_disk((640, 480), (320.0, 240.0), 220.0, rng))
    assert circle is not None and why == ""


def test_circle_of_data_gen_circular_fisheye_renders():
    from data_gen import Camera, make_sample
    from data_gen.presets import get_preset

    preset = get_preset("fisheye", fisheye_fov_deg=(185.0, 185.0), sizes=((320, 240),), partial_probability=0.0)
    for seed in range(2):
        s = make_sample(preset, 4, seed, pattern=(9, 6))
        lab = s.label
        K = np.array(lab["K"])
        cam = Camera(K, lab["dist"], (320, 240), model=lab["distortion_model"], max_theta=math.radians(92.5))
        c = estimate_image_circle(s.image / 255.0)
        assert c is not None
        assert (c.cx, c.cy) == pytest.approx((K[0, 2], K[1, 2]), abs=0.5)
        assert c.radius == pytest.approx(cam.circle_radius() * 0.5 * (K[0, 0] + K[1, 1]), abs=0.6)


def test_bad_input_is_a_clear_error():
    with pytest.raises(ValueError, match="grey image"):
        estimate_image_circle(np.zeros((8, 8, 3)))
    with pytest.raises(ValueError, match="NaN"):
        estimate_image_circle(np.full((32, 32), np.nan))
    with pytest.raises(ValueError, match="radius > 0"):
        ImageCircle(10.0, 10.0, 0.0)


F = 300.0
K = np.array([[F, 0, 639.5], [0, F, 479.5], [0, 0, 1]])
CIRCLE = ImageCircle(639.5, 479.5, F * math.radians(92.5))  # an ideal 185° equidistant lens's circle


def test_boards_reach_is_the_widest_corners_ray():
    ideal = Lens("equidistant", K, None, (1280, 960))
    corners = [K[:2, 2] + F * math.radians(a) * np.array([math.cos(b), math.sin(b)]) for a, b in ((30, 1.0), (71, 2.0))]
    assert boards_reach_deg(ideal, corners) == pytest.approx(71.0, abs=1e-6)
    assert math.isnan(boards_reach_deg(ideal, np.zeros((0, 2))))


def test_field_of_view_of_a_circular_fisheye_is_its_circle():
    lens = Lens("equidistant", K, None, (1280, 960))
    assert circle_fov_deg(lens, CIRCLE) == pytest.approx(185.0, abs=1e-6)
    assert lens.field_of_view()["horizontal"] > 240  # the black corners, counted through the model
    fov = lens.field_of_view(CIRCLE)
    assert fov["horizontal"] == pytest.approx(185.0, abs=1e-6) and fov["diagonal"] == pytest.approx(185.0, abs=1e-6)
    assert fov["vertical"] == pytest.approx(math.degrees(2 * 479.5 / F) + 0.0, abs=0.2)  # the frame cuts it


def test_field_of_view_is_never_nan_and_says_beyond_the_model():
    lens = Lens("plumb_bob", np.array([[200.0, 0, 319.5], [0, 200, 239.5], [0, 0, 1]]), [-0.5, 0.1, 0, 0, 0], (640, 480))
    fov = lens.field_of_view()
    assert all(np.isfinite(fov[k]) for k in ("horizontal", "vertical", "diagonal")) and fov["beyond_model"]


def test_circle_problem_names_a_model_that_cannot_reach_the_rim_and_corners_outside():
    fisheye = Lens("equidistant", K, None, (1280, 960))
    assert circle_problem(fisheye, CIRCLE) is None
    pinhole = Lens("plumb_bob", K, [-0.5, 0, 0, 0, 0], (1280, 960))  # valid out to 163 px from the centre
    assert "beyond the rays the plumb_bob model images" in circle_problem(pinhole, CIRCLE)
    outside = np.array([[639.5 + CIRCLE.radius + 10, 479.5]])
    assert "1 detected corners lie outside" in circle_problem(fisheye, CIRCLE, outside)


def test_undistortion_maps_are_invalid_outside_the_circle():
    lens = Lens("equidistant", K, None, (1280, 960))
    small = ImageCircle(639.5, 479.5, 200.0)
    new_K = np.array([[150.0, 0, 639.5], [0, 150.0, 479.5], [0, 0, 1]])  # wide enough to see past the small circle
    mx, my = lens.undistort_maps(new_K=new_K, circle=small)
    valid = mx >= 0
    assert valid.any() and (~valid).any()
    assert np.all(np.hypot(mx[valid] - 639.5, my[valid] - 479.5) <= 200.0 + 1e-3)


def test_doctests():
    import doctest

    from aicalib_tf.geometry import image_circle

    assert doctest.testmod(image_circle).failed == 0


def test_circle_cut_by_the_frame_with_dark_things_reaching_into_it():
    """A circle cut at top, bottom and right (as on a 185° lens on a 4:3 sensor) whose rim dark objects
    touch from inside (a chair's legs): their dents in the dark area's boundary are left out."""
    rng = np.random.default_rng(4)
    size, centre, radius = (1032, 778), (546.0, 370.0), 544.0
    img = _disk(size, centre, radius, rng)
    yy, xx = np.mgrid[:size[1], :size[0]]
    for a in np.radians([120.0, 130.0, 140.0, 150.0]):  # dark bars from the rim inwards, lower left
        ux, uy = np.cos(a), np.sin(a)
        along = (xx - centre[0]) * ux + (yy - centre[1]) * uy
        across = np.abs(-(xx - centre[0]) * uy + (yy - centre[1]) * ux)
        img[(along > radius - 90) & (across < 9)] = 0.02
    c = estimate_image_circle(thumbnail(img), size)
    assert c is not None
    assert (c.cx, c.cy) == pytest.approx(centre, abs=1.0) and c.radius == pytest.approx(radius, abs=1.0)
