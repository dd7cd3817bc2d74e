import numpy as np
import pytest

from aicalib_tf.cnn.corner_map import STRIDE, decode_map, encode_corners, padded_shape, standardize


def test_encode_decode_round_trip_is_exact():
    rng = np.random.default_rng(0)
    # one corner per cell: a jittered grid 8 px apart
    gx, gy = np.meshgrid(np.arange(6, 120, 8.0), np.arange(6, 90, 8.0))
    pts = np.stack([gx.ravel(), gy.ravel()], 1) + rng.uniform(-1.5, 1.5, (gx.size, 2))
    target = encode_corners(pts, (128, 96))
    assert target.shape == (96 // STRIDE, 128 // STRIDE, 3)
    assert target[..., 0].sum() == len(pts)
    got, scores = decode_map(target, 0.5)
    assert len(got) == len(pts) and np.all(scores == 1.0)
    order = np.lexsort((got[:, 0], got[:, 1]))
    ref = np.lexsort((pts[:, 0], pts[:, 1]))
    np.testing.assert_allclose(got[order], pts[ref], atol=1e-5)


def test_cell_convention_matches_pixel_centres():
    # pixel centre (0, 0) lies in cell 0 at fraction 0.125; y = 3.5 starts cell 1 (fraction 0)
    t = encode_corners(np.array([[0.0, 0.0], [3.49, 3.5]]), (8, 8))
    np.testing.assert_allclose(t[0, 0], [1.0, 0.125, 0.125])
    np.testing.assert_allclose(t[1, 0], [1.0, (3.49 + 0.5) / 4, 0.0], atol=1e-6)


def test_points_outside_the_image_are_ignored():
    t = encode_corners(np.array([[-0.6, 3.0], [8.0, 2.0], [2.0, 7.6]]), (8, 8))
    assert t[..., 0].sum() == 0


def test_decode_keeps_one_of_two_cells_lit_by_one_corner():
    m = np.zeros((4, 4, 3), np.float32)
    m[1, 1] = [0.9, 0.99, 0.5]  # x = 4·1.99 − 0.5 = 7.46
    m[1, 2] = [0.7, 0.0, 0.5]  # x = 4·2 − 0.5 = 7.5, the same corner from the next cell
    m[3, 3] = [0.6, 0.5, 0.5]  # a separate corner
    pts, scores = decode_map(m, 0.5)
    assert len(pts) == 2
    np.testing.assert_allclose(scores, [1.0, 0.6])  # 0.9 + 0.7 pooled, capped at 1
    np.testing.assert_allclose(pts[0], [(0.9 * 7.46 + 0.7 * 7.5) / 1.6, 5.5], atol=1e-5)


def test_decode_pools_a_corner_split_between_four_cells():
    """A corner exactly on a cell corner lights four cells below the threshold; it is still found."""
    m = np.zeros((4, 4, 3), np.float32)
    m[1, 1] = [0.45, 1.0, 1.0]
    m[1, 2] = [0.4, 0.0, 1.0]
    m[2, 1] = [0.45, 1.0, 0.0]
    m[2, 2] = [0.4, 0.0, 0.0]  # all four point at (7.5, 7.5)
    m[0, 3] = [0.45, 0.5, 0.5]  # alone and weak: stays out
    pts, scores = decode_map(m, 0.5)
    assert len(pts) == 1 and scores[0] == 1.0
    np.testing.assert_allclose(pts[0], [7.5, 7.5], atol=1e-5)


def test_decode_ties_keep_the_cell_first_in_row_major_order_and_take_any_float_map():
    m = np.zeros((3, 5, 3))  # float64 in: decoded as float32
    m[1, 1] = [0.8, 0.9, 0.5]  # x = 4·1.9 − 0.5 = 7.1
    m[1, 2] = [0.8, 0.2, 0.5]  # x = 8.3, 1.2 px away: close, not pooled, an equal weight
    m[0, 4] = [0.6, 0.5, 0.5]  # on the map's edge: its missing neighbours count for nothing
    pts, scores = decode_map(m, 0.5)
    assert pts.dtype == np.float32 and scores.dtype == np.float32
    np.testing.assert_allclose(pts, [[7.1, 5.5], [17.5, 1.5]], atol=1e-5)
    np.testing.assert_allclose(scores, [0.8, 0.6])


def test_decode_threshold_and_shape_check():
    m = np.zeros((2, 2, 3), np.float32)
    m[0, 0, 0] = 0.4
    assert len(decode_map(m, 0.5)[0]) == 0
    assert len(decode_map(m, 0.3)[0]) == 1
    with pytest.raises(ValueError, match=r"\(h, w, 3\)"):
        decode_map(np.zeros((2, 2)), 0.5)


def test_standardize_and_padding():
    g = np.array([[0, 255], [255, 0]], np.uint8)
    s = standardize(g)
    assert s.dtype == np.float32 and abs(s.mean()) < 1e-6 and abs(s.std() - 1) < 1e-6
    assert np.all(standardize(np.full((3, 3), 7, np.uint8)) == 0)
    assert padded_shape(481, 640) == (484, 640)


@pytest.mark.parametrize("shape", [(240, 320), (7, 5), (1, 1), (0, 4)])
def test_the_compiled_statistics_are_numpys_in_float64(shape):
    from aicalib_tf.cnn.corner_map_kernels import mean_std

    g = np.random.default_rng(shape[0]).random(shape).astype(np.float32) * 0.3 + 0.5
    mean, std = mean_std(g)
    want = (g.astype(np.float64).mean(), g.astype(np.float64).std()) if g.size else (0.0, 0.0)
    np.testing.assert_allclose((mean, std), want, rtol=1e-12, atol=1e-15)
    # the network's input is the same as with numpy's float32 statistics, to float32 rounding
    if g.size:
        want_input = (g - np.float32(g.mean())) / np.float32(max(g.std(), 1e-3))
        np.testing.assert_allclose(standardize(g), want_input, rtol=0, atol=1e-5)
