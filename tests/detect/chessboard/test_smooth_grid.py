"""The interpolation test: a full board's corners off the smooth grid of their neighbours."""

from dataclasses import replace

import cv2
import numpy as np
import pytest

from aicalib_tf.detect.chessboard.smooth_grid import STENCILS, cubic_weights, off_grid, smallest_steps, without_off_grid
from aicalib_tf.detect.detection import Detection

COLS, ROWS = 9, 6


def _fisheye_board(rng: np.random.Generator) -> np.ndarray:
    """(ROWS, COLS, 2) px: a board's corners through an equidistant fisheye (f 150 px), towards its rim
    (up to 82° off-axis, squares of up to 10° of field)."""
    square = rng.uniform(20.0, 40.0)
    x, y = np.meshgrid((np.arange(COLS) - 4.0) * square, (np.arange(ROWS) - 2.5) * square)
    board = np.stack([x, y, np.zeros_like(x)], -1)
    tilt, spin = np.deg2rad(rng.uniform(0, 50)), rng.uniform(0, 2 * np.pi)
    axis = np.array([np.cos(spin), np.sin(spin), 0.0])
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    rot = np.eye(3) + np.sin(tilt) * k + (1 - np.cos(tilt)) * k @ k
    off_axis, towards = np.deg2rad(rng.uniform(0, 60)), rng.uniform(0, 2 * np.pi)
    centre = rng.uniform(250, 500) * np.array([np.sin(off_axis) * np.cos(towards), np.sin(off_axis) * np.sin(towards),
                                               np.cos(off_axis)])
    p = board @ rot.T + centre
    theta = np.arctan2(np.hypot(p[..., 0], p[..., 1]), p[..., 2])
    phi = np.arctan2(p[..., 1], p[..., 0])
    return np.stack([320 + 150 * theta * np.cos(phi), 240 + 150 * theta * np.sin(phi)], -1)


def test_the_stencils_interpolate_a_cubic():
    for offs, wts in STENCILS:
        np.testing.assert_allclose(cubic_weights(offs), wts, atol=1e-12)
        for power in range(4):
            assert abs(sum(w * o ** power for o, w in zip(offs, wts)) - (1.0 if power == 0 else 0.0)) < 1e-12


def test_bent_boards_keep_every_corner():
    rng = np.random.default_rng(3)
    for _ in range(40):
        pts = _fisheye_board(rng) + rng.normal(0, 0.1, (ROWS, COLS, 2))
        assert not off_grid(pts, np.full((ROWS, COLS), 0.1)).any()


def test_a_ring_corner_off_its_line_is_found():
    rng = np.random.default_rng(5)
    for _ in range(10):
        pts = _fisheye_board(rng) + rng.normal(0, 0.1, (ROWS, COLS, 2))
        moved = pts.copy()
        a = rng.uniform(0, 2 * np.pi)
        moved[0, 3] += 2.5 * np.array([np.cos(a), np.sin(a)])  # a point on an object's edge
        assert np.argwhere(off_grid(moved, np.full((ROWS, COLS), 0.1))).tolist() == [[0, 3]]


def test_two_neighbours_off_are_both_found():
    rng = np.random.default_rng(7)
    pts = _fisheye_board(rng) + rng.normal(0, 0.1, (ROWS, COLS, 2))
    pts[0, 4] += [3.0, 1.0]
    pts[0, 5] += [-1.5, 2.5]
    assert sorted(map(tuple, np.argwhere(off_grid(pts, np.full((ROWS, COLS), 0.1))).tolist())) == [(0, 4), (0, 5)]


def test_a_board_corner_beside_an_off_corner_goes_with_it():
    rng = np.random.default_rng(9)
    pts = _fisheye_board(rng) + rng.normal(0, 0.1, (ROWS, COLS, 2))
    pts[0, 7] += [2.0, -2.0]  # beside the board's corner (0, 8), which no interpolation tests
    assert sorted(map(tuple, np.argwhere(off_grid(pts, np.full((ROWS, COLS), 0.1))).tolist())) == [(0, 7), (0, 8)]


def test_three_corners_off_under_one_object_all_go():
    rng = np.random.default_rng(13)
    pts = _fisheye_board(rng) + rng.normal(0, 0.1, (ROWS, COLS, 2))
    for (r, c), shift in zip(((0, 1), (0, 2), (1, 1)), ([2.5, 2.0], [-3.0, 1.5], [3.0, -2.5])):
        pts[r, c] += shift
    flagged = set(map(tuple, np.argwhere(off_grid(pts, np.full((ROWS, COLS), 0.1))).tolist()))
    assert {(0, 1), (0, 2), (1, 1)} <= flagged and all(r <= 2 and c <= 3 for r, c in flagged)


def test_a_full_board_loses_its_off_corner():
    rng = np.random.default_rng(11)
    pts = _fisheye_board(rng).reshape(-1, 2).astype(np.float32)
    ids = np.array([(k % COLS, k // COLS) for k in range(COLS * ROWS)], np.int32)
    det = Detection(pts, ids, np.ones(len(pts), np.float32), (COLS, ROWS), True, (640, 480),
                    sigmas=np.full(len(pts), 0.1, np.float32))
    assert without_off_grid(det, "refused") is det
    moved = pts.copy()
    moved[2 * COLS] += [3.0, -2.0]  # corner (0, 2), on the outer ring
    got = without_off_grid(replace(det, corners=moved), "refused")
    assert not got.complete and len(got.corners) == COLS * ROWS - 1 and got.reason == ""
    assert [0, 2] not in got.ids.tolist() and len(got.sigmas) == len(got.ids)
    np.testing.assert_array_equal(got.corners, np.delete(moved, 2 * COLS, axis=0))
    for k in (2, 4 * COLS, 2 * COLS + COLS - 1, 5 * COLS + 4):  # more than MAX_OFF corners off: no board
        moved[k] += [-2.5, 2.5]
    refused = without_off_grid(replace(det, corners=moved), "refused")
    assert not refused.found and refused.reason == "refused"


# closeup-eq images with occluded_closeups.py's objects: (image, object's outline px, its grey level)
OBJECTS = {
    # a blob at the ring's corner (6, 0): a full board whose corner (6, 0) lies 3.7 px off, on the blob's edge
    "blob": (18, [[451.13, 245.1], [448.65, 245.49], [444.88, 247.56], [444.17, 247.6], [440.87, 243.58],
                  [441.14, 240.09], [444.53, 240.08], [446.27, 238.71], [448.89, 238.99], [448.68, 241.36]], 0.306),
    # a bar over (1, 0), (2, 0) and (1, 1), 3.2-5.5 px off: (1, 0) fits its only interpolation left
    "bar": (1, [[239.41, 75.81], [243.06, 80.56], [215.91, 101.44], [212.25, 96.69]], 0.83),
    # a blob over (0, 3) and (0, 4), which pulls the column beside them: (0, 3) 2.3-3.1 px off its column's
    # interpolations; their twins on column 1 miss by 0.08 of the step, on column 2 by 0.03
    "blob over two lines": (7, [[257.05, 281.1], [249.79, 282.77], [245.55, 281.6], [241.76, 277.56],
                                [237.38, 273.75], [242.94, 267.21], [249.63, 268.67], [253.37, 270.53]], 0.788),
}


@pytest.mark.parametrize("name", sorted(OBJECTS))
def test_an_object_over_a_close_ups_rim_makes_no_wrong_board(name):
    from aicalib_tf import detect_corners
    from aicalib_tf.bench.conditions import PATTERN, select_conditions
    from data_gen.sample import draw_scene

    index, outline, level = OBJECTS[name]
    cond = select_conditions("closeup-eq")[0]
    scene = draw_scene(cond.preset, cond.seed, index, size=cond.size, pattern=PATTERN)
    img = replace(scene, occluders=[np.array(outline)], occluder_levels=[level]).render()
    det = detect_corners(img, PATTERN)
    assert det.found or name == "blob over two lines"  # the rim completion refuses the corner placed under the
    # blob (faint_placed), and a grid of the other 53 corners cannot be placed on the pattern: a miss, not wrong
    truth = scene.corners[det.ids[:, 1] * PATTERN[0] + det.ids[:, 0]]
    assert np.hypot(*(det.corners - truth).T).max(initial=0.0) <= 2.0


def _close_fisheye_board(cols: int = 8, rows: int = 6) -> np.ndarray:
    """(rows, cols, 2) px: a 32.5 mm board 100 mm from a 185° equidistant fisheye (f 337 px), turned 60°
    and 20° off-axis: its steps run 27-120 px, as a real fisheye's close board's 39-150 px did."""
    x, y = np.meshgrid((np.arange(cols) - 3.5) * 32.5, (np.arange(rows) - 2.5) * 32.5)
    t, o = np.deg2rad(60.0), np.deg2rad(20.0)
    rot = np.array([[np.cos(t), 0, np.sin(t)], [0, 1, 0], [-np.sin(t), 0, np.cos(t)]])
    p = np.stack([x, y, np.zeros_like(x)], -1) @ rot.T + 100.0 * np.array([np.sin(o), 0, np.cos(o)])
    theta, phi = np.arctan2(np.hypot(p[..., 0], p[..., 1]), p[..., 2]), np.arctan2(p[..., 1], p[..., 0])
    return np.stack([516 + 337 * theta * np.cos(phi), 389 + 337 * theta * np.sin(phi)], -1)


def test_a_close_board_bent_all_over_keeps_its_corners_and_still_shows_one_off():
    pts = _close_fisheye_board()
    sig = np.full(pts.shape[:2], 0.05)
    assert not off_grid(pts, sig).any()  # with the least share alone (0.01 of a step) 3 of its corners went
    steps = smallest_steps(pts).reshape(pts.shape[:2])
    for r, c in [(0, 3), (2, 4), (5, 2), (3, 0)]:  # 4 px or 0.15 of its step off, on every part of it
        q = pts.copy()
        q[r, c, 1] += max(4.0, 0.15 * steps[r, c])
        assert np.argwhere(off_grid(q, sig)).tolist() == [[r, c]]


def _rim_row_board() -> np.ndarray:
    """(6, 9, 2) px: a 25 mm board through a 203° Kannala-Brandt fisheye (f 125 px), its last row 83-86° off
    axis (closeup_families' cover-70-90, seed 301 #2): that row's steps run 19-50 px, and its interpolations miss
    by up to 0.1 of the step, about twice the row inside it and four times the board's median."""
    x, y = np.meshgrid(np.arange(9) * 25.0, np.arange(6) * 25.0)
    rot = cv2.Rodrigues(np.array([-0.7324, -0.9525, 1.7009]))[0]
    p = np.stack([x, y, np.zeros_like(x)], -1) @ rot.T + [44.44, -94.35, 145.0]
    theta, phi = np.arctan2(np.hypot(p[..., 0], p[..., 1]), p[..., 2]), np.arctan2(p[..., 1], p[..., 0])
    theta = theta * (1 + 0.03287 * theta ** 2 + 0.00386 * theta ** 4 - 0.00128 * theta ** 6 - 0.000897 * theta ** 8)
    return np.stack([319.54 + 125.15 * theta * np.cos(phi), 237.45 + 125.09 * theta * np.sin(phi)], -1)


def test_a_rim_row_bent_twice_as_much_as_the_row_inside_keeps_its_corners():
    pts, sig = _rim_row_board(), np.full((6, 9), 0.1)
    moved = pts.copy()
    moved[5, 7, 1] -= 0.7  # the detector's bias on that row, 0.2-0.3 px a corner, adds up to this on one interpolation
    assert not off_grid(moved, sig).any()  # judged by the board's median bend alone, (5, 6)-(5, 8) went
    for r, c in [(1, 2), (3, 6), (0, 4)]:  # 2.5 px off where the rows bend less is still found
        q = pts.copy()
        q[r, c] += [1.5, -2.0]
        assert np.argwhere(off_grid(q, sig)).tolist() == [[r, c]]
