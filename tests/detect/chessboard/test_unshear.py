"""The second look at steeply tilted boards (aicalib_tf.detect.chessboard.unshear and its use in detect_corners)."""

import cv2
import numpy as np
import pytest

from aicalib_tf.detect.chessboard.unshear import (STEP, from_warp, is_sheared, lattice_map, quad_map, refine_rectified,
                                                  texture_quads, warp)


def _sliver_lattice(shape=(9, 6), origin=(100.0, 300.0)):
    """A steep-tilt-like lattice: ids (K, 2) and points (K, 2) px, steps 20 and 15 px meeting at 10°."""
    c, r = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]))
    ids = np.stack([c.ravel(), r.ravel()], 1)
    u = 20.0 * np.array([np.cos(np.radians(-5)), np.sin(np.radians(-5))])
    v = 15.0 * np.array([np.cos(np.radians(5)), np.sin(np.radians(5))])
    return ids, np.asarray(origin) + ids[:, :1] * u + ids[:, 1:] * v, u, v


@pytest.mark.parametrize("interpolation, tol", [(cv2.INTER_LINEAR, 2e-3), (cv2.INTER_CUBIC, 0.06)])
def test_from_warp_maps_warped_pixel_centres_back_to_the_image(monkeypatch, interpolation, tol):
    # on a linear ramp bilinear sampling is exact, so each warped pixel's value is the image x (or y)
    # of the place it came from: the pixel-centre convention needs no half-pixel term (OpenCV's bicubic
    # weights are tabulated at 1/32 px: exact to that)
    from aicalib_tf.detect.chessboard import unshear

    monkeypatch.setattr(unshear, "INTERPOLATION", interpolation)
    h, w = 120, 160
    ramp_x = np.tile(np.arange(w, dtype=np.float32), (h, 1))
    ramp_y = np.tile(np.arange(h, dtype=np.float32)[:, None], (1, w))
    affine = np.array([[2.0, 0.7, -30.0], [-0.4, 3.0, -50.0], [0.0, 0.0, 1.0]])
    persp = affine @ np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [4e-4, 1e-3, 1.0]])
    for m in (affine, persp):
        wx, wy = warp(ramp_x, m, (200, 150)), warp(ramp_y, m, (200, 150))
        ys, xs = np.mgrid[0:150:7, 0:200:7]
        back = from_warp(np.stack([xs.ravel(), ys.ravel()], 1), m)
        inside = np.all((back > 1) & (back < [w - 2, h - 2]), axis=1)
        assert inside.sum() > 50
        assert np.abs(back[inside, 0] - wx[ys, xs].ravel()[inside]).max() < tol
        assert np.abs(back[inside, 1] - wy[ys, xs].ravel()[inside]).max() < tol


def test_a_sharp_or_uneven_lattice_is_sheared_and_warped_square_with_its_handedness():
    ids, pts, u, v = _sliver_lattice()
    assert is_sheared(u, v) and is_sheared(np.array([20.0, 0]), np.array([0, 5.0]))
    assert not is_sheared(np.array([20.0, 0]), np.array([3.0, 15.0]))  # 79°, steps 20 and 15
    for mirror in (False, True):
        p = pts * [1, -1] + [0, 600] if mirror else pts  # a lattice mirrored on the image
        m, size = lattice_map(ids, p, (9, 6))
        q = from_warp(np.zeros((0, 2)), m)
        assert q.shape == (0, 2)
        warped = cv2.perspectiveTransform(p.reshape(-1, 1, 2), m).reshape(-1, 2)
        g = warped.reshape(6, 9, 2)
        np.testing.assert_allclose(np.diff(g, axis=1), np.broadcast_to([STEP, 0], (6, 8, 2)), atol=1e-4)
        np.testing.assert_allclose(np.abs(np.diff(g, axis=0)), np.broadcast_to([0, STEP], (5, 9, 2)), atol=1e-4)
        assert np.linalg.det(m[:2, :2]) > 0  # no mirror: the board's handedness is kept
        assert np.all((warped > 0) & (warped < size))


def test_an_outline_maps_onto_a_square_in_the_same_sense():
    quad = np.array([[100.0, 300.0], [220.0, 270.0], [400.0, 250.0], [280.0, 282.0]])
    for q in (quad, quad[::-1]):
        m, size = quad_map(q, side=100.0)
        assert np.linalg.det(m[:2, :2]) > 0 and size[0] == size[1] > 100


def _sliver_board(h=480, w=640):
    """A 9×6 board of 20 px squares (one more row and column of squares around the inner corners, a
    white margin of one square) drawn through a sharp affine map, squares becoming slivers meeting at
    10°, averaged over 4×4 samples a pixel: the image (h, w) float32 and the board's centre there (2,) px."""
    _, _, u, v = _sliver_lattice()
    a = np.array([[u[0] / 20, v[0] / 20, 150.0], [u[1] / 20, v[1] / 20, 200.0]])  # board px -> image px
    inv = cv2.invertAffineTransform(a)
    sub = (np.arange(4) + 0.5) / 4 - 0.5
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    image = np.zeros((h, w), np.float32)
    for dy in sub:
        for dx in sub:
            bx = inv[0, 0] * (xs + dx) + inv[0, 1] * (ys + dy) + inv[0, 2]  # board px; square (c, r) spans
            by = inv[1, 0] * (xs + dx) + inv[1, 1] * (ys + dy) + inv[1, 2]  # [20 + 20c, 40 + 20c) - 0.5
            c, r = np.floor((bx + 0.5 - 20) / 20), np.floor((by + 0.5 - 20) / 20)
            on = (bx > -0.5) & (bx < 239.5) & (by > -0.5) & (by < 179.5)
            inside = (c >= 0) & (c < 10) & (r >= 0) & (r < 7)
            image += np.where(on, np.where(inside & ((c + r) % 2 == 0), 0.1, 0.9), 0.5) / 16
    return image, a[:, :2] @ [119.5, 89.5] + a[:, 2]


def test_texture_slivers_are_found_and_frontal_textures_are_not():
    image, centre = _sliver_board()
    quads = texture_quads(image)
    assert len(quads) == 1
    assert np.linalg.norm(quads[0].mean(axis=0) - centre) < 15
    frontal = np.full((480, 640), 0.5, np.float32)
    frontal[100:300, 100:400] = np.kron((np.indices((10, 15)).sum(0) % 2), np.ones((20, 20))) * 0.8 + 0.1
    assert texture_quads(frontal) == []
    rng = np.random.default_rng(3)
    assert texture_quads(cv2.GaussianBlur(rng.random((480, 640), dtype=np.float32), (0, 0), 2.0)) == []
    for shape in ((1600, 1), (1, 1600), (8, 8), (2000, 12)):  # strips too narrow for a board
        assert texture_quads(rng.random(shape, dtype=np.float32)) == []


def test_a_sliver_beside_a_much_brighter_texture_is_found_with_that_texture_left_out(monkeypatch):
    from aicalib_tf.detect.chessboard import unshear

    image, centre = _sliver_board()
    image[20:100, 20:180] = np.kron(np.indices((8, 16)).sum(0) % 2, np.ones((10, 10))) * 2.0 - 0.5  # bold, frontal
    quads = texture_quads(image)
    assert len(quads) == 1 and np.linalg.norm(quads[0].mean(axis=0) - centre) < 15
    monkeypatch.setattr(unshear, "ENERGY_PASSES", 1)
    assert texture_quads(image) == []  # under either share of the bold texture's energy the sliver falls apart


def test_the_thinnest_square_of_a_grid_and_a_partial_board_predicting_thin_squares_gets_a_look():
    from aicalib_tf.detect.chessboard.unshear import MIN_THICKNESS, candidate_maps, thinnest_square

    ids = np.stack(np.meshgrid(np.arange(9), np.arange(6)), -1).reshape(-1, 2)
    assert thinnest_square(ids, ids * [20.0, 5.0]) == pytest.approx(5.0)
    assert thinnest_square(ids, ids * [20.0, 5.0] @ np.array([[1.0, 0.3], [0.0, 1.0]])) == pytest.approx(100 / np.hypot(20, 6))
    # a board tilted about its x axis: rows 9.6, 6.4, 4.6, 3.4, 2.7 px apart as they recede
    lat = np.array([[24.0, 0.0, 0.0], [0.0, 12.0, 0.0], [0.0, 0.25, 1.0]])
    pts = cv2.perspectiveTransform(ids.reshape(-1, 1, 2).astype(np.float64), lat).reshape(-1, 2) + [100, 300]
    near = ids[:, 1] <= 2  # the far rows were not found: their lattice predicts the next one 4.6 px thick
    assert thinnest_square(ids[near], pts[near]) < MIN_THICKNESS < thinnest_square(ids[near], 3 * pts[near])
    gray = np.zeros((480, 640), np.float32)
    assert len(candidate_maps(gray, (9, 6), ids[near], pts[near])) == 1
    assert candidate_maps(gray, (9, 6), ids, ids * [20.0, 20.0] + 100) == []  # square, fronto-parallel: none


def test_a_steep_boards_corners_are_refined_on_its_rectified_view():
    # tilt-steep #43 (seed 41): its lines meet at 8-14 deg; on the image the saddle fit fails at nearly
    # every corner, on the board's rectified view it brings corners 0.2 px off to within 0.1 px
    from aicalib_tf.bench.conditions import PATTERN, generalize_conditions
    from aicalib_tf.detect.pyramid import refine_full
    from data_gen import make_sample

    cond = {c.name: c for c in generalize_conditions()}["tilt-steep"]
    s = make_sample(cond.preset, cond.seed, 43, size=cond.size, pattern=PATTERN)
    gray, truth = s.image.astype(np.float32) / 255, np.asarray(s.corners, np.float64)
    start = truth + np.random.default_rng(5).uniform(-0.2, 0.2, truth.shape)
    refine = lambda g, p: refine_full(g, p, max_shift=1.0)  # noqa: E731
    assert refine(gray, start.astype(np.float32))[1].mean() < 0.1
    got = refine_rectified(gray, start, PATTERN, refine)
    assert np.median(np.linalg.norm(got - truth, axis=1)) < 0.08 < np.median(np.linalg.norm(start - truth, axis=1))


@pytest.mark.parametrize("index", [43, 59])  # no grid at all / a partial board of 50 corners at first
def test_a_steeply_tilted_board_is_found_by_its_second_look(monkeypatch, index):
    from aicalib_tf.bench.conditions import PATTERN, generalize_conditions
    from aicalib_tf.bench.metrics import board_detection_outcome
    from aicalib_tf.detect import pipeline
    from data_gen import make_sample

    cond = {c.name: c for c in generalize_conditions()}["tilt-steep"]
    s = make_sample(cond.preset, cond.seed, index, size=cond.size, pattern=PATTERN)
    det = pipeline.detect_corners(s.image, PATTERN)
    assert det.complete and board_detection_outcome(det.corners, s.corners, PATTERN)[0] == "hit"
    monkeypatch.setattr(pipeline, "_unsheared", lambda *a: a[-1])
    assert not pipeline.detect_corners(s.image, PATTERN).complete


def test_a_board_close_to_a_wide_lens_whose_far_squares_the_search_missed_is_found_on_its_lattices_view(monkeypatch):
    # a wide barrel lens (k1 -0.39), the board tilted 70° and close: its near squares 5 times its far ones, the
    # search finds 49 corners whose lattice predicts a next square 5.3 px thick (thicker than MIN_THICKNESS was)
    from dataclasses import replace

    from aicalib_tf.bench.conditions import PATTERN
    from aicalib_tf.bench.metrics import board_detection_outcome
    from aicalib_tf.detect import pipeline
    from data_gen import make_sample
    from aicalib_tf.detect.chessboard import unshear
    from data_gen.presets import Rule, get_preset

    steep = get_preset("tilt_steep")
    wide = replace(steep, lens=("pinhole", "fisheye"), hfov_deg=(80.0, 120.0), distortion=("strong",),
                   fisheye_fov_deg=(150.0, 175.0), fisheye_circular_from_deg=180.0,
                   rules=steep.rules + (Rule.of("depth_blur", focus=(0.0, 1.0), sigma_min=(0.4, 0.8), sigma_max=(1.5, 3.0)),))
    s = make_sample(wide, 301, 16, size=(640, 480), pattern=PATTERN)
    det = pipeline.detect_corners(s.image, PATTERN)
    assert det.complete and board_detection_outcome(det.corners, s.corners, PATTERN)[0] == "hit"
    monkeypatch.setattr(unshear, "MIN_THICKNESS", 5.0)
    assert not pipeline.detect_corners(s.image, PATTERN).complete


def test_a_small_board_seen_nearly_edge_on_is_found_whole_by_its_texture_sliver(monkeypatch):
    # tilted 69°, seen nearly edge-on, its squares 2 px thick: the far end's texture is faint, and under a quarter of
    # the largest energy the sliver was its near half only, whose outline warps the board still sheared
    from dataclasses import replace

    from aicalib_tf.bench.conditions import PATTERN
    from aicalib_tf.bench.metrics import board_detection_outcome
    from aicalib_tf.detect import pipeline
    from aicalib_tf.detect.chessboard import unshear
    from data_gen import make_sample
    from data_gen.presets import get_preset

    steep = get_preset("tilt_steep")
    small = replace(steep, pose=replace(steep.pose, fill=(0.25, 0.45)))
    s = make_sample(small, 301, 26, size=(640, 480), pattern=PATTERN)
    det = pipeline.detect_corners(s.image, PATTERN)
    assert det.complete and board_detection_outcome(det.corners, s.corners, PATTERN)[0] == "hit"
    monkeypatch.setattr(unshear, "ENERGY_SHARES", (0.25,))
    assert not pipeline.detect_corners(s.image, PATTERN).complete


def test_only_a_board_thin_but_not_sheared_is_held_to_the_object_test():
    from aicalib_tf.detect.chessboard.unshear import thin_not_sheared

    ids = np.stack(np.meshgrid(np.arange(4), np.arange(3)), -1).reshape(-1, 2)
    square = 10.0 + 20.0 * ids.astype(np.float64)  # a close-up's lattice: square steps
    sheared = 10.0 + ids @ np.array([[20.0, 0.0], [18.0, 4.0]])  # axes meeting at about 13°: a steep board
    assert thin_not_sheared(ids, square)
    assert not thin_not_sheared(ids, sheared)
    assert not thin_not_sheared(None, None) and not thin_not_sheared(ids[:4], square[:4])  # no lattice to judge
