"""calib.schema: the text checks before cv2.FileStorage and the field checks after."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from aicalib_tf.calib import schema as S


@pytest.mark.parametrize("text, low, high", [
    ("%YAML:1.0\n---\na: 1\nm: !!opencv-matrix\n   rows: 1\n   cols: 1\n   dt: d\n   data: [ 1. ]\n", 1, 10),
    ("a: " + "[" * 100 + "]" * 100, S.MAX_DEPTH + 1, 110),
    ("a:\n  " + "- " * 100 + "1\n", S.MAX_DEPTH + 1, 110),
    ("".join(" " * i + "a:\n" for i in range(100)), S.MAX_DEPTH + 1, 110),  # block maps, one space deeper each
    ('a: "' + "[" * 100 + '"\nb: [x, \'' + "{" * 100 + "', [1]]\n", 2, 12),  # brackets in quoted strings are text
    ('a: [x, "' + "]" * 100 + '", ' + "[" * 80 + "]" * 80 + "]", 81, 92),  # quoted closers hide nothing
    ('a: [x"' + ", " + "[" * 80 + "]" * 80 + '"]', 81, 92),  # a quote inside a plain scalar opens no string
])
def test_yaml_depth_bounds_the_nesting(text, low, high):
    """An upper bound up to MAX_DEPTH; past it, some number over MAX_DEPTH (the scan stops early)."""
    assert low <= S.yaml_depth(text) <= high


def test_within_names_nested_fields():
    with pytest.raises(S.FieldError, match=r"^field cameras\[1\].board.square_size must be a positive finite number"):
        with S.within("cameras[1]"), S.within("board"):
            S.require_number({"square_size": -25}, "square_size", positive=True)


def test_numbers_and_ints():
    assert S.require_int({"w": 64.0}, "w", 1, 100) == 64
    assert S.require_int({"w": np.array([[7.0]])}, "w", 1, 10) == 7
    for bad in (True, "7", 7.5, float("inf"), 10**400, None):
        with pytest.raises(S.FieldError, match="field w must be an integer"):
            S.require_int({"w": bad}, "w", 1, 10)
    assert np.isnan(S.require_number({"x": None}, "x", nullable=True))
    with pytest.raises(S.FieldError, match="field x is missing"):
        S.require_number({}, "x")


def test_rotations_within_tolerance():
    R = Rotation.from_euler("xyz", [0.3, -0.2, 1.0]).as_matrix()
    np.testing.assert_array_equal(S.require_rotation({"R": R}, "R"), R)
    for bad in (R * 1.001, -R, R @ np.diag([1, 1, -1])):
        with pytest.raises(S.FieldError, match="field R must be a rotation"):
            S.require_rotation({"R": bad}, "R")


def test_camera_matrix_and_dist():
    K = [[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]
    assert S.require_camera_matrix({"K": K}, "K").shape == (3, 3)
    with pytest.raises(S.FieldError, match="fx, fy > 0"):
        S.require_camera_matrix({"K": [[0.0, 0, 320], [0, 500, 240], [0, 0, 1]]}, "K")
    np.testing.assert_array_equal(S.require_dist({"d": [[0.1, 0.2, 0, 0]]}, "d", "plumb_bob"), [0.1, 0.2, 0, 0, 0])
    with pytest.raises(S.FieldError, match="field d does not fit the lens model"):
        S.require_dist({"d": [0.1] * 5}, "d", "equidistant")


def test_model_names():
    assert S.require_model({}, 5) == "plumb_bob"
    assert S.require_model({"model": "thin_prism", "distortion_model": "rational_polynomial"}, 12) == "thin_prism"
    assert S.require_model({"distortion_model": "fisheye"}, 4) == "equidistant"
    with pytest.raises(S.FieldError, match="field distortion_model is 'plumb_bob' but model is 'equidistant'"):
        S.require_model({"model": "equidistant", "distortion_model": "plumb_bob"}, 4)
