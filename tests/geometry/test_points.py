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


def _dense_pairs(a, b, r, strict):
    d2 = sq_distances(a, b)
    return np.nonzero(d2 < r**2 if strict else d2 <= r**2)


def test_close_pairs_are_the_dense_pairs_through_the_tree_too(monkeypatch):
    """The k-d tree path (large sets) finds exactly the dense path's pairs, boundary ties included."""
    from aicalib_tf.geometry import points

    rng = np.random.default_rng(3)
    for dtype in (np.float32, np.float64):
        a = (rng.random((400, 2)) * 80).astype(dtype)
        b = (rng.random((500, 2)) * 80).astype(dtype)
        b[:20] = a[:20] + np.array([2.5, 0.0], dtype)  # exactly on the radius
        b[20] = np.nan
        for strict in (False, True):
            want = _dense_pairs(a, b, 2.5, strict)
            monkeypatch.setattr(points, "BLOCK", 1 << 20)
            dense = points.close_pairs(a, b, 2.5, strict=strict)
            monkeypatch.setattr(points, "BLOCK", 16)
            tree = points.close_pairs(a, b, 2.5, strict=strict)
            for got in (dense, tree):
                assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
            assert np.array_equal(points.any_within(a, b, 2.5, strict=strict),
                                  np.isin(np.arange(len(a)), want[0]))


def test_a_large_weak_point_set_needs_no_dense_matrix():
    """134,821 × 52,426 points once took a 26 GiB matrix (weak_points); the tree answers in O(N + pairs)."""
    from aicalib_tf.geometry.points import any_within

    rng = np.random.default_rng(4)
    low = (rng.random((134_821, 2)) * [3840, 2160]).astype(np.float32)
    strong = (rng.random((52_426, 2)) * [3840, 2160]).astype(np.float32)
    near = any_within(low, strong, 2.5, strict=True)
    k = rng.choice(len(low), 200, replace=False)  # spot check against the dense answer
    assert np.array_equal(near[k], sq_distances(low[k], strong).min(axis=1) < 2.5**2)


def test_nearest_k_and_nearest_index_match_the_dense_sort(monkeypatch):
    from aicalib_tf.geometry import points

    rng = np.random.default_rng(5)
    pts = np.round(rng.random((300, 2)) * 20)  # many ties
    d2 = sq_distances(pts, pts)
    np.fill_diagonal(d2, np.inf)
    monkeypatch.setattr(points, "BLOCK", 200)
    assert np.array_equal(points.nearest_k(pts, 12), np.argsort(d2, axis=1)[:, :12])
    centres = np.round(rng.random((40, 2)) * 20)
    want = np.argmin(np.linalg.norm(pts[:, None] - centres[None], axis=2), axis=1)
    assert np.array_equal(points.nearest_index(pts, centres), want)
