"""Each corner's σ (aicalib_tf.detect.corners.sigma): its measurements, the model, and the detector's sigmas."""

import numpy as np
import pytest

from aicalib_tf.detect.corners import sigma as cs
from aicalib_tf.detect.corners.sigma_kernels import (SPREAD_KNOT, WHITE_EVEN, axis_spacing, blockiness, design_columns, edge_width, flat_noise,
                                                     lattice_bend, square_contrast, window_measures)
from aicalib_tf.detect.detection import Detection
from aicalib_tf.detect.pipeline import detect_corners
from aicalib_tf.detect.warm import synthetic_board

PATTERN = (9, 6)


def _noisy(img: np.ndarray, sigma: float, seed: int = 0, contrast: float = 1.0) -> np.ndarray:
    """img (uint8) with its contrast scaled about mid-grey and Gaussian noise of ``sigma`` grey levels."""
    rng = np.random.default_rng(seed)
    out = 128.0 + contrast * (img.astype(np.float64) - 128.0) + rng.normal(0.0, sigma, img.shape)
    return np.clip(np.round(out), 0, 255).astype(np.uint8)


@pytest.fixture(scope="module")
def board():
    return synthetic_board(PATTERN, square=30, angle=7.0)


def test_a_detected_board_carries_one_positive_sigma_per_corner(board):
    det = detect_corners(board, PATTERN)
    assert det.complete
    assert det.sigmas.dtype == np.float32 and det.sigmas.shape == (len(det.corners),)
    assert np.all(np.isfinite(det.sigmas)) and np.all(det.sigmas > 0)


def test_sigma_grows_with_noise_and_with_lower_contrast(board):
    clean = detect_corners(_noisy(board, 1.0), PATTERN).sigmas
    noisy = detect_corners(_noisy(board, 30.0), PATTERN).sigmas
    faint = detect_corners(_noisy(board, 1.0, contrast=0.2), PATTERN).sigmas
    assert np.median(noisy) > 4 * np.median(clean)
    assert np.median(faint) > 1.5 * np.median(clean)


def _true_corners(square: int = 30, angle: float = 7.0, size=(640, 480)) -> np.ndarray:
    """synthetic_board's inner corners (cols·rows, 2) px, row by row: the paper's corners mapped as it maps them."""
    import cv2

    cols, rows = PATTERN
    width, height = (cols + 3) * square, (rows + 3) * square
    M = cv2.getRotationMatrix2D((width / 2, height / 2), angle, 1.0)
    M[:, 2] += (size[0] / 2 - width / 2, size[1] / 2 - height / 2)
    paper = np.array([((c + 2) * square - 0.5, (r + 2) * square - 0.5) for r in range(rows) for c in range(cols)])
    return paper @ M[:, :2].T + M[:, 2]


@pytest.mark.parametrize("noise, contrast", [(1.0, 1.0), (30.0, 1.0), (1.0, 0.2)])
def test_sigma_predicts_the_measured_error_on_a_board_of_known_corners(board, noise, contrast):
    truth = _true_corners()
    err, sig = [], []
    for seed in range(4):
        det = detect_corners(_noisy(board, noise, seed=seed, contrast=contrast), PATTERN)
        d = det.corners[:, None, :] - truth[None]
        err.append(d[np.arange(len(d)), np.argmin(np.einsum("nmk,nmk->nm", d, d), axis=1)])
        sig.append(det.sigmas)
    ratio = np.sqrt(np.mean(np.concatenate(err) ** 2)) / np.sqrt(np.mean(np.concatenate(sig) ** 2))
    assert 0.7 < ratio < 1.45  # RMS error per axis over RMS σ


def test_a_board_found_nowhere_keeps_no_sigmas():
    det = detect_corners(np.full((120, 160), 128, np.uint8), PATTERN)
    assert not det.found and det.sigmas is None
    empty = Detection(np.zeros((0, 2), np.float32), np.zeros((0, 2), np.int32), np.zeros(0, np.float32), PATTERN, False, (4, 4))
    assert cs.with_sigmas(empty, lambda *box: np.zeros((4, 4), np.float32)) is empty


def _junction(size: int = 41, centre=(20.0, 20.0), angle: float = 0.3) -> np.ndarray:
    """An X-junction of two lines through ``centre`` (px), black/white 0.2/0.8, sharp."""
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    u, v = x - centre[0], y - centre[1]
    a = np.cos(angle) * u + np.sin(angle) * v
    b = -np.sin(angle) * u + np.cos(angle) * v
    return np.where(a * b > 0, 0.8, 0.2).astype(np.float32)


def test_window_measures_of_a_point_symmetric_junction_have_no_odd_part():
    fits, weights = cs._operators()
    img = _junction()
    got = window_measures(img, np.array([[20.0, 20.0]]), np.array([3]), fits, weights)[0]
    odd, odd_median, even, residual, curvature, smoothed = got
    assert odd < 1e-6 and odd_median < 1e-6 and smoothed < 1e-6
    assert 0.2 < even < 0.35 and residual > 0 and curvature > 0
    stronger = window_measures(0.5 + 1.5 * (img - 0.5), np.array([[20.0, 20.0]]), np.array([3]), fits, weights)[0]
    np.testing.assert_allclose(stronger[[2, 3, 4]], 1.5 * got[[2, 3, 4]], rtol=1e-6)  # contrast, residual, curvature: grey levels
    moved = window_measures(img, np.array([[21.0, 20.0]]), np.array([3]), fits, weights)[0]
    assert moved[0] > 0.05  # a px off the centre, the window is far from point-symmetric


def test_lattice_bend_is_zero_on_a_straight_lattice_and_the_second_difference_otherwise():
    ids = np.array([(c, r) for r in range(3) for c in range(4)], np.int64)
    pts = ids.astype(np.float64) * 10.0
    bend = lattice_bend(pts, ids)
    assert np.all(bend[[5, 6]] == 0)  # the two inner corners
    assert np.all(bend[[0, 3, 8, 11]] == -1)  # the four outer corners have no row or column through them
    pts[5] += [0.0, 0.3]  # (1, 1) moved 0.3 px along y: both second differences through it are 2 · 0.3
    bend = lattice_bend(pts, ids)
    assert bend[5] == pytest.approx(0.6) and bend[6] == pytest.approx(0.15)  # (2, 1): its row 0.3, its column 0


def test_design_columns_take_the_boards_medians_and_the_usual_bend_where_a_corner_has_none():
    measures = np.array([[0.02, 0.01, 0.2, 0.05, 0.1, 0.01], [0.02, 0.04, 0.2, 0.05, 0.1, 0.01],
                         [0.08, 0.01, 0.1, 0.05, 0.2, 0.04]])
    width = np.array([1.0, 4.0, 3.0])
    axes = np.array([[10.0, 10.0], [10.0, -1.0], [5.0, 10.0]])  # the second has no neighbour along its rows' axis
    x = design_columns(measures, np.array([0.1, -1.0, 0.3]), np.full(3, 10.0), np.array([1.0, 0.0, 0.5]), 0.05, 1e-6, 0.004, 1.5,
                       width, axes)
    nb = cs.BOARD_COLUMNS
    assert x.shape == (3, len(cs.COLUMNS)) and np.all(x[:, :nb - 1] == x[0, :nb - 1])  # the board's columns: one row
    noise = np.log(0.01)  # the median odd_median
    n = noise - np.log([0.2, 0.2, 0.1])
    np.testing.assert_allclose(x[0, 0], np.median(n))
    np.testing.assert_allclose(x[:, nb], n - np.median(n))
    np.testing.assert_allclose(x[:, nb + 1], np.log([0.01, 0.04, 0.01]) - noise)
    np.testing.assert_allclose(x[0, 2], np.median(np.log([0.02, 0.02, 0.08])) - noise)  # the board's impulsiveness
    bend = np.log([0.1, 0.2, 0.3]) - np.log(10.0)  # (0.1 + 0.3) / 2 for the second
    np.testing.assert_allclose(x[0, 3], np.median(bend))
    np.testing.assert_allclose(x[:, nb + 4], bend - np.median(bend))
    np.testing.assert_allclose(x[:, nb + 5], np.log([1.0, 0.05, 0.5]) - np.log(0.5))
    np.testing.assert_allclose(x[0, 5], x[0, 0] ** 2)
    np.testing.assert_allclose(x[:, nb + 6], np.log([0.5, 0.5, 2.0]) - np.log(0.5))  # curvature over contrast
    np.testing.assert_allclose(x[0, 15], np.log(0.004) - np.median(np.log([0.2, 0.2, 0.1])))  # flat noise / contrast
    np.testing.assert_allclose(x[0, 16], noise - np.log(0.004))  # the window's noise over the flat noise
    np.testing.assert_allclose(x[0, 17], np.log(1.5))  # blockiness
    smooth = np.log([0.01, 0.01, 0.04]) - np.log([0.02, 0.02, 0.08])  # smoothed over raw asymmetry
    np.testing.assert_allclose(x[0, 18], np.median(smooth))
    np.testing.assert_allclose(x[:, nb + 8], smooth - np.median(smooth))
    np.testing.assert_allclose(x[:, nb + 9], [0.0, np.log(4.0) - 0.5, 0.0])  # own asymmetry beyond e^0.5 the board's
    np.testing.assert_allclose(x[0, 14], np.log(3.0))  # the median edge width, px
    # each corner's blur reach: (3 px / its nearer neighbour along each axis, or its spacing)² beyond the knot, summed
    np.testing.assert_allclose(x[:, 19], [2 * (0.09 - SPREAD_KNOT), 2 * (0.09 - SPREAD_KNOT), 0.36 + 0.09 - 2 * SPREAD_KNOT])
    np.testing.assert_allclose(x[:, cs.FOREIGN_COLUMN], 2 * np.log([0.1, 0.1, 0.8]))  # log(odd² / even²)
    no_square = design_columns(measures, np.array([0.1, -1.0, 0.3]), np.full(3, 10.0), np.ones(3), 0.05, 1e-6, -1.0, 1.0,
                               width, axes)
    np.testing.assert_allclose(no_square[0, 16], -0.95)  # no flat noise measured: the window's, as white noise


def test_axis_spacing_is_the_nearer_neighbours_distance_along_each_lattice_axis():
    ids = np.array([(0, 0), (1, 0), (2, 0), (0, 1)], np.int64)
    pts = np.array([(0.0, 0.0), (10.0, 0.0), (16.0, 0.0), (0.0, 12.0)])
    np.testing.assert_allclose(axis_spacing(pts, ids), [[10.0, 12.0], [6.0, -1.0], [6.0, -1.0], [-1.0, 12.0]])


def test_an_objects_edge_beside_a_corner_lifts_its_sigma_and_a_shadows_edge_does_not(board):
    """An edge that replaces the pattern near a corner leaves asymmetry that no shadow edge explains: the corner's
    foreign edge amplitude grows, and its σ with it; a shadow's straight edge across another corner adds none."""
    det = detect_corners(board, PATTERN)
    pts, k, j = det.corners.astype(np.float64), 20, 31
    img = _noisy(board, 2.0).astype(np.float64)
    x0, y0 = np.round(pts[k]).astype(int)
    img[y0 + 2:y0 + 12, x0 - 10:x0 + 10] = 90.0  # an object's grey edge 2 px below corner k
    yy, xx = np.mgrid[0:img.shape[0], 0:img.shape[1]]
    img[(xx - pts[j, 0]) + 0.3 * (yy - pts[j, 1]) > 1.5] *= 0.5  # a shadow edge 1.5 px beside corner j
    img = np.clip(np.round(img), 0, 255).astype(np.uint8)
    x = cs.design(img, pts, det.ids, det.scores)
    amp = x[:, cs.FOREIGN_COLUMN]
    assert amp[k] > 0.3 and amp[j] < 0.1 * amp[k] and np.sum(amp > 0) <= 3
    plain = cs.design(_noisy(board, 2.0), pts, det.ids, det.scores)
    assert np.all(plain[:, cs.FOREIGN_COLUMN] == 0)
    sig = cs.sigma_from_design(x)
    assert sig[k] > 3 * np.median(sig)
    region = lambda x0, y0, x1, y1: img[y0:y1, x0:x1].astype(np.float32) / 255.0  # noqa: E731
    whole = cs.board_sigmas(region, pts, det.ids, det.scores, (img.shape[1], img.shape[0]), own=True)
    gate = cs.board_sigmas(region, pts, det.ids, det.scores, (img.shape[1], img.shape[0]))  # the detector's gates: without it
    assert whole[k] == pytest.approx(sig[k], rel=1e-3) and gate[k] < 0.5 * whole[k]


def test_sigma_inside_a_board_spreads_less_than_between_noise_levels(board):
    """The corner's part only orders corners inside an image: its spread stays far below the board's part."""
    quiet = detect_corners(_noisy(board, 2.0), PATTERN).sigmas
    noisy = detect_corners(_noisy(board, 30.0, seed=1), PATTERN).sigmas
    for s in (quiet, noisy):
        assert np.percentile(s, 90) / np.percentile(s, 10) < 2.0
    assert np.median(noisy) > 4 * np.median(quiet)


def test_the_model_clips_its_columns_to_the_fitted_range():
    x = np.zeros((2, len(cs.COLUMNS)))
    x[1, 0] = 50.0  # far beyond the range fitted
    top = x.copy()
    top[1, 0] = cs.HIGH[0]
    np.testing.assert_array_equal(cs.sigma_from_design(x)[1], cs.sigma_from_design(top)[1])
    assert cs.sigma_from_design(x).dtype == np.float32


def test_the_opencv_detectors_give_no_sigmas_and_the_cnn_detector_does(board):
    from aicalib_tf.calib.workflow import make_detector

    cnn, cv = make_detector("cnn", PATTERN), make_detector("opencv", PATTERN)
    corners, _ = cnn(board)
    assert cnn.sigmas is not None and len(cnn.sigmas) == len(corners)
    assert cv(board) is not None and cv.sigmas is None


def test_a_uint8_frame_and_its_float_grey_give_the_same_columns(board):
    det = detect_corners(board, PATTERN)
    grey = board.astype(np.float32) / 255.0
    np.testing.assert_allclose(cs.design(board, det.corners, det.ids, det.scores),
                               cs.design(grey, det.corners, det.ids, det.scores), atol=1e-4)


def _grid(cols: int = 5, rows: int = 4, square: float = 16.0, origin=(20.3, 18.6)):
    """A straight lattice of points (cols·rows, 2) px and their ids (col, row)."""
    ids = np.array([(c, r) for r in range(rows) for c in range(cols)], np.int64)
    return origin + ids.astype(np.float64) * square, ids


def test_flat_noise_reads_the_noise_in_the_squares_middles_blind_to_shading():
    rng = np.random.default_rng(3)
    pts, ids = _grid()
    y, x = np.mgrid[0:120, 0:140].astype(np.float64)
    shaded = 60.0 + 0.4 * x + 0.2 * y  # a linear shading: no second difference
    img = (shaded + rng.normal(0.0, 4.0, shaded.shape)).astype(np.float32)
    got = flat_noise(img, pts, ids, 1.0)
    assert got == pytest.approx(np.sqrt(16.0 + 1 / 12), rel=0.15)  # σ 4, and 8-bit rounding's floor
    assert flat_noise(shaded.astype(np.float32), pts, ids, 1.0) == pytest.approx(np.sqrt(1 / 12), rel=1e-3)
    line = ids[:, 1] == 0  # one row of corners: no square has all four
    assert flat_noise(img, pts[line], ids[line], 1.0) == -1.0


def test_blockiness_finds_jpeg_blocks_where_the_image_has_them():
    import cv2

    board = synthetic_board(PATTERN, square=30, angle=7.0)
    noisy = _noisy(board, 3.0)
    det = detect_corners(noisy, PATTERN)
    pts = det.corners.astype(np.float64)
    jpeg = cv2.imdecode(cv2.imencode(".jpg", noisy, [cv2.IMWRITE_JPEG_QUALITY, 10])[1], cv2.IMREAD_GRAYSCALE)
    plain = blockiness(noisy, pts, 0, 0, 1e-3)
    blocky = blockiness(jpeg, pts, 0, 0, 1e-3)
    assert 0.9 < plain < 1.1 and blocky > 1.3
    # a part of the image cut 3 px in: the blocks start 3 px earlier in its own pixels; with its origin given, the same
    part = np.ascontiguousarray(jpeg[3:, 3:])
    assert blockiness(part, pts - 3.0, 3, 3, 1e-3) == pytest.approx(blocky)
    assert blockiness(part, pts - 3.0, 0, 0, 1e-3) < 0.9 * blocky


def test_the_smoothed_asymmetry_is_small_for_white_noise_and_near_whole_for_a_smooth_slope():
    fits, weights = cs._operators()
    rng = np.random.default_rng(5)
    pts = np.array([[10.0 + 9 * i, 12.0 + 9 * j] for i in range(8) for j in range(8)])
    noise = rng.normal(0.5, 0.05, (90, 90)).astype(np.float32)
    got = window_measures(noise, pts, np.full(len(pts), 3), fits, weights)
    ratio = np.median(got[:, 5] / got[:, 0])
    assert 0.25 < ratio < 0.5  # white noise: [1 2 1]² keeps about 0.4 of its asymmetry
    y, x = np.mgrid[0:90, 0:90].astype(np.float64)
    slope = (0.5 + 0.01 * x + 0.004 * y).astype(np.float32)  # odd about every point: a smooth asymmetry
    got = window_measures(slope, pts, np.full(len(pts), 3), fits, weights)
    np.testing.assert_allclose(got[:, 5] / got[:, 0], 1.0, rtol=1e-6)


def test_sigma_grows_with_jpeg_compression_of_the_same_board(board):
    import cv2

    noisy = _noisy(board, 2.0)
    sig = {}
    for q in (95, 8):
        img = cv2.imdecode(cv2.imencode(".jpg", noisy, [cv2.IMWRITE_JPEG_QUALITY, q])[1], cv2.IMREAD_GRAYSCALE)
        sig[q] = np.median(detect_corners(img, PATTERN).sigmas)
    assert sig[8] > 2 * sig[95]


def test_edge_width_inverts_the_contrast_a_gaussian_blur_leaves_in_the_window():
    s = 2.0  # the radius-3 window's Gaussian σ
    for blur in (0.5, 1.0, 3.0, 6.0):
        kept = (2 / np.pi) * np.arcsin(s * s / (s * s + blur * blur))  # even over C/2 of an X-junction blurred by σ
        got = edge_width(np.array([0.5 * 0.6 * kept]), np.array([3]), 0.6, 0.0)
        assert got[0] == pytest.approx(blur, rel=1e-6)
        noisy = np.hypot(0.5 * 0.6 * kept, WHITE_EVEN * 0.01)  # the noise's share of the contrast comes out
        assert edge_width(np.array([noisy]), np.array([3]), 0.6, 0.01)[0] == pytest.approx(blur, rel=1e-6)
    sharp = edge_width(np.array([0.3]), np.array([3]), -1.0, 0.0)  # no contrast measured: a sharp render's
    assert 0.7 < sharp[0] < 1.1


def test_white_noise_alone_has_the_symmetric_part_the_edge_width_takes_out():
    fits, weights = cs._operators()
    rng = np.random.default_rng(7)
    img = rng.normal(0.5, 0.05, (200, 200)).astype(np.float32)
    pts = rng.uniform(10.0, 190.0, (300, 2))
    for r in (2, 3):
        m = window_measures(img, pts, np.full(len(pts), r), fits, weights)
        ratio = np.sqrt(np.mean(m[:, 2] ** 2)) / np.exp(np.median(np.log(m[:, 1])))
        assert ratio == pytest.approx(WHITE_EVEN, rel=0.05)


def test_the_squares_contrast_and_the_edge_width_follow_a_blurred_board():
    import cv2

    board = synthetic_board(PATTERN, square=30, angle=7.0)
    det = detect_corners(board, PATTERN)
    pts, ids = det.corners.astype(np.float64), det.ids.astype(np.int64)
    assert square_contrast(board, pts, ids) == pytest.approx(255.0, abs=2.0)
    fits, weights = cs._operators()
    widths = {}
    for blur in (0.0, 3.0):
        img = cv2.GaussianBlur(board, (0, 0), blur) if blur else board
        even = window_measures(img, pts, np.full(len(pts), 3), fits, weights)[:, 2]
        widths[blur] = np.median(edge_width(even, np.full(len(pts), 3), square_contrast(img, pts, ids), 0.0))
    assert widths[0.0] < 1.2  # the rotated board's own anti-aliasing
    # the closed form takes an untruncated window: on the 7×7 one it reads a 3 px blur about a fifth high
    assert np.hypot(3.0, widths[0.0]) < widths[3.0] < 1.3 * np.hypot(3.0, widths[0.0])
    line = ids[:, 1] == 0  # one row of corners: no square with all four
    assert square_contrast(board, pts[line], ids[line]) == -1.0


def test_a_board_of_close_corners_takes_white_noises_smoothed_asymmetry():
    """Closer than SMOOTHED_MIN_SPACING the smoothed window reaches the next squares' edges: the board's column is white noise's."""
    ids = np.array([(c, r) for r in range(PATTERN[1]) for c in range(PATTERN[0])], np.int64)
    k = cs.COLUMNS.index("smoothed/raw asymmetry")
    for square, close in ((8, True), (30, False)):
        img = _noisy(synthetic_board(PATTERN, square=square, angle=7.0), 2.0)
        x = cs.design(img, _true_corners(square), ids, np.ones(len(ids)))
        assert np.all(x[:, k] == cs.WHITE_SMOOTHED) == close
        assert np.all(x[:, k] == x[0, k])  # a board's column, the same for all its corners


def test_a_corner_sigma_is_at_least_the_bound_of_its_contrast_over_the_noise():
    from aicalib_tf.detect.corners.contrast import board_contrast
    from tests.detect.corners.test_contrast import _board

    for contrast, noise, raised in ((60.0, 2.0, False), (6.0, 5.0, True)):
        img, pts, ids = _board(contrast, noise)
        img = (np.clip(np.round(img), 0, 255) / 255.0).astype(np.float32)

        def region(x0, y0, x1, y1):
            return img[y0:y1, x0:x1]

        scores = np.ones(len(pts))
        model = cs.sigma_from_design(cs.board_design(region, pts, ids, scores, (240, 240)))
        bound = board_contrast(region, pts, ids, (240, 240))["bound"]
        own = cs.board_sigmas(region, pts, ids, scores, (240, 240), own=True)
        np.testing.assert_allclose(own, np.maximum(model, bound), rtol=1e-6)
        # a clear board keeps the model's σ; at cnr 1.2 the bound (about 0.5 px) lifts most corners above it
        assert (np.mean(own > model) > 0.5) == raised
        np.testing.assert_array_equal(cs.board_sigmas(region, pts, ids, scores, (240, 240)),  # the gates': the model's
                                      cs.sigma_from_design(_gates_design(region, pts, ids, scores)))


def _gates_design(region, pts, ids, scores):
    """board_design as the detector's gates take it: no foreign edge, the board's median blur reach for all."""
    x = cs.board_design(region, pts, ids, scores, (240, 240), foreign=False)
    x[:, cs._REACH_COLUMN] = np.median(x[:, cs._REACH_COLUMN])
    return x
