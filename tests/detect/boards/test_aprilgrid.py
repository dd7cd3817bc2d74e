"""AprilGrid detection on rendered views with exact truth: ids, the saddle fit against OpenCV's
refined corners, partial views, and a calibration from rendered views."""

import cv2
import numpy as np
import pytest

from aicalib_tf.detect.boards.aprilgrid import detect_aprilgrid, make_detector
from aicalib_tf.geometry.aprilgrid import PRINT_ROTATION, layout_image, parse_board, render_view

BOARD = parse_board("aprilgrid:6x6,tag=88mm,spacing=0.3")
K = np.array([[900.0, 0, 639.5], [0, 900.0, 479.5], [0, 0, 1]])
SIZE = (1280, 960)
Q = 8
MARGIN = BOARD.fraction[0] * Q + 8


@pytest.fixture(scope="module")
def layout():
    return layout_image(BOARD, Q, MARGIN)


def pose(rvec, centre_px, z):
    """(rvec, tvec) in lattice units: the grid's centre seen at ``centre_px`` from distance z."""
    R, _ = cv2.Rodrigues(np.asarray(rvec, np.float64))
    L = (np.array(BOARD.pattern_size) - 1) / 2.0
    return np.asarray(rvec, np.float64), z * np.linalg.solve(K, [*centre_px, 1.0]) - R @ np.array([L[0], L[1], 0.0])


def render(layout, rvec, tvec, seed=0, noise=2 / 255):
    R, _ = cv2.Rodrigues(rvec)
    img = render_view(layout, Q, MARGIN, K @ np.column_stack([R[:, 0], R[:, 1], tvec]), SIZE, 4)
    img = cv2.GaussianBlur(img, (0, 0), 0.7) + np.random.default_rng(seed).normal(0, noise, img.shape).astype(np.float32)
    return np.clip(np.rint(img * 255), 0, 255).astype(np.uint8)


def truth(ids, rvec, tvec):
    return cv2.projectPoints(BOARD.object_points(ids) / BOARD.square_size, rvec, tvec, K, None)[0].reshape(-1, 2)


def test_full_view_every_corner_with_its_id_and_better_than_opencv(layout):
    rvec, tvec = pose([0.35, -0.25, 0.1], (640, 480), 110)
    img = render(layout, rvec, tvec)
    ours = detect_aprilgrid(img, BOARD)
    assert len(ours.ids) == 144 and ours.rotation == PRINT_ROTATION and ours.why == ""
    assert sorted(map(tuple, ours.ids.tolist())) == sorted(map(tuple, BOARD.corner_ids().tolist()))
    err = np.linalg.norm(ours.corners - truth(ours.ids, rvec, tvec), axis=1)
    assert np.median(err) < 0.03 and err.max() < 0.15
    cv = detect_aprilgrid(img, BOARD, refine="opencv")
    cv_err = np.linalg.norm(cv.corners - truth(cv.ids, rvec, tvec), axis=1)
    assert np.median(err) <= 0.5 * np.median(cv_err)


def test_partial_view_keeps_the_true_ids(layout):
    rvec, tvec = pose([-0.3, 0.4, -0.2], (1230, 420), 100)  # the grid's centre near the right edge
    img = render(layout, rvec, tvec, seed=1)
    det = detect_aprilgrid(img, BOARD)
    assert 0 < len(det.ids) < 144 and 0 < len(det.tags) < 36
    err = np.linalg.norm(det.corners - truth(det.ids, rvec, tvec), axis=1)
    assert err.max() < 0.15  # a wrong id would put its truth a lattice step away
    whole = [k for k in BOARD.tag_ids() if (truth(BOARD.tag_corner_ids(k), rvec, tvec)[:, 0] < SIZE[0] - 4).all()]
    assert 0 < len(whole) < 36 and len(det.ids) >= 0.95 * 4 * len(whole)  # the corners of the tags seen whole


def test_a_grid_of_other_ids_is_not_found(layout):
    rvec, tvec = pose([0.2, 0.1, 0.0], (640, 480), 120)
    img = render(layout, rvec, tvec)
    other = parse_board("aprilgrid:6x6,tag=88mm,spacing=0.3,first=100")
    det = detect_aprilgrid(img, other)
    assert len(det.ids) == 0 and "first=" in det.why
    d = make_detector(other)
    assert d(img) is None and "family" in d.why


def test_calibration_from_eight_rendered_views_recovers_fx(layout):
    from aicalib_tf.calib.fit import View, calibrate_camera

    rng = np.random.default_rng(3)
    detect = make_detector(BOARD)
    views = []
    for v in range(8):
        rvec, tvec = pose(np.r_[rng.uniform(-0.6, 0.6, 2), rng.uniform(-0.4, 0.4)],
                          (rng.uniform(450, 830), rng.uniform(330, 630)) if v % 4 else (1150, 480), rng.uniform(100, 140))
        corners, ids = detect(render(layout, rvec, tvec, seed=v))
        views.append(View(f"v{v}", corners, ids))
    cal = calibrate_camera(views, BOARD.pattern_size, BOARD.square_size, SIZE, model="plumb_bob", square_unit="mm")
    assert abs(cal.K[0, 0] / 900.0 - 1) < 0.01 and abs(cal.K[1, 1] / 900.0 - 1) < 0.01
    assert cal.rms < 0.05


def test_the_printed_page_reads_back_with_every_corner():
    from aicalib_tf.board import page_image

    board = parse_board("aprilgrid:6x6,tag=20mm,spacing=0.3")
    page = cv2.GaussianBlur(page_image(board, "A4", 150), (0, 0), 0.8)
    det = detect_aprilgrid(page, board)
    assert len(det.ids) == 144 and det.rotation == PRINT_ROTATION
    # the corners are evenly spaced lattice points: an affine map from ids fits them to a pixel's fraction
    A = np.c_[det.ids, np.ones(len(det.ids))]
    fit, *_ = np.linalg.lstsq(A, det.corners, rcond=None)
    assert np.abs(A @ fit - det.corners).max() < 0.3
    px_per_mm = 150 / 25.4
    assert fit[0, 0] == pytest.approx(round(board.square_size * px_per_mm), rel=1e-3)  # the bitmap: whole px a unit


def test_tags_printed_another_way_round_keep_their_ids(monkeypatch):
    import aicalib_tf.geometry.aprilgrid as geometry

    monkeypatch.setattr(geometry, "PRINT_ROTATION", 1)  # every tag's code turned a quarter
    turned = layout_image(BOARD, Q, MARGIN)
    monkeypatch.undo()
    rvec, tvec = pose([0.2, -0.3, 0.4], (640, 480), 120)
    det = detect_aprilgrid(render(turned, rvec, tvec), BOARD)
    assert det.rotation == 1 and len(det.ids) == 144
    assert np.linalg.norm(det.corners - truth(det.ids, rvec, tvec), axis=1).max() < 0.15


def test_a_steeply_sheared_corner_is_placed_from_its_placed_neighbours(monkeypatch):
    """The grid's outer corner seen steeply sheared (a crop of a benchmark view, data_gen's exact
    renderer): OpenCV's quad corner lies 5 px out along the diagonal, beyond the first fit's reach;
    the second pass starts where the placed corners of the tag and its neighbours put it."""
    import aicalib_tf.detect.boards.aprilgrid as aprilgrid
    from aicalib_tf.geometry.camera import Camera
    from aicalib_tf.geometry.pose import project_points
    from data_gen.aprilgrid import AprilGridTarget
    from data_gen.render import render_board

    cam = Camera(np.array([[900.0, 0, -260.5], [0, 900.0, 89.5], [0, 0, 1]]), np.zeros(5), (240, 200))
    rvec, tvec = np.array([-0.6546, -0.673, 0.0665]), np.array([345.52, -70.14, 1029.47])  # mm
    target = AprilGridTarget(BOARD, margin=0.25, black=0.0, white=1.0)
    img = render_board(cam, target, rvec, tvec, np.full((200, 240), 0.5, np.float32))
    img = cv2.GaussianBlur(img, (0, 0), 0.7) + np.random.default_rng(0).normal(0, 2 / 255, img.shape).astype(np.float32)
    img = np.clip(np.rint(img * 255), 0, 255).astype(np.uint8)
    det = detect_aprilgrid(img, BOARD)
    assert (0, 0) in set(map(tuple, det.ids.tolist()))
    err = np.linalg.norm(det.corners - project_points(BOARD.object_points(det.ids), rvec, tvec, cam), axis=1)
    assert err.max() < 0.1
    monkeypatch.setattr(aprilgrid, "_from_neighbours", lambda smoothed, cells, lattice, pts, ok, spacing: (pts, ok))
    first = detect_aprilgrid(img, BOARD)
    assert (0, 0) not in set(map(tuple, first.ids.tolist())) and len(first.ids) == len(det.ids) - 1


def test_tags_opencv_missed_are_read_square_on_from_their_neighbours(layout, monkeypatch):
    """Tags left out of OpenCV's decoding are seen square-on through their neighbours' homography and
    decoded there; a tag whose code cannot be read (its bits painted out) gives no corner."""
    import aicalib_tf.detect.boards.aprilgrid as aprilgrid

    dropped, blank = [14, 21, 22], 8
    page = layout.copy()
    cell = Q * BOARD.fraction[1] // (BOARD.bits + 4)  # px a bit cell on the page
    x0, y0 = BOARD.tag_corner_ids(blank).min(axis=0) * Q + MARGIN
    page[y0 + 2 * cell: y0 + (BOARD.bits + 2) * cell, x0 + 2 * cell: x0 + (BOARD.bits + 2) * cell] = 255
    rvec, tvec = pose([0.35, -0.25, 0.1], (640, 480), 110)
    img = render(page, rvec, tvec)
    decode = aprilgrid.decode_tags

    def missing(gray, board, refine="none"):
        ids, quads = decode(gray, board, refine)
        keep = ~np.isin(ids, dropped)
        return ids[keep], quads[keep]

    monkeypatch.setattr(aprilgrid, "decode_tags", missing)
    det = detect_aprilgrid(img, BOARD)
    assert set(dropped) <= set(det.tags.tolist()) and blank not in det.tags
    found = set(map(tuple, det.ids.tolist()))
    assert all(tuple(i) in found for t in dropped for i in BOARD.tag_corner_ids(t).tolist())
    assert len(det.ids) == 4 * 35 and not any(tuple(i) in found for i in BOARD.tag_corner_ids(blank).tolist())
    assert np.linalg.norm(det.corners - truth(det.ids, rvec, tvec), axis=1).max() < 0.15
