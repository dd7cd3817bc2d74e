"""ChArUco detection: rendered boards with exact truth, every returned id right (0 wrong ids)."""

from dataclasses import replace

import cv2
import numpy as np
import pytest

from aicalib_tf.cnn.model import load_model
from aicalib_tf.detect.pipeline import detect_charuco, detect_corners
from aicalib_tf.geometry.charuco import parse_board
from data_gen.pose import PoseConfig
from data_gen.presets import get_preset
from data_gen.sample import make_sample

B = "charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100"
B4 = "charuco:7x5,square=30mm,marker=22mm,dict=DICT_4X4_50"


@pytest.fixture(scope="module")
def model():
    return load_model("default")


def _check(det, sample, tol=1.0):
    """Every corner within tol px of its id's true corner; returns the share of visible corners named."""
    err = np.linalg.norm(det.corners - sample.corners[det.charuco_ids], axis=1)
    assert err.max() < tol, f"{int((err >= tol).sum())} corners off their ids"
    assert sample.visible[det.charuco_ids].all()
    return len(det.corners) / sample.visible.sum()


@pytest.mark.parametrize("index", [1, 2, 4])
def test_clean_boards_found_with_exact_ids(model, index):
    s = make_sample(get_preset("clean", board=B), 5, index, size=(800, 600))
    found = detect_charuco(s.image, [B], model=model)
    assert len(found) == 1 and not found[0].duplicate
    assert _check(found[0], s, tol=0.3) >= 0.95
    assert len(found[0].marker_ids) >= 30


def test_detect_corners_dispatches_on_a_board(model):
    s = make_sample(get_preset("clean", board=B), 5, 2, size=(800, 600))
    det = detect_corners(s.image, parse_board(B), model=model)
    assert det.found and det.pattern_size == (10, 7)
    assert np.abs(det.corners - s.corners[det.ids[:, 1] * 10 + det.ids[:, 0]]).max() < 0.3


def test_partial_board_gets_the_right_ids(model):
    p = replace(get_preset("partial", board=B), pose=PoseConfig(tilt_max_deg=30.0, fill=(0.7, 1.0), framing="partial"))
    for i in range(2):
        s = make_sample(p, 41, i, size=(640, 480))
        assert not s.visible.all()
        found = detect_charuco(s.image, [B], model=model)
        assert found and _check(found[0], s) >= 0.9


def test_an_unreadable_marker_leaves_the_corners_other_markers_decide(model):
    s = make_sample(get_preset("clean", board=B), 5, 2, size=(800, 600))
    img = s.image.copy()
    quad = np.asarray(s.label["markers"]["corners"][17])  # a marker in the middle: square (3, 3)
    cv2.fillConvexPoly(img, np.round(quad).astype(np.int32), 200)  # hide its bits (not the square's corners)
    found = detect_charuco(img, [B], model=model)
    assert found and 17 not in found[0].marker_ids.tolist()
    assert _check(found[0], s, tol=0.3) >= 0.95
    i, j = parse_board(B).marker_square_of()[17]
    around = {(i - 1, j - 1), (i, j - 1), (i, j), (i - 1, j)}  # its square's corners, decided by the neighbours
    assert around <= set(map(tuple, found[0].ids.tolist()))


def test_two_boards_told_apart_and_same_ids_reported(model):
    a = make_sample(get_preset("clean", board=B4), 3, 1, size=(480, 480)).image
    b = make_sample(get_preset("clean", board=B4.replace("DICT_4X4_50", "DICT_6X6_50")), 3, 2, size=(480, 480)).image
    two = detect_charuco(np.hstack([a, b]), [B4, B4.replace("DICT_4X4_50", "DICT_6X6_50")], model=model)
    assert sorted(d.board.dictionary for d in two) == ["DICT_4X4_50", "DICT_6X6_50"]
    assert not any(d.duplicate for d in two) and all(d.corners[:, 0].min() >= 480 or d.corners[:, 0].max() < 480 for d in two)
    same = detect_charuco(np.hstack([a, a]), [B4], model=model)
    assert len(same) == 2 and all(d.duplicate for d in same)


def test_no_board_no_corners(model):
    s = make_sample("clutter", 1, 0, size=(320, 240))
    assert detect_charuco(s.image, [B], model=model) == []


def test_detect_cli_takes_a_board(tmp_path, capsys):
    import json

    from aicalib_tf.detect.__main__ import main

    s = make_sample(get_preset("clean", board=B), 5, 2, size=(800, 600))
    cv2.imwrite(str(tmp_path / "a.png"), s.image)
    out = tmp_path / "out"
    assert main([str(tmp_path / "a.png"), "--board", B, "--out", str(out), "--workers", "1", "--quiet"]) == 0
    rec = json.loads((out / "a.json").read_text())
    assert rec["board"] == B and rec["pattern_size"] == [10, 7] and len(rec["ids"]) >= 66
    assert main([str(tmp_path / "a.png"), "--board", "charuco:11x8,square=3,marker=4,dict=DICT_5X5_100",
                 "--out", str(tmp_path / "o2")]) == 2
    assert "smaller than square" in capsys.readouterr().err


def _posed(tilt_deg, axis, fill, size=(640, 480)):
    """(image, true corners (70, 2) px, visible (70,)) of the board B at a chosen pose: centred, turned
    by tilt_deg about ``axis`` (board frame), its squares' width ``fill`` of the image's."""
    from data_gen.pose import corner_visibility
    from data_gen.sample import draw_scene

    sc = draw_scene(get_preset("clean", board=B), 5, 2, size=size)
    cam, board = sc.camera, sc.board
    a = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    R, _ = cv2.Rodrigues(a * np.radians(tilt_deg))
    z = cam.K[0, 0] * board.square_size * 11 / (fill * size[0])
    t = -R @ board.centre() + np.array([0.0, 0.0, z])
    rvec = cv2.Rodrigues(R)[0].ravel()
    corners, visible = corner_visibility(board, rvec, t, cam)
    return sc.render(rvec, t), corners, visible


def test_a_steep_oblique_view_is_named_whole(model):
    # turned 70° about a diagonal: the squares are sheared and the white margins thin; few grids
    # of corners form, and a marker's own outline predicts its square's corners too coarsely
    img, corners, visible = _posed(70.0, (1.0, 1.0, 0.0), 0.5)
    found = detect_charuco(img, [B], model=model)
    assert found and visible.all()
    err = np.linalg.norm(found[0].corners - corners[found[0].charuco_ids], axis=1)
    assert err.max() < 0.5 and np.median(err) < 0.05
    assert len(found[0].corners) >= 0.95 * visible.sum()


@pytest.mark.parametrize("side", ["left", "bottom"])
def test_corners_at_the_frame_edge_are_named(model, side):
    # the frame cuts the board within a pixel of a corner: the fit's window leaves the image there
    img, corners, _ = _posed(20.0, (0.0, 1.0, 0.0), 0.75)
    if side == "left":
        k = 30  # (0, 3)
        x0 = int(np.floor(corners[k, 0] - 0.4))
        img, corners = img[:, x0:], corners - [x0, 0]
    else:
        k = 63  # (3, 6)
        y1 = int(np.ceil(corners[k, 1] + 0.4)) + 1
        img = img[:y1]
    h, w = img.shape[:2]
    visible = (corners[:, 0] >= 0) & (corners[:, 0] <= w - 1) & (corners[:, 1] >= 0) & (corners[:, 1] <= h - 1)
    found = detect_charuco(np.ascontiguousarray(img), [B], model=model)
    assert found and visible[k]
    d = found[0]
    err = np.linalg.norm(d.corners - corners[d.charuco_ids], axis=1)
    assert visible[d.charuco_ids].all() and err.max() < 0.5
    assert k in d.charuco_ids.tolist()
    assert len(d.corners) >= 0.98 * visible.sum()


def test_no_corner_named_under_an_object_in_front(model):
    # the lattice predicts corners under an object too; the image shows none there
    p = get_preset("occluded", board=B)
    for seed, i in [(7, 0), (7, 1), (7, 2), (42, 1)]:  # (42, 1): a corner 2 px behind an object's edge
        s = make_sample(p, seed, i, size=(640, 480))
        found = detect_charuco(s.image, [B], model=model)
        assert found and _check(found[0], s) >= 0.9  # _check: every corner named is visible and right


def test_noise_sigma_reads_the_noise_not_the_edges():
    from aicalib_tf.detect.charuco.markers import noise_sigma

    img = np.zeros((240, 320), np.float64)
    img[:, 160:] = 200.0  # a strong edge
    img += np.linspace(0, 40, 320)[None]  # and a ramp
    rng = np.random.default_rng(0)
    assert noise_sigma(np.clip(img, 0, 255).astype(np.uint8)) < 1.0
    noisy = np.clip(img + rng.normal(0, 10, img.shape), 0, 255).astype(np.uint8)
    assert abs(noise_sigma(noisy) - 10.0) < 1.0


def test_outside_markers_matches_opencvs_polygon_test():
    from aicalib_tf.detect.charuco.grid import MARKER_GROW, outside_markers

    rng = np.random.default_rng(1)
    quads = rng.uniform(0, 100, (6, 1, 2)) + np.array([[-8, -8], [8, -7], [7, 8], [-7, 7]]) * rng.uniform(0.5, 2, (6, 1, 1))
    pts = rng.uniform(-10, 110, (2000, 2))
    expect = np.ones(len(pts), bool)
    for q in quads:
        c = q.mean(axis=0)
        poly = (c + MARKER_GROW * (q - c)).astype(np.float32).reshape(-1, 1, 2)
        expect &= np.array([cv2.pointPolygonTest(poly, (float(x), float(y)), False) < 0 for x, y in pts])
    assert (outside_markers(pts, quads) == expect).all() and (~expect).sum() > 50
    assert outside_markers(pts, np.zeros((0, 4, 2))).all()


def test_refine_in_squares_finds_the_centre_of_a_sheared_corner():
    from aicalib_tf.detect.charuco.grow import asymmetry, refine_in_squares

    # a corner at exactly (24.5, 24.5), its squares sheared: the board's x axis along (10, 0) px,
    # its y axis along (6, 8) px; blurred
    yy, xx = np.mgrid[0:50, 0:50].astype(np.float64)
    u, v = np.linalg.solve(np.array([[10.0, 6.0], [0.0, 8.0]]), np.stack([xx.ravel() - 24.5, yy.ravel() - 24.5]))
    img = cv2.GaussianBlur(((u > 0) == (v > 0)).reshape(50, 50).astype(np.float32), (0, 0), 0.8)
    steps = np.array([[[10.0, 6.0], [0.0, 8.0]]] * 3)
    steps[2, 0, 0] = np.nan  # no lattice there
    got, ok = refine_in_squares(img, np.array([[25.0, 24.1], [24.2, 24.9], [24.0, 24.0]]), steps, 0.15)
    assert ok.tolist() == [True, True, False]
    assert np.abs(got[:2] - 24.5).max() < 0.01 and (got[2] == 24.0).all()
    assert asymmetry(img, np.array([[24.5, 24.5]]), steps[:1], 0.15)[0] < 0.01
    assert asymmetry(img, np.array([[27.5, 24.5]]), steps[:1], 0.15)[0] > 0.5  # on an edge, not a corner
