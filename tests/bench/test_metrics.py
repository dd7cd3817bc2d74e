import numpy as np
import pytest

from aicalib_tf.bench.metrics import align_to_truth, corner_error_stats
from aicalib_tf.geometry.pattern import board_symmetries


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
    from aicalib_tf.cnn.point_metrics import match_points, point_detection_stats

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
    from aicalib_tf.bench.metrics import calibration_errors

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
    from aicalib_tf.bench.metrics import calibration_errors
    from aicalib_tf.geometry.camera import distortion_field

    K = np.array([[400.0, 0, 320], [0, 400.0, 240], [0, 0, 1]])
    dist = np.array([-0.2, 0, 0, 0, 0])
    # a point at normalized (0.5, 0): distorted radius 0.5·(1 − 0.2·0.25) = 0.475
    field, ok = distortion_field(np.array([[320 + 400 * 0.475, 240.0]]), K, dist)
    assert ok.all() and field[0] == pytest.approx([400 * 0.025, 0.0], abs=1e-6)
    small = calibration_errors(K, dist * 0.9, K, dist, (640, 480))["dist_field_mean_px"]
    big = calibration_errors(K, dist * 0.5, K, dist, (640, 480))["dist_field_mean_px"]
    assert 0 < small < big


def test_projection_error_field_across_models():
    import math

    from aicalib_tf.bench.metrics import calibration_errors
    from aicalib_tf.geometry import lens

    K = np.array([[150.0, 0, 319.5], [0, 150.0, 239.5], [0, 0, 1]])
    kb = np.array([0.02, -0.004, 0.001, 0.0])
    theta = math.radians(92.5)
    same = calibration_errors(K, kb, K, kb, (640, 480), model="equidistant", model_true="equidistant",
                              max_theta_true=theta, seen=[[200, 150], [440, 150], [440, 330], [200, 330]])
    assert same["proj_err_max_px"] < 1e-6 and same["proj_err_fail_frac"] == 0.0
    assert same["proj_err_seen_mean_px"] < 1e-6
    # Only the circle counts: the corners of this 185° circular image see nothing.
    r = 150.0 * theta * (1 + sum(kb[i] * theta ** (2 * i + 2) for i in range(4)))
    assert same["proj_err_points"] < 32 * 24 * math.pi * r * r / (640 * 480) * 1.1
    # A 1 % focal error of the same model: the error grows with the radius, at most 1 % of it.
    K2 = K.copy()
    K2[0, 0] = K2[1, 1] = 151.5
    e = calibration_errors(K2, kb, K, kb, (640, 480), model="equidistant", model_true="equidistant",
                           max_theta_true=theta)
    assert 0 < e["proj_err_mean_px"] < e["proj_err_max_px"] <= 0.01 * r + 1e-6
    # A pinhole estimate cannot project the rays at and past 90°.
    pin = calibration_errors(K, np.zeros(5), K, kb, (640, 480), model_true="equidistant", max_theta_true=theta)
    assert pin["proj_err_fail_frac"] > 0.05 and pin["proj_err_mean_px"] > 1.0
    # The other way round: a fisheye estimate of a plumb_bob lens.
    d = np.array([-0.2, 0.03, 0, 0, 0])
    ray = lens.unproject([[600.0, 400.0]], "plumb_bob", K, d)
    assert np.isfinite(ray).all()
    mixed = calibration_errors(K, kb, K, d, (640, 480), model="equidistant")
    assert mixed["proj_err_fail_frac"] == 0.0 and mixed["proj_err_mean_px"] > 1.0


# --- detection outcomes, partial boards, agreement ------------------------------------------

def _ids(cols, rows):
    c, r = np.meshgrid(np.arange(cols), np.arange(rows))
    return np.stack([c.ravel(), r.ravel()], axis=1)


def test_perfect_oracle_is_a_hit_with_zero_error():
    from aicalib_tf.bench.metrics import board_detection_outcome

    gt = _grid(9, 6)
    outcome, err = board_detection_outcome(gt.copy(), gt, (9, 6))
    assert outcome == "hit" and err.shape == (54,) and err.max() == 0.0


def test_shifted_oracle_gives_exactly_the_shift():
    from aicalib_tf.bench.metrics import board_detection_outcome

    gt = _grid(9, 6)
    outcome, err = board_detection_outcome(gt + [0.6, -0.8], gt, (9, 6))
    assert outcome == "hit"
    np.testing.assert_allclose(err, 1.0, atol=1e-12)
    assert corner_error_stats(err)["median"] == pytest.approx(1.0)


def test_reversed_order_is_still_a_hit():
    from aicalib_tf.bench.metrics import board_detection_outcome

    gt = _grid(9, 6)
    outcome, err = board_detection_outcome(gt[::-1], gt, (9, 6))
    assert outcome == "hit" and err.max() == 0.0


def test_random_corners_and_no_board_are_not_hits():
    from aicalib_tf.bench.metrics import board_detection_outcome

    gt = _grid(9, 6)
    rng = np.random.default_rng(0)
    outcome, _ = board_detection_outcome(rng.uniform(0, 100, (54, 2)), gt, (9, 6))
    assert outcome == "wrong"  # a reported board that is not the board: never counted as detected
    outcome, err = board_detection_outcome(None, gt, (9, 6))
    assert outcome == "miss" and err.size == 0


def test_one_corner_three_px_off_is_a_wrong_detection():
    from aicalib_tf.bench.metrics import board_detection_outcome

    gt = _grid(9, 6)
    det = gt.copy()
    det[17] += [3.0, 0.0]
    outcome, err = board_detection_outcome(det, gt, (9, 6))
    assert outcome == "wrong" and err.max() == pytest.approx(3.0) and np.sum(err > 0) == 1
    det[17] = gt[17] + [1.9, 0.0]
    assert board_detection_outcome(det, gt, (9, 6))[0] == "hit"


def test_outcome_rejects_wrong_sizes():
    from aicalib_tf.bench.metrics import board_detection_outcome

    with pytest.raises(ValueError, match="need 54"):
        board_detection_outcome(None, np.zeros((53, 2)), (9, 6))
    with pytest.raises(ValueError, match="need 54"):
        board_detection_outcome(np.zeros((50, 2)), _grid(9, 6), (9, 6))


def test_partial_with_correct_ids_has_full_recall_and_no_wrong_ids():
    from aicalib_tf.bench.metrics import partial_board_stats

    gt, ids = _grid(9, 6), _ids(9, 6)
    visible = ids[:, 0] < 5  # the right part of the board is out of frame
    st = partial_board_stats(gt[visible] + 0.1, ids[visible], gt, visible, (9, 6))
    assert st["visible"] == 30 and st["correct"] == 30 and st["wrong_ids"] == 0 and st["recall"] == 1.0
    np.testing.assert_allclose(st["errors"], np.hypot(0.1, 0.1))


def test_partial_with_ids_shifted_by_one_column_is_all_wrong():
    from aicalib_tf.bench.metrics import partial_board_stats

    gt, ids = _grid(9, 6), _ids(9, 6)
    visible = ids[:, 0] < 5
    st = partial_board_stats(gt[visible], ids[visible] + [1, 0], gt, visible, (9, 6))
    assert st["correct"] == 0 and st["wrong_ids"] == 30 and st["recall"] == 0.0


def test_partial_read_in_reverse_uses_the_180_degree_symmetry():
    from aicalib_tf.bench.metrics import partial_board_stats

    gt, ids = _grid(9, 6), _ids(9, 6)
    visible = ids[:, 1] >= 2
    flipped = np.stack([8 - ids[:, 0], 5 - ids[:, 1]], axis=1)
    st = partial_board_stats(gt[visible], flipped[visible], gt, visible, (9, 6))
    assert st["correct"] == 36 and st["wrong_ids"] == 0 and st["symmetry"] == 1


def test_partial_full_detection_duplicates_and_out_of_range_ids():
    from aicalib_tf.bench.metrics import partial_board_stats

    gt, ids = _grid(4, 3), _ids(4, 3)
    visible = np.ones(12, bool)
    visible[0] = False  # an occluded corner found in place: neither a recovery nor a wrong id
    st = partial_board_stats(gt, ids, gt, visible, (4, 3))
    assert st["correct"] == 11 and st["hidden_found"] == 1 and st["wrong_ids"] == 0 and st["recall"] == 1.0
    far = gt.copy()
    far[0] += 5.0
    st = partial_board_stats(far, ids, gt, visible, (4, 3))
    assert st["correct"] == 11 and st["hidden_found"] == 0 and st["wrong_ids"] == 1
    corners = np.vstack([gt[5], gt[5] + 0.5, gt[6]])
    st = partial_board_stats(corners, np.array([[1, 1], [1, 1], [9, 9]]), gt, visible, (4, 3))
    assert st["correct"] == 1 and st["wrong_ids"] == 2 and st["errors"].tolist() == [0.0]
    st = partial_board_stats(np.zeros((0, 2)), np.zeros((0, 2), int), gt, visible, (4, 3))
    assert st["correct"] == 0 and st["recall"] == 0.0
    with pytest.raises(ValueError, match="disagree"):
        partial_board_stats(gt, ids[:5], gt, visible, (4, 3))


def test_partial_square_board_quarter_turn():
    from aicalib_tf.bench.metrics import partial_board_stats

    gt, ids = _grid(5, 5), _ids(5, 5)
    turned = np.stack([ids[:, 1], 4 - ids[:, 0]], axis=1)  # ids of the same corners after a 90° turn
    st = partial_board_stats(gt, turned, gt, np.ones(25, bool), (5, 5))
    assert st["correct"] == 25 and st["wrong_ids"] == 0


def test_agreement_of_two_detectors_after_symmetry():
    from aicalib_tf.bench.metrics import detection_agreement

    gt = _grid(9, 6)
    b = gt[::-1].copy()
    b[0] += [0.0, 0.5]
    ag = detection_agreement(gt, b, (9, 6))
    assert ag["median_px"] == 0.0 and ag["max_px"] == pytest.approx(0.5)


def test_calibration_errors_seen_region_leaves_out_the_unseen_image_corners():
    from aicalib_tf.bench.metrics import calibration_errors

    K = np.array([[400.0, 0, 320], [0, 400.0, 240], [0, 0, 1]])
    true, est = np.array([-0.3, 0.1, 0, 0, 0]), np.array([-0.3, 0.1, 0, 0, -0.05])  # differ mostly far out
    seen = np.array([[220.0, 160], [420, 160], [420, 320], [220, 320]])
    e = calibration_errors(K, est, K, true, (640, 480), seen=seen)
    assert e["dist_field_seen_max_px"] < 0.05 < e["dist_field_max_px"]
    assert e["dist_field_seen_mean_px"] < e["dist_field_mean_px"]
