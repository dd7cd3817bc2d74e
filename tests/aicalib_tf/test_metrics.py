import numpy as np
import pytest

from aicalib_tf.metrics import align_to_truth, board_symmetries, corner_error_stats


def _grid(cols, rows):
    c, r = np.meshgrid(np.arange(cols), np.arange(rows))
    return np.stack([c.ravel() * 10.0 + 5, r.ravel() * 10.0 + 7], axis=1)


def test_reversed_order_is_aligned_back():
    gt = _grid(9, 6)
    assert np.array_equal(align_to_truth(gt[::-1], gt, (9, 6)), gt)


def test_square_board_allows_quarter_turns():
    gt = _grid(5, 5)
    assert len(board_symmetries((5, 5))) == 4 and len(board_symmetries((9, 6))) == 2
    idx = np.arange(25).reshape(5, 5)
    turned = gt[np.rot90(idx, 1).ravel()]
    assert np.array_equal(align_to_truth(turned, gt, (5, 5)), gt)


def test_shift_gives_exactly_the_shift():
    gt = _grid(4, 3)
    e = np.linalg.norm(align_to_truth(gt + [0.3, 0.4], gt, (4, 3)) - gt, axis=1)
    st = corner_error_stats(e)
    assert st["median"] == pytest.approx(0.5) and st["rmse"] == pytest.approx(0.5) and st["count"] == 12


def test_wrong_sizes_are_rejected():
    with pytest.raises(ValueError, match="need 12 corners"):
        align_to_truth(np.zeros((11, 2)), np.zeros((12, 2)), (4, 3))


def test_match_points_is_one_to_one_and_closest_first():
    from aicalib_tf.metrics import match_points, point_detection_stats

    truth = np.array([[0.0, 0.0], [10.0, 0.0]])
    pred = np.array([[0.3, 0.0], [0.1, 0.0], [10.0, 0.9], [50.0, 50.0]])
    ip, it, d = match_points(pred, truth, 1.0)
    assert sorted(zip(ip.tolist(), it.tolist())) == [(1, 0), (2, 1)]
    np.testing.assert_allclose(sorted(d), [0.1, 0.9])
    stats = point_detection_stats([(pred, truth), (np.zeros((0, 2)), np.array([[5.0, 5.0]]))])
    assert stats["matched"] == 2 and stats["predicted"] == 4 and stats["true"] == 3
    assert stats["precision"] == 0.5 and abs(stats["recall"] - 2 / 3) < 1e-12
    assert abs(stats["loc_median_px"] - 0.5) < 1e-12


def test_calibration_errors_zero_for_the_true_camera_and_exact_for_a_focal_change():
    from aicalib_tf.metrics import calibration_errors

    K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])
    dist = np.array([-0.3, 0.1, 0.001, -0.0005, -0.02])
    e = calibration_errors(K, dist, K, dist, (640, 480))
    assert e["fx_pct"] == 0 and e["pp_px"] == 0 and e["dist_field_max_px"] < 1e-6
    assert e["dist_field_points"] == 32 * 24
    K2 = K.copy()
    K2[0, 0], K2[0, 2] = 505.0, 323.0
    e2 = calibration_errors(K2, np.zeros(5), K, np.zeros(5), (640, 480))
    assert e2["fx_pct"] == pytest.approx(1.0) and e2["pp_px"] == pytest.approx(3.0)
    assert e2["dist_field_max_px"] < 1e-9  # no lens distortion in either: the fields are both zero


def test_distortion_field_matches_projection_and_grows_with_k1():
    from aicalib_tf.metrics import calibration_errors, distortion_field

    K = np.array([[400.0, 0, 320], [0, 400.0, 240], [0, 0, 1]])
    dist = np.array([-0.2, 0, 0, 0, 0])
    # a point at normalized (0.5, 0): distorted radius 0.5·(1 − 0.2·0.25) = 0.475
    field, ok = distortion_field(np.array([[320 + 400 * 0.475, 240.0]]), K, dist)
    assert ok.all() and field[0] == pytest.approx([400 * 0.025, 0.0], abs=1e-6)
    small = calibration_errors(K, dist * 0.9, K, dist, (640, 480))["dist_field_mean_px"]
    big = calibration_errors(K, dist * 0.5, K, dist, (640, 480))["dist_field_mean_px"]
    assert 0 < small < big
