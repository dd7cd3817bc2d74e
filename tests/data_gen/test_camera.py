import math

import cv2
import numpy as np
import pytest

from aicalib_tf.geometry.camera import Camera, distort_normalized, monotonic_radius, undistort_normalized
from data_gen.camera import sample_camera

STRONGEST = np.array([-0.45, 0.55 * 0.45**2, 0.0012, -0.0012, -0.002])  # the sampler's extreme barrel


def _pixel_grid(w, h, step=4.0):
    us, vs = np.meshgrid(np.arange(-0.5, w, step), np.arange(-0.5, h, step))
    return np.stack([us, vs], axis=-1).reshape(-1, 2)


def test_distort_matches_opencv_projectpoints():
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(-1.2, 1.2, (500, 2)), np.ones(500)])
    K = np.eye(3)
    dist = np.array([-0.3, 0.08, 0.001, -0.002, 0.01])
    ref, _ = cv2.projectPoints(pts.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, dist)
    ours = distort_normalized(pts[:, :2], dist)
    assert np.max(np.abs(ours - ref.reshape(-1, 2))) < 1e-12


def test_inverse_round_trips_over_whole_image_for_strongest_distortion():
    w, h = 1920, 1080
    # HFOV 120 degrees through the distortion, as the sampler would set it.
    r_edge = math.tan(math.radians(60))
    k1, k2, _, _, k3 = STRONGEST
    fx = (w / 2) / (r_edge * (1 + k1 * r_edge**2 + k2 * r_edge**4 + k3 * r_edge**6))
    cam = Camera(np.array([[fx, 0, (w - 1) / 2], [0, fx, (h - 1) / 2], [0, 0, 1]]), STRONGEST, (w, h))
    uv = _pixel_grid(w, h)
    xy = cam.pixel_to_normalized(uv)
    assert np.all(np.isfinite(xy)), "every pixel of the image must have an inverse"
    pts3 = np.column_stack([xy, np.ones(len(xy))])
    back, _ = cv2.projectPoints(pts3.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.dist)
    err = np.linalg.norm(back.reshape(-1, 2) - uv, axis=1)
    assert err.max() < 1e-3
    # The field of view really is wide: the image corners are ~65 degrees off-axis.
    assert math.degrees(math.atan(np.max(np.hypot(xy[:, 0], xy[:, 1])))) > 60


def test_points_outside_monotonic_domain_have_no_inverse():
    dist = np.array([-0.45, 0.05, 0, 0, 0])  # folds back: not monotonic
    r_mono = monotonic_radius(dist)
    assert r_mono < 2.0
    peak = r_mono * (1 - 0.45 * r_mono**2 + 0.05 * r_mono**4)
    out = undistort_normalized(np.array([[peak * 1.01, 0.0], [peak * 0.5, 0.0]]), dist)
    assert np.isnan(out[0]).all() and np.isfinite(out[1]).all()


@pytest.mark.parametrize(
    "level, hfov", [("none", (40, 120)), ("mild", (40, 120)), ("strong", (70, 120)), ("pincushion", (40, 75))]
)
def test_sampled_cameras_are_realistic_and_monotonic(level, hfov):
    rng = np.random.default_rng(1)
    for size in [(640, 480), (1920, 1080)]:
        for _ in range(10):
            cam = sample_camera(rng, size, hfov_deg=hfov, distortion=level)
            assert cam.image_size == size
            assert 39.5 <= cam.horizontal_fov_deg() <= 120.5
            w, h = size
            corners = cam.pixel_to_normalized(np.array([[-0.5, -0.5], [w - 0.5, -0.5], [-0.5, h - 0.5], [w - 0.5, h - 0.5]]))
            assert np.all(np.isfinite(corners))
            if level == "strong":
                assert cam.dist[0] <= -0.25
            if level == "pincushion":
                assert cam.dist[0] > 0


def test_strong_barrel_reaches_k1_minus_045():
    rng = np.random.default_rng(2)
    k1s = [sample_camera(rng, (640, 480), hfov_deg=(90, 120), distortion="strong").dist[0] for _ in range(60)]
    assert min(k1s) < -0.42


def test_camera_validates_inputs():
    with pytest.raises(ValueError, match="5 coefficients"):
        Camera(np.eye(3), np.zeros(6), (640, 480))
    with pytest.raises(ValueError, match="image_size"):
        Camera(np.eye(3), np.zeros(5), (0, 0))
