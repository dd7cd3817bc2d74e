"""Fisheye renders: exact labels past 90°, the image circle, and the renderer against brute force."""

import math

import numpy as np

from aicalib_tf.geometry import lens
from data_gen import Board, Camera, make_sample, render_board
from data_gen.camera import sample_fisheye
from data_gen.presets import get_preset
from data_gen.sample import OUTSIDE_CIRCLE

from .brute_force import BACKGROUND, brute_force_render


def _preset(fov):
    return get_preset("fisheye", fisheye_fov_deg=(fov, fov), sizes=((160, 120),), partial_probability=0.0,
                      rules=())


def test_sampled_fisheyes_have_the_asked_field_of_view():
    rng = np.random.default_rng(0)
    for fov in (150.0, 185.0, 200.0):
        cam = sample_fisheye(rng, (640, 480), fov_deg=(fov, fov))
        assert cam.model == "equidistant" and cam.fisheye
        assert cam.diagonal_fov_deg() == np.float64(cam.diagonal_fov_deg())
        if fov < 175:  # full frame: the diagonal sees the lens' FOV, every pixel is imaged
            assert abs(cam.diagonal_fov_deg() - fov) < 1.5
            assert np.isfinite(cam.pixel_to_ray(np.array([[-0.5, -0.5], [639.5, 479.5]]))).all()
        else:  # circular: the whole circle inside the frame, the corners dark
            assert math.degrees(cam.max_theta) == np.float64(fov / 2)
            r = cam.circle_radius()
            assert cam.cx - r * cam.fx >= -0.5 and cam.cx + r * cam.fx <= 639.5
            assert np.isnan(cam.pixel_to_ray(np.array([0.0, 0.0]))).all()
            edge = cam.pixel_to_ray(np.array([cam.cx + 0.999 * r * cam.fx, cam.cy]))
            assert math.degrees(math.atan2(math.hypot(edge[0], edge[1]), edge[2])) > 90.0


def test_labels_are_lens_projections_and_visibility_means_inside_the_circle():
    for fov in (150.0, 185.0):
        for i in range(3):
            s = make_sample(_preset(fov), 4, i, pattern=(9, 6))
            lab = s.label
            assert lab["distortion_model"] == "equidistant" and len(lab["dist"]) == 4
            R = np.array(__import__("cv2").Rodrigues(np.array(lab["rvec"]))[0])
            obj = Board((9, 6), lab["square_size"]).object_points()
            cam_pts = obj @ R.T + np.array(lab["tvec"])
            uv = lens.project(cam_pts, "equidistant", np.array(lab["K"]), lab["dist"])
            np.testing.assert_allclose(s.corners[s.visible], uv[s.visible], atol=1e-9)
            theta = np.degrees(np.arctan2(np.hypot(cam_pts[:, 0], cam_pts[:, 1]), cam_pts[:, 2]))
            assert np.all(theta[s.visible] <= lab["max_theta_deg"] + 1e-9)
            assert s.visible.any()


def test_outside_the_circle_is_dark():
    s = make_sample(_preset(185.0), 4, 0, pattern=(9, 6))
    assert s.image[0, 0] <= 255 * OUTSIDE_CIRCLE + 1 and s.image[-1, -1] <= 255 * OUTSIDE_CIRCLE + 1


def test_fisheye_render_matches_brute_force_past_90_degrees():
    # A board seen at 70–100° off-axis by a 200° lens: the renderer intersects 3-D rays.
    K = np.array([[40.0, 0, 79.5], [0, 40.0, 59.5], [0, 0, 1]])
    cam = Camera(K, np.array([0.01, -0.002, 0.0, 0.0]), (160, 120), model="equidistant", max_theta=math.radians(100))
    board = Board((4, 3), 0.1, 0.05, 0.1, 0.9)
    rvec = np.array([0.0, -math.pi / 2, 0.0])  # board plane facing -x, i.e. towards a camera looking along +z
    tvec = np.array([0.5, -0.15, -0.1])  # to the right and slightly behind the camera
    uv = lens.project(np.array([[0.5, 0.0, -0.05]]), "equidistant", K, cam.dist)
    assert np.isfinite(uv).all()  # behind z = 0 and still imaged
    bg = np.full((120, 160), BACKGROUND, np.float32)
    img = render_board(cam, board, rvec, tvec, bg)
    ref = brute_force_render(cam, board, rvec, tvec, 16)
    diff = np.abs(img - ref) / (board.white - board.black)
    assert (img != BACKGROUND).sum() > 200  # the board is really there
    assert diff.max() < 1 / 16 + 1 / 89 and diff.mean() < 3e-3


def test_ds_and_eucm_lenses_render_with_exact_labels():
    for model, fov in (("ds", 190.0), ("eucm", 170.0)):
        preset = get_preset("fisheye", lens=model, fisheye_fov_deg=(fov, fov), sizes=((160, 120),),
                            partial_probability=0.0, rules=())
        s = make_sample(preset, 5, 0, pattern=(9, 6))
        lab = s.label
        assert lab["distortion_model"] == model and len(lab["dist"]) == 2
        R = np.array(__import__("cv2").Rodrigues(np.array(lab["rvec"]))[0])
        cam_pts = Board((9, 6), lab["square_size"]).object_points() @ R.T + np.array(lab["tvec"])
        uv = lens.project(cam_pts, model, np.array(lab["K"]), lab["dist"])
        np.testing.assert_allclose(s.corners[s.visible], uv[s.visible], atol=1e-9)
        assert s.visible.sum() >= 6 and s.image.std() > 10  # a board is drawn
        cam = Camera(np.array(lab["K"]), lab["dist"], (160, 120), model=model, max_theta=math.radians(fov / 2))
        assert cam.fisheye and abs(cam.diagonal_fov_deg() - fov) < 1.5 + (fov >= 175) * 40
