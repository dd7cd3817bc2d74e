"""Photos of any size in bounded memory: large frames through the coarse-to-fine path, under a limit.

Every detection here runs in a child process limited to 2 GiB of address space
(:class:`tests.detect.bounded.BoundedDetector`), about 1 GB more than the detector's peak on a
48 MP photo: a dense N×M matrix or a network run on the whole of a large frame (once 26 GiB, or
"XNNPack delegate failed to reshape" at 3–6.5 GB) fails the test instead of the machine.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from aicalib_tf.cnn.model import MODELS_DIR
from aicalib_tf.detect.pyramid import charuco_scales, refine_full, scales
from data_gen import make_sample
from tests.detect.bounded import BoundedDetector

pytestmark = pytest.mark.skipif(not (MODELS_DIR / "default.tflite").is_file(), reason="no shipped runtime model")


@pytest.fixture(scope="module")
def bounded():
    detector = BoundedDetector()
    yield detector
    detector.close()


@pytest.fixture(scope="module")
def board():
    """A sharp 9x6 board rendered at 1000x750 and its true corners."""
    s = make_sample("clean", 3, 0, size=(1000, 750), pattern=(9, 6))
    return s.image, s.corners


def _upscaled(img: np.ndarray, corners: np.ndarray, size: tuple[int, int]):
    """The image resized (bicubic) to ``size`` and its corners at the same places: x' = (x + 0.5)·k − 0.5."""
    k = size[0] / img.shape[1]
    return cv2.resize(img, size, interpolation=cv2.INTER_CUBIC), (corners + 0.5) * k - 0.5


def test_a_48_mp_photo_is_found_within_the_bound(bounded, board):
    img, truth = _upscaled(*board, (8000, 6000))
    det = bounded(img, (9, 6))
    assert det.complete and det.image_size == (8000, 6000)
    err = np.linalg.norm(det.corners - truth, axis=1)
    assert np.median(err) < 2.0 and err.max() < 8.0  # 8 px of the photo are 1 px of the render


def test_a_24_mp_photo_without_a_pattern_never_runs_the_network_on_all_of_it(bounded, board):
    """Without a pattern every scale was searched, full size included: 'XNNPack delegate failed to reshape'."""
    img, _ = _upscaled(*board, (5800, 4350))
    det = bounded(img, None)
    assert det.complete and det.pattern_size in ((9, 6), (6, 9))


def test_an_11000_px_frame_without_a_board_ends_within_the_bound(bounded):
    """11000×11000 frames stopped with 'XNNPack delegate failed to reshape' at 6.5 GB."""
    ramp = np.linspace(0, 255, 11000).astype(np.uint8)
    img = np.broadcast_to(ramp[None, :], (11000, 11000)).copy()
    det = bounded(img, (9, 6))
    assert not det.complete and det.image_size == (11000, 11000)


def test_scales_searched_whole_stay_under_16_mp():
    for w, h in [(8000, 6000), (11000, 11000), (12000, 9000), (40000, 100)]:
        f = scales(w, h)[-1]
        assert (w // f) * (h // f) <= 16_000_000 or f == scales(w, h)[0]
        assert charuco_scales(w, h)[-1] == f
    assert charuco_scales(2000, 1500) == [1]


def test_refine_full_in_windows_gives_the_same_corners(board, monkeypatch):
    """A board refined in windows about its corners (a large photo): the corners refined in one region."""
    from aicalib_tf.detect import pyramid

    img, truth = _upscaled(*board, (2000, 1500))
    gray = img.astype(np.float32) / 255
    start = (truth + np.float32(0.7)).astype(np.float32)
    whole = refine_full(gray, start)
    monkeypatch.setattr(pyramid, "MAX_REFINE_PIXELS", 10_000)
    monkeypatch.setattr(pyramid, "REFINE_TILE", 256)
    assert len(pyramid._refine_groups(start, 13, (2000, 1500))) > 4
    tiled = refine_full(gray, start)
    assert whole[1].all() and np.array_equal(whole[1], tiled[1])
    assert np.abs(whole[0] - tiled[0]).max() < 1e-3  # float32 rounding of each window's offset


@pytest.mark.parametrize("dtype", [np.uint8, np.float32])
def test_the_network_in_windows_gives_the_single_runs_map(monkeypatch, board, dtype):
    """Large images run the network in windows (the whole image's statistics, 32 px of context): the same map."""
    from aicalib_tf.cnn import inference
    from aicalib_tf.cnn.model import load_model

    net = load_model("default")
    img = np.ascontiguousarray(board[0][:743, :998])  # sides that are not multiples of 4: the edge padding
    img = img if dtype == np.uint8 else img.astype(np.float32) / 255
    whole = inference.corner_map(net, img)
    monkeypatch.setattr(inference, "MAX_RUN_PIXELS", 10_000)
    monkeypatch.setattr(inference, "TILE", 256)
    assert len(inference._windows(744)) > 1
    tiled = inference.corner_map(net, img)
    assert tiled.shape == whole.shape and np.array_equal(tiled, whole)


def test_a_photo_whose_every_board_is_refused_on_the_full_image_says_none_was_found(board, monkeypatch):
    """On 8000x6000 every searched scale is reduced; when the full-image check refuses each scale's board the
    answer is no board with a reason, never an error."""
    from aicalib_tf.detect import pipeline
    from aicalib_tf.detect.detection import NO_MATCH

    monkeypatch.setattr(pipeline, "object_in_front_at", lambda *args: True)
    img, _ = _upscaled(*board, (8000, 6000))
    det = pipeline.detect_corners(img, (9, 6))
    assert not det.found and det.image_size == (8000, 6000) and det.reason == NO_MATCH
