"""Distances between point sets (aicalib_tf.geometry.points)."""

import numpy as np
import pytest

from aicalib_tf.geometry.points import sq_distances


@pytest.mark.parametrize("m, n", [(0, 4), (3, 0), (1, 1), (60, 45)])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_sq_distances_are_the_summed_squares_bit_for_bit(m, n, dtype):
    rng = np.random.default_rng(m * 100 + n)
    a, b = rng.uniform(-500, 2000, (m, 2)).astype(dtype), rng.uniform(-500, 2000, (n, 2)).astype(dtype)
    got = sq_distances(a, b)
    assert got.shape == (m, n) and got.dtype == dtype
    np.testing.assert_array_equal(got, ((a[:, None, :] - b[None, :, :]) ** 2).sum(-1))
