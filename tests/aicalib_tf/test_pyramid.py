"""Coarse-to-fine detection on large images (aicalib_tf.pyramid and its use in detect_corners)."""

import numpy as np
import pytest

from aicalib_tf.pyramid import downscale, refine_full, scales, to_full
from data_gen import make_sample


@pytest.mark.parametrize("size, want", [((640, 480), [1]), ((1599, 1200), [1]), ((1600, 1200), [2, 1]),
                                        ((1920, 1080), [2, 1]), ((8000, 6000), [8, 4, 2, 1]), ((32, 32), [1])])
def test_scales_keep_at_least_min_side_pixels(size, want):
    assert scales(*size) == want


def test_downscale_is_the_block_mean_and_to_full_maps_block_centres():
    rng = np.random.default_rng(0)
    g = rng.random((37, 54)).astype(np.float32)
    small = downscale(g, 4)
    assert small.shape == (9, 13)
    np.testing.assert_allclose(small[2, 3], g[8:12, 12:16].mean(), atol=1e-6)
    assert downscale(g, 1) is not None and np.array_equal(downscale(g, 1), g)
    # block (i, j) = (2, 3) holds full pixels x 12..15, y 8..11: centre (13.5, 9.5)
    np.testing.assert_allclose(to_full(np.array([[3.0, 2.0]]), 4), [[13.5, 9.5]])
    np.testing.assert_allclose(to_full(np.array([[3.0, 2.0]]), 1), [[3.0, 2.0]])


def test_refine_full_brings_coarse_corners_back_to_subpixel_accuracy():
    s = make_sample("clean", 4, 0, size=(1920, 1080), pattern=(9, 6))
    gray = s.image.astype(np.float32) / 255.0
    coarse = s.corners + np.random.default_rng(1).uniform(-0.8, 0.8, s.corners.shape)  # a 2x scale's error
    out = refine_full(gray, coarse)
    err = np.linalg.norm(out - s.corners, axis=1)
    assert np.median(err) < 0.03 and err.max() < 0.2


pytest.importorskip("keras")


def test_a_large_image_is_detected_at_half_scale_as_accurately_as_at_full(monkeypatch):
    import aicalib_tf.detect as detect

    s = make_sample("clean", 4, 0, size=(1920, 1080), pattern=(9, 6))
    tried = []
    real = detect._detect_at
    monkeypatch.setattr(detect, "_detect_at", lambda g, *a: tried.append(g.shape) or real(g, *a))
    det = detect.detect_corners(s.image, (9, 6))
    assert det.complete and det.image_size == (1920, 1080)
    assert tried == [(540, 960)]  # found at the coarse scale: full size never searched
    from aicalib_tf.metrics import board_detection_outcome

    outcome, err = board_detection_outcome(det.corners, s.corners, (9, 6))
    assert outcome == "hit" and np.median(err) < 0.02


def test_a_board_too_small_for_the_coarse_scale_is_found_at_full_size(monkeypatch):
    import aicalib_tf.detect as detect

    s = make_sample("clean", 0, 0, size=(640, 480), pattern=(9, 6))
    small = detect.detect_corners(s.image, (9, 6))
    assert small.complete
    # the 640×480 image shrunk to squares of ~5 px inside a plain 1920×1080 frame
    import cv2

    img = cv2.resize(s.image, (320, 240), interpolation=cv2.INTER_AREA)
    frame = np.full((1080, 1920), int(np.median(img)), np.uint8)
    frame[400:640, 800:1120] = img
    tried = []
    real = detect._detect_at
    monkeypatch.setattr(detect, "_detect_at", lambda g, *a: tried.append(g.shape) or real(g, *a))
    det = detect.detect_corners(frame, (9, 6))
    assert tried == [(540, 960), (1080, 1920)]
    assert det.complete
    truth = (s.corners + 0.5) / 2 - 0.5 + [800, 400]
    from aicalib_tf.metrics import board_detection_outcome

    assert board_detection_outcome(det.corners, truth, (9, 6))[0] == "hit"
