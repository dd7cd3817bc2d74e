"""calib.board_shape (and its hooks in calib.flex, calib.flex_check): the board's shape beyond the sag."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aicalib_tf.calib import board_shape as BS
from aicalib_tf.calib.files import calibration_from_dict, to_json
from aicalib_tf.calib.fit import calibrate_camera
from aicalib_tf.calib.flex import flex_line
from aicalib_tf.calib.flex_check import afford_cut, afford_part, confirm_shape, lens_shift, shape_estimate
from aicalib_tf.calib.schema import FieldError
from aicalib_tf.geometry import lens as L
from aicalib_tf.geometry.board_shape import SHAPE_TERMS, out_of_plane_rms
from tests.calib.synthetic import synthetic_views

PATTERN = (9, 6)
SQUARE = 0.04
SIZE = (640, 480)
PINHOLE = L.Lens("plumb_bob", [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]], [-0.25, 0.08, 0.001, -0.0005, 0.0], SIZE)
SHAPE = (0.006, 0.004, 0.01, 0.004, -0.003, 0.0, 0.003)  # squares: a twisted board with an S along each axis


@pytest.fixture(scope="module")
def shaped():
    """(views, the shape fit (flex "auto"), the flat fit) of 20 views of SHAPE, 0.2 px noise."""
    views = synthetic_views(PINHOLE, 20, 0.2, seed=np.random.default_rng([0, 47]), flex=SHAPE)
    fit = lambda mode: calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", square_unit="m",  # noqa: E731
                                        flex=mode)
    return views, fit("auto"), fit("off")


def test_a_twisted_board_is_recovered_and_the_focal_length_unbiased(shaped):
    _, cal, flat = shaped
    assert cal.flex.shape == (len(SHAPE_TERMS),) and cal.flex_covariance.shape == (7, 7)
    se = np.sqrt(np.diag(cal.flex_covariance))
    for k in (0, 1, 2, 3, 4):  # the terms the board has
        assert abs(cal.flex[k] - SHAPE[k]) < max(3 * se[k], 0.001), (SHAPE_TERMS[k], cal.flex[k], se[k])
    truth = out_of_plane_rms(SHAPE, np.zeros((7, 7)), PATTERN)[0]
    assert out_of_plane_rms(cal.flex, cal.flex_covariance, PATTERN)[0] == pytest.approx(truth, rel=0.15)
    assert abs(cal.fx - 500.0) < 2 * cal.std["fx"] < abs(flat.fx - 500.0)  # the flat board pulls fx by 5σ
    assert cal.rms < flat.rms


def test_the_shape_round_trips_through_camera_json_and_the_report_names_its_terms(shaped):
    _, cal, _ = shaped
    d = json.loads(to_json(cal))["board_flex"]
    assert d["shape_terms"] == list(SHAPE_TERMS) and d["shape"] == pytest.approx(cal.flex.tolist())
    assert d["wx"] == cal.flex[0] and d["out_of_plane_rms_unit"] == pytest.approx(d["out_of_plane_rms"] * SQUARE)
    back = calibration_from_dict(json.loads(to_json(cal)))
    np.testing.assert_array_equal(back.flex, cal.flex)
    np.testing.assert_array_equal(back.flex_covariance, cal.flex_covariance)
    line = flex_line(cal)
    assert line.startswith("board flex: shape out of plane RMS") and "twist +0.01" in line
    bad = json.loads(to_json(cal))
    bad["board_flex"]["shape"] = bad["board_flex"]["shape"][:2]
    with pytest.raises(FieldError, match="board_flex.shape"):
        calibration_from_dict(bad)


def test_terms_within_half_a_standard_error_are_zero_and_a_shape_of_noise_is_flat(shaped):
    est, se, _ = shape_estimate([0.02, 0.0004, -0.003], [0.001, 0.001, 0.001], np.zeros((3, 3)))
    assert est[1] == 0.0 and est[0] == 0.02 and -0.003 < est[2] < 0.0 and se.tolist() == [0.001] * 3
    views, cal, flat = shaped

    class Fit:  # a solved shape every leave-one-out refit contradicts
        flex, flex_covariance = np.full(7, 1e-4), np.eye(7) * 1e-8

    loo = iter(np.tile([1e-3, -1e-3], 10))
    refit = lambda vs, mode: (flat if mode == "off" else type("F", (), {"flex": np.full(7, next(loo))}))  # noqa: E731
    out = confirm_shape(Fit(), views, refit)
    assert out.flex is None and "every term of the board's shape is within 0.5 standard error" in out.flex_note


def test_the_shape_is_kept_when_it_moves_the_lens_beyond_its_noise_and_the_note_says_so(shaped):
    _, cal, _ = shaped  # flex="auto": 20 views of a twisted board
    assert cal.flex is not None and "of it kept: it moves the projection over the boards" in cal.flex_note
    assert f"20 views afford none of a shape up to {afford_cut(20):.2f}" in cal.flex_note and "twist" in flex_line(cal)


def test_a_flat_boards_shape_is_not_afforded_and_the_note_says_why():
    views = synthetic_views(PINHOLE, 8, 0.2, seed=np.random.default_rng([1, 47]))
    cal = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", flex="auto")
    assert cal.flex is None and cal.flex_note.startswith("not used: it moves the projection over the boards")
    assert cal.flex_note.endswith("the board is taken as flat") and "8 views afford none of a shape" in cal.flex_note


def test_lens_shift_is_the_move_against_flat_and_se_the_leave_one_out_spread():
    from types import SimpleNamespace

    fit = lambda fx: SimpleNamespace(model="plumb_bob", intrinsics=np.r_[fx, fx, 320.0, 240.0, PINHOLE.dist])  # noqa: E731
    views = [SimpleNamespace(corners=np.array([[60.0, 60.0], [580.0, 60.0], [580.0, 420.0], [60.0, 420.0]]))]
    shift, se = lens_shift(fit(500.0), fit(505.0), [fit(505.0)] * 6, views, SIZE)
    assert shift > 1.0 and se == 0.0  # fx 1% longer: pixels move outwards, no rotation undoes it
    shift, se = lens_shift(fit(500.0), fit(500.0), [fit(499.0), fit(501.0)] * 3, views, SIZE)
    assert shift < 1e-6 and se > 0.5
    assert afford_cut(6) > afford_cut(20) > 1.28  # fewer views, a higher bar (Student's t, one-sided 90%)
    assert afford_part(1.0, 1.0, 20) == 0.0 and afford_part(2.7, 1.0, 20) == 1.0 and 0 < afford_part(2.0, 1.0, 20) < 1


def test_an_implausible_shape_is_not_used():
    assert BS.shape_problem(np.zeros(7), np.eye(7)) == ""
    assert "twist" in BS.shape_problem(np.array([0, 0, 0.3, 0, 0, 0, 0.0]), np.eye(7))
    assert BS.shape_problem(None, None) == "not determined by these views"


def test_held_out_views_of_the_model_choice_are_posed_on_the_shape_the_fold_solved():
    from aicalib_tf.calib.fit import _fit_model
    from aicalib_tf.calib.robust import SolveOptions
    from aicalib_tf.calib.select import fold_scores

    views = synthetic_views(PINHOLE, 12, 0.1, seed=8, flex=(0.0, 0.0, 0.02))
    fit = lambda vs, m, start: _fit_model(m, vs, 1.0, SIZE, start, False, True, SolveOptions(PATTERN, "shape"))  # noqa: E731
    full = fit(views, "plumb_bob", None)
    scores = fold_scores(views, 1.0, fit, "plumb_bob", full, PATTERN)
    assert len(full.flex) == 7 and scores.mean() < 1.2 * full.rms, (scores, full.rms)
