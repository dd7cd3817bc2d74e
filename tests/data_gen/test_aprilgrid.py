"""data_gen's AprilGrid: the printed layout cell for cell, rendered views (pinhole, partial, fisheye)
that the detector reads back with the true ids, and the labels of a rendered set."""

import cv2
import numpy as np
import pytest

from aicalib_tf.geometry.aprilgrid import layout_image, parse_board
from aicalib_tf.geometry.camera import Camera
from aicalib_tf.geometry.pose import project_points
from data_gen.aprilgrid import AprilGridTarget
from data_gen.render import render_board
from data_gen.targets import parse_marker_board
from tests.data_gen.brute_force import BACKGROUND, brute_force_render

BOARD = parse_board("aprilgrid:6x6,tag=88mm,spacing=0.3")


@pytest.mark.parametrize("text, q", [("aprilgrid:6x6,tag=88mm,spacing=0.3", 8),
                                     ("aprilgrid:3x2,tag=80mm,spacing=0.25,family=tag25h9,first=5", 9)])
def test_classify_is_the_printed_layout(text, q):
    board = parse_board(text)
    m = board.fraction[0] * q + 5  # q px a lattice unit: whole px a tag bit
    img = layout_image(board, q, m)
    jj, ii = np.meshgrid(np.arange(img.shape[1]), np.arange(img.shape[0]))
    X, Y = ((v - m + 0.5) / q * board.square_size for v in (jj, ii))  # the pixel centres on the board
    cls = AprilGridTarget(board, margin=1.0).classify(X, Y)
    assert set(np.unique(cls)) == {0, 1} and np.array_equal(cls == 0, img == 0)


def test_render_matches_brute_force():
    cam = Camera(np.array([[110.0, 0, 47.5], [0, 110.0, 35.5], [0, 0, 1]]), np.array([-0.2, 0.05, 0.0, 0.0, 0.0]), (96, 72))
    t = AprilGridTarget(parse_board("aprilgrid:2x2,tag=40mm,spacing=0.3"), margin=0.3)
    rvec, tvec = np.array([0.3, -0.2, 0.1]), np.array([-45.0, -40.0, 190.0])
    img = render_board(cam, t, rvec, tvec, np.full((72, 96), BACKGROUND, np.float32))
    ref = brute_force_render(cam, t, rvec, tvec, 24)
    assert np.abs(img - ref).max() < 0.035 and np.abs(img - ref).mean() < 2e-3


def _view(cam: Camera, rvec, centre_px, z):
    """The grid's centre seen at ``centre_px`` from ``z`` mm: (uint8 image, rvec, tvec)."""
    target = AprilGridTarget(BOARD)
    R, _ = cv2.Rodrigues(np.asarray(rvec, np.float64))
    ray = cam.pixel_to_ray(np.asarray(centre_px, np.float64))
    tvec = z * ray / ray[2] - R @ target.centre()
    bg = np.full(cam.image_size[::-1], 0.5, np.float32)
    img = render_board(cam, target, rvec, tvec, bg, samples=34, junction_samples=89)  # the video's sampling
    img = cv2.GaussianBlur(img, (0, 0), 0.7)
    return np.clip(np.rint(img * 255), 0, 255).astype(np.uint8), np.asarray(rvec, np.float64), tvec


PINHOLE = Camera(np.array([[600.0, 0, 319.5], [0, 600.0, 239.5], [0, 0, 1]]), np.zeros(5), (640, 480))
FISHEYE = Camera(np.array([[230.0, 0, 319.5], [0, 230.0, 239.5], [0, 0, 1]]), np.array([0.05, -0.01, 0, 0]), (640, 480),
                 model="equidistant")


@pytest.mark.parametrize("cam, rvec, centre, z, partial", [
    (PINHOLE, [0.3, -0.2, 0.1], (320, 240), 1100, False),
    (PINHOLE, [-0.3, 0.35, -0.2], (600, 220), 800, True),  # the grid's right half out of frame
    (FISHEYE, [0.2, -0.3, 0.1], (200, 300), 400, False),
], ids=["pinhole", "pinhole-partial", "fisheye"])
def test_rendered_views_read_back_with_true_ids(cam, rvec, centre, z, partial):
    from aicalib_tf.detect.boards.aprilgrid import detect_aprilgrid

    img, rvec, tvec = _view(cam, rvec, centre, z)
    truth = project_points(BOARD.object_points(), rvec, tvec, cam)  # every corner, corner_ids order
    det = detect_aprilgrid(img, BOARD)
    assert det.why == "" and len(det.ids) >= 40
    w, h = cam.image_size
    assert (not ((truth >= 0) & (truth <= [w - 1, h - 1])).all()) == partial
    d = np.linalg.norm(det.corners[:, None] - truth[None], axis=2)  # (found, all)
    own = [int(np.flatnonzero((BOARD.corner_ids() == i).all(axis=1))[0]) for i in det.ids.tolist()]
    assert np.array_equal(d.argmin(axis=1), own)  # each corner nearest its own id's truth
    err = d[np.arange(len(own)), own]
    assert err.max() < 0.05, np.sort(err)[-5:]


def test_a_rendered_set_labels_every_tag_corner_and_tag(tmp_path):
    from data_gen.presets import get_preset
    from data_gen.sample import make_sample

    preset = get_preset("fisheye", board="aprilgrid:3x3,tag=60mm,spacing=0.3,first=7")
    s = make_sample(preset, seed=2, index=0, size=(320, 240))
    lab = s.label
    ids, corners = np.asarray(lab["ids"]), np.asarray(lab["corners"])
    assert ids.shape == (36, 2) and corners.shape == (36, 2) and len(lab["visible"]) == 36
    assert lab["board"]["type"] == "aprilgrid" and lab["tags"]["ids"] == list(range(7, 16))
    board = parse_board("aprilgrid:3x3,tag=60mm,spacing=0.3,first=7")
    at = {tuple(i): c for i, c in zip(ids.tolist(), corners)}
    for k, quad in zip(lab["tags"]["ids"], np.asarray(lab["tags"]["corners"])):  # a tag's corners are grid corners
        assert np.allclose([at[tuple(i)] for i in board.tag_corner_ids(k).tolist()], quad)
    assert s.image.shape == (240, 320)


def test_a_kalibr_checkerboard_is_not_a_marker_board(tmp_path):
    f = tmp_path / "checker.yaml"
    f.write_text("target_type: checkerboard\ntargetCols: 7\ntargetRows: 5\nrowSpacingMeters: 0.03\ncolSpacingMeters: 0.03\n")
    with pytest.raises(ValueError, match="--pattern 7x5"):
        parse_marker_board(str(f))
    assert parse_marker_board("aprilgrid:6x6,tag=88mm,spacing=0.3") == BOARD


def test_a_video_frame_of_a_grid_reads_back_with_its_labelled_ids(tmp_path):
    from aicalib_tf.detect.boards.aprilgrid import detect_aprilgrid
    from data_gen.video import VideoConfig, make_scene, render_frame

    grid = "aprilgrid:4x3,tag=40mm,spacing=0.3"
    cfg = VideoConfig(out=str(tmp_path), seconds=2.0, fps=2.0, size=(480, 360), board=grid, noise=0.0, shutter=0.0)
    assert cfg.pattern == parse_board(grid).pattern_size and cfg.square == pytest.approx(4.0)
    scene = make_scene(cfg)
    for index in range(4):
        img, lab = render_frame(scene, index)
        det = detect_aprilgrid(img, parse_board(grid))
        if len(det.ids):
            break
    assert len(det.ids) >= 8, "no frame of the video showed the grid"
    at = {tuple(i): c for i, c in zip(lab["ids"], lab["corners"])}
    err = [np.hypot(*np.subtract(c, at[tuple(i)])) for c, i in zip(det.corners, det.ids.tolist())]
    assert lab["board"] == grid and len(lab["ids"]) == 48 and max(err) < 0.05, (index, max(err))
