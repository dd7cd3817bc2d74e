"""geometry.board_shape: the board's out-of-plane polynomial, its first two terms the flex."""

from __future__ import annotations

import doctest

import numpy as np
import pytest

from aicalib_tf.geometry import board_shape as B
from aicalib_tf.geometry.board_flex import flex_basis
from aicalib_tf.geometry.pattern import board_points, pattern_ids

PATTERN = (9, 6)


def test_the_first_two_terms_are_the_flex_and_a_two_term_shape_is_the_flex():
    ids = pattern_ids(PATTERN).astype(float)
    basis = B.shape_basis(ids[:, 0], ids[:, 1], PATTERN)
    assert basis.shape == (54, len(B.SHAPE_TERMS))
    np.testing.assert_array_equal(basis[:, :2], flex_basis(ids[:, 0], ids[:, 1], PATTERN))
    assert np.abs(basis).max() <= 1.0 + 1e-12  # each term at most 1 over the grid: w_k is an offset in squares
    pts = board_points(pattern_ids(PATTERN), 0.04)
    flexed = pts + np.outer(0.04 * flex_basis(ids[:, 0], ids[:, 1], PATTERN) @ (0.01, -0.02), [0.0, 0.0, 1.0])
    np.testing.assert_allclose(B.shaped_points(pts, PATTERN, (0.01, -0.02), 0.04), flexed, atol=1e-15)


def test_no_term_is_a_rigid_motion_of_the_board():
    """A constant and the linear terms are the pose's: every term has a part no plane explains."""
    ids = pattern_ids(PATTERN).astype(float)
    basis = B.shape_basis(ids[:, 0], ids[:, 1], PATTERN)
    A = np.stack([np.ones(len(ids)), ids[:, 0], ids[:, 1]], 1)
    left = basis - A @ np.linalg.lstsq(A, basis, rcond=None)[0]
    assert np.linalg.matrix_rank(left) == len(B.SHAPE_TERMS)
    rms, sd = B.out_of_plane_rms([0.0, 0.0, 0.01], np.diag([0.0, 0.0, 1e-6]), PATTERN)
    assert rms == pytest.approx(0.01 * np.sqrt(np.mean(left[:, 2] ** 2))) and sd == pytest.approx(rms / 10)
    assert B.out_of_plane_rms([0.0, 0.0], np.eye(2), PATTERN) == (0.0, 0.0)


def test_the_twist_lifts_opposite_corners_and_bad_input_is_refused():
    z = B.shape_height(np.array([0.0, 8.0, 0.0, 8.0]), np.array([0.0, 0.0, 5.0, 5.0]), PATTERN, [0, 0, 0.01])
    np.testing.assert_allclose(z, [0.01, -0.01, -0.01, 0.01])
    with pytest.raises(ValueError, match="n_terms"):
        B.shape_basis(0.0, 0.0, PATTERN, 8)
    with pytest.raises(ValueError, match="pattern_size"):
        B.shape_basis(0.0, 0.0, (1, 6))


def test_doctests():
    assert doctest.testmod(B).failed == 0
