"""geometry.camera.Camera is a thin wrapper over geometry.lens (one geometry)."""

import math

import cv2
import numpy as np
import pytest

from aicalib_tf.geometry import lens
from aicalib_tf.geometry.camera import Camera, distortion_field, normalized_rays

K = np.array([[300.0, 0, 320.0], [0, 301.0, 240.0], [0, 0, 1]])


def test_pinhole_camera_is_lens_and_opencv():
    d = np.array([-0.3, 0.08, 0.001, -0.002, 0.01])
    cam = Camera(K, d, (640, 480))
    assert cam.model == "plumb_bob" and cam.lens == lens.Lens("plumb_bob", K, d, (640, 480))
    pts = np.column_stack([np.random.default_rng(0).uniform(-0.8, 0.8, (100, 2)), np.ones(100)])
    ref, _ = cv2.projectPoints(pts.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, d)
    np.testing.assert_allclose(cam.project(pts), ref.reshape(-1, 2), atol=1e-9)
    xy = cam.pixel_to_normalized(ref.reshape(-1, 2))
    np.testing.assert_allclose(xy, pts[:, :2], atol=1e-9)
    rays = cam.pixel_to_ray(ref.reshape(-1, 2))
    assert np.all(rays[:, 2] == 1.0)
    ok_xy, ok = normalized_rays(ref.reshape(-1, 2), K, d)
    assert ok.all() and np.allclose(ok_xy, pts[:, :2], atol=1e-9)
    f1, _ = distortion_field(ref.reshape(-1, 2), K, d)
    f2, _ = lens.distortion_field(ref.reshape(-1, 2), "plumb_bob", K, d)
    np.testing.assert_array_equal(f1, f2)


def test_fisheye_rays_past_90_degrees_and_the_circle():
    k = np.array([0.02, -0.003, 0.001, 0.0])
    cam = Camera(K, k, (640, 480), model="equidistant", max_theta=math.radians(95))
    theta = np.radians([0.0, 45.0, 89.0, 94.0, 96.0])
    pts = np.stack([np.sin(theta), np.zeros(5), np.cos(theta)], axis=1)
    uv = cam.project(pts)
    assert np.isfinite(uv[:4]).all() and np.isnan(uv[4]).all()  # 96° is outside the circle
    back = cam.pixel_to_ray(uv[:4])
    np.testing.assert_allclose(back, pts[:4], atol=1e-9)
    assert cam.imaged(pts).tolist() == [True, True, True, True, False]
    assert cam.inside_circle(uv[:4]).all()
    wide = Camera(np.array([[100.0, 0, 320], [0, 100.0, 240], [0, 0, 1]]), k, (640, 480), model="equidistant",
                  max_theta=math.radians(95))
    assert wide.horizontal_fov_deg() == pytest.approx(190.0)  # the circle is inside the frame
    assert np.isnan(cam.pixel_to_normalized(uv[3])).all()  # behind 90°: no pinhole coordinates


def test_camera_rejects_bad_input():
    with pytest.raises(ValueError, match="unknown lens model"):
        Camera(K, np.zeros(4), (640, 480), model="fisheye62")
    with pytest.raises(ValueError, match="4 coefficients"):
        Camera(K, np.zeros(5), (640, 480), model="equidistant")
    with pytest.raises(ValueError, match="max_theta"):
        Camera(K, np.zeros(4), (640, 480), model="equidistant", max_theta=4.0)
