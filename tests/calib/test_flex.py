"""calib.flex, calib.robust: the board's flex, per-corner weights and single-corner rejection inside the solve."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aicalib_tf.calib.files import calibration_dict, calibration_from_dict, to_json
from aicalib_tf.calib.fit import View, _fit_model, calibrate_camera
from aicalib_tf.calib.flex import FLEX_SIGMA_MAX, flex_problem
from aicalib_tf.calib.report import solve_lines
from aicalib_tf.calib.robust import SolveOptions
from aicalib_tf.calib.select import fold_scores
from aicalib_tf.geometry import lens as L
from aicalib_tf.geometry.board_flex import flex_basis
from aicalib_tf.geometry.board_shape import shape_height, shaped_points
from aicalib_tf.geometry.pattern import board_points
from tests.calib.synthetic import synthetic_views

PATTERN = (9, 6)
SQUARE = 0.04
SIZE = (640, 480)
PINHOLE = L.Lens("plumb_bob", [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]], [-0.25, 0.08, 0.001, -0.0005, 0.0], SIZE)


def flexed_views(n=20, noise=0.2, flex=(0.0, 0.0), seed=2, noise_of=None):
    """``n`` views of a 9x6 board (square 0.04 m) flexed by ``flex`` squares; noise px (1σ per axis), or
    per view from noise_of(k)."""
    return synthetic_views(PINHOLE, n, noise, seed=seed, flex=flex, noise_of=noise_of)


def test_flex_basis_is_zero_on_the_grid_edges_and_one_at_the_centre():
    b = flex_basis(np.array([0.0, 8.0, 4.0, 4.0]), np.array([0.0, 5.0, 2.5, 0.0]), PATTERN)
    np.testing.assert_allclose(b, [[0, 0], [0, 0], [1, 1], [1, 0]])
    assert shape_height(4.0, 2.5, PATTERN, (0.01, 0.02)) == pytest.approx(0.03)
    p = shaped_points(board_points(np.array([[4, 0], [0, 0]]), 25.0), PATTERN, (0.02, 0.0), 25.0)
    np.testing.assert_allclose(p[:, 2], [0.5, 0.0])  # 0.02 squares of 25 mm at the centre column


def test_flex_is_recovered_and_the_focal_length_unbiased():
    views = flexed_views(flex=(0.012, 0.006))
    cal = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", square_unit="m", flex="sag")
    sd = np.sqrt(np.diag(cal.flex_covariance))
    assert cal.flex_note == "" and sd.max() < FLEX_SIGMA_MAX
    np.testing.assert_allclose(cal.flex, [0.012, 0.006], atol=max(0.002, 3 * sd.max()))
    assert abs(cal.fx - 500.0) < 2.5 * cal.std["fx"]
    flat = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob")  # the default: a flat board
    assert flat.flex is None and abs(flat.fx - 500.0) > 3 * flat.std["fx"]  # ignoring the flex biases fx
    lines = solve_lines(cal)
    assert lines and lines[-1].startswith("board flex: sag") and "squares" in lines[-1] and " m (" in lines[-1]


def test_a_flex_the_views_cannot_determine_stays_off_and_says_why():
    assert "not determined" in flex_problem([0.01, 0.0], np.diag([0.02, 0.001]) ** 2)
    assert flex_problem([0.01, 0.0], np.diag([0.001, 0.001]) ** 2) == ""
    assert "plausible" in flex_problem([0.6, 0.0], np.diag([0.001, 0.001]) ** 2)
    views = [View(v.name, v.corners, v.ids, relative=True) for v in flexed_views(8, flex=(0.01, 0.0))]
    cal = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", flex="sag")
    assert cal.flex is None and "relative" in cal.flex_note
    assert solve_lines(cal)[-1].startswith("board flex: not solved")


def test_a_flex_too_noisy_to_determine_is_left_off_in_the_fit_the_report_and_camera_json():
    views = flexed_views(6, noise=1.5, flex=(0.01, 0.0), seed=6)  # six views at 1.5 px: σ of the flex ≈ 0.01 squares
    cal = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", flex="sag")
    flat = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", flex="off")
    assert cal.flex is None and cal.flex_note.startswith("not determined by these views (σ")
    assert abs(cal.fx - flat.fx) < 1e-3 * flat.std["fx"]  # the fit is the flat one
    assert solve_lines(cal)[-1] == f"board flex: {cal.flex_note}"
    d = json.loads(to_json(cal))["board_flex"]
    assert d["wx"] is None and d["wy"] is None and d["note"] == cal.flex_note
    assert calibration_from_dict(json.loads(to_json(cal))).flex is None


def test_held_out_views_are_posed_on_the_board_the_fold_solved():
    # the model choice's folds: a held-out view posed on a flat board charged a flexed fit with its own flex
    # (12 views, sag 0.02 squares: held-out RMS 1.29x the in-sample RMS, against 1.05x on the fold's board)
    views = flexed_views(12, noise=0.1, flex=(0.012, 0.008), seed=8)
    options = SolveOptions(PATTERN, "sag")
    fit = lambda vs, m, start: _fit_model(m, vs, 1.0, SIZE, start, False, True, options)  # noqa: E731
    full = fit(views, "plumb_bob", None)
    scores = fold_scores(views, 1.0, fit, "plumb_bob", full, PATTERN)
    assert full.flex is not None and scores.mean() < 1.15 * full.rms, (scores, full.rms)
    with pytest.raises(ValueError, match="pattern_size"):
        fold_scores(views, 1.0, fit, "plumb_bob", full)


def test_displaced_corners_are_the_ones_rejected_and_the_fit_is_the_clean_one():
    views = flexed_views(seed=3)
    rng = np.random.default_rng(7)
    dirty, moved = [], {}
    for k, v in enumerate(views):
        c = v.corners.copy()
        if k % 4 == 0:
            i = int(rng.integers(len(c)))
            c[i] += rng.uniform(3, 10) * np.array([np.cos(a := rng.uniform(0, 2 * np.pi)), np.sin(a)])
            moved[v.name] = [v.ids[i].tolist()]
        dirty.append(View(v.name, c, v.ids))
    clean = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", flex="off")
    cal = calibrate_camera(dirty, PATTERN, SQUARE, SIZE, model="plumb_bob", flex="off")
    assert {k: v.tolist() for k, v in cal.rejected_corners.items()} == moved
    assert cal.n_rejected_corners == len(moved) and not cal.rejected and clean.n_rejected_corners == 0
    assert abs(cal.fx - clean.fx) < 0.1 * clean.std["fx"] and abs(cal.cx - clean.cx) < 0.1 * clean.std["cx"]
    old = calibrate_camera(dirty, PATTERN, SQUARE, SIZE, model="plumb_bob", flex="off", reject_corners=False)
    assert old.rejected or abs(old.fx - clean.fx) > 0.5 * clean.std["fx"]  # whole views went, or fx moved
    assert solve_lines(cal)[0].startswith(f"{len(moved)} single corners rejected inside the solve")
    back = calibration_from_dict(json.loads(to_json(cal)))
    assert {k: v.tolist() for k, v in back.rejected_corners.items()} == moved
    assert calibration_dict(cal)["n_rejected_corners"] == len(moved)


def test_per_corner_sigmas_weight_the_fit():
    noisy = set(range(0, 20, 3))
    views = flexed_views(noise=0.1, seed=4, noise_of=lambda k: 1.0 if k in noisy else 0.1)
    weighted = [View(v.name, v.corners, v.ids, sigmas=np.full(len(v.ids), 1.0 if k in noisy else 0.1))
                for k, v in enumerate(views)]
    kw = dict(model="plumb_bob", flex="off", reject_outliers=False)
    plain = calibrate_camera(views, PATTERN, SQUARE, SIZE, **kw)
    cal = calibrate_camera(weighted, PATTERN, SQUARE, SIZE, **kw)
    assert cal.std["fx"] < 0.6 * plain.std["fx"] and abs(cal.fx - 500.0) < 3 * cal.std["fx"]
    # one σ for all corners, at any scale, is the unweighted fit
    same = [View(v.name, v.corners, v.ids, sigmas=np.full(len(v.ids), 7.0)) for v in views]
    eq = calibrate_camera(same, PATTERN, SQUARE, SIZE, **kw)
    assert eq.fx == pytest.approx(plain.fx, abs=1e-5) and eq.std["fx"] == pytest.approx(plain.std["fx"], rel=1e-5)
    with pytest.raises(ValueError, match="sigmas"):
        View("x", views[0].corners, views[0].ids, sigmas=np.zeros(len(views[0].ids)))


def test_flex_round_trips_through_camera_json():
    cal = calibrate_camera(flexed_views(12, flex=(0.01, 0.0), seed=5), PATTERN, SQUARE, SIZE, model="plumb_bob",
                           square_unit="m", flex="sag")
    d = json.loads(to_json(cal))
    assert d["board_flex"]["wx"] == pytest.approx(cal.flex[0]) and d["board_flex"]["note"] == ""
    assert d["board_flex"]["sag_unit"] == pytest.approx(d["board_flex"]["sag"] * SQUARE)
    back = calibration_from_dict(d)
    np.testing.assert_array_equal(back.flex, cal.flex)
    np.testing.assert_array_equal(back.flex_covariance, cal.flex_covariance)


def test_data_gen_renders_a_flexed_board_and_labels_its_projection():
    import cv2
    from dataclasses import replace

    from data_gen.presets import get_preset
    from data_gen.render import board_coordinates
    from data_gen.sample import draw_scene, make_sample

    preset = replace(get_preset("calib"), name="calib_flexed", flex=(0.08, 0.04))
    sample, flat = make_sample(preset, 0, 3), make_sample("calib", 0, 3)
    assert sample.label["board"]["flex"] == [0.08, 0.04] and "flex" not in flat.label["board"]
    scene = draw_scene(preset, 0, 3)
    X, Y = board_coordinates(scene.camera.pixel_to_ray(scene.corners), scene.rvec, scene.tvec, scene.board)
    np.testing.assert_allclose(np.stack([X, Y], 1), scene.board.object_points()[:, :2], atol=1e-9)
    ok, found = cv2.findChessboardCorners(sample.image, PATTERN)
    assert ok
    found = cv2.cornerSubPix(sample.image, found, (5, 5), (-1, -1), (3, 50, 1e-4)).reshape(-1, 2)
    to_flexed = np.median(np.linalg.norm(found - sample.corners, axis=1))
    to_flat = np.median(np.linalg.norm(found - flat.corners, axis=1))
    assert to_flexed < 0.1 and to_flat > 2 * to_flexed, (to_flexed, to_flat)
