"""The quick passes (aicalib_tf.detect.pyramid.quick_scales) and tracking through frames (aicalib_tf.detect.track)."""

import numpy as np
import pytest

from aicalib_tf.detect import pipeline
from aicalib_tf.detect.pipeline import detect_corners
from aicalib_tf.detect.pyramid import quick_scales
from aicalib_tf.detect.track import Tracker, follow, lattice_bent, search_box
from aicalib_tf.detect.warm import synthetic_board

PATTERN = (9, 6)


@pytest.mark.parametrize("size, want", [((640, 480), [2]), ((1920, 1080), [8, 4]), ((1280, 720), [4, 2]),
                                        ((479, 479), []), ((320, 240), []), ((1, 1), []), ((8000, 1), []),
                                        ((640, 15), []), ((8000, 6000), [32, 16])])
def test_quick_scales_go_coarser_than_the_coarsest_scale_while_enough_pixels_are_left(size, want):
    assert quick_scales(*size) == want


def _scales_used(monkeypatch, image, quick=True):
    """detect_corners on image, and the factors it downscaled by (the quick pass off when not quick)."""
    seen = []
    reduced = pipeline.Frame.reduced
    monkeypatch.setattr(pipeline.Frame, "reduced", lambda frame, f: seen.append(f) or reduced(frame, f))
    if not quick:
        monkeypatch.setattr(pipeline, "quick_scales", lambda w, h: [])
    det = detect_corners(image, PATTERN)
    monkeypatch.undo()
    return det, seen


def test_the_quick_pass_gives_the_full_passs_corners_on_large_squares(monkeypatch):
    img = synthetic_board(PATTERN, square=36, angle=9.0)
    fast, seen = _scales_used(monkeypatch, img)
    full, seen_full = _scales_used(monkeypatch, img, quick=False)
    assert seen == [2] and seen_full == [1]
    assert fast.complete and full.complete and fast.image_size == (640, 480)
    np.testing.assert_array_equal(fast.ids, full.ids)
    assert np.abs(fast.corners - full.corners).max() < 0.05


def test_the_quick_pass_falls_back_to_full_size_on_small_squares(monkeypatch):
    img = synthetic_board(PATTERN, square=6, angle=5.0)  # 3 px squares at half size
    fast, seen = _scales_used(monkeypatch, img)
    full, _ = _scales_used(monkeypatch, img, quick=False)
    assert seen == [2, 1]
    assert fast.complete and full.complete
    np.testing.assert_array_equal(fast.corners, full.corners)


@pytest.mark.parametrize("size", [(643, 487), (481, 641)])
def test_the_quick_pass_on_odd_sizes_maps_corners_back_exactly(monkeypatch, size):
    img = synthetic_board(PATTERN, square=30, size=size, angle=20.0)
    fast, seen = _scales_used(monkeypatch, img)
    full, _ = _scales_used(monkeypatch, img, quick=False)
    assert seen == [2] and fast.complete and fast.image_size == size
    assert np.abs(fast.corners - full.corners).max() < 0.05


@pytest.mark.parametrize("shape", [(1, 1), (2, 641), (479, 9), (17, 640), (480, 640), (1, 1, 3), (3, 1700, 4),
                                   (15, 1920, 3), (1080, 7, 3)])
def test_the_quick_pass_on_tiny_or_empty_images_is_no_board_not_a_crash(shape):
    for pattern in (PATTERN, (3, 3)):  # grey and colour frames: their block means come from the bytes
        det = detect_corners(np.full(shape, 128, np.uint8), pattern)
        assert not det.found and det.image_size == shape[1::-1] and det.reason


def test_a_colour_frame_gives_the_board_its_grey_gives():
    import cv2

    grey = synthetic_board(PATTERN, square=30, size=(1920, 1080), angle=12.0)
    colour = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
    a, b = detect_corners(grey, PATTERN), detect_corners(colour, PATTERN)
    assert a.complete and b.complete
    np.testing.assert_allclose(a.corners, b.corners, atol=1e-4)


def test_the_quick_pass_keeps_partial_boards_to_the_full_size_search(monkeypatch):
    img = synthetic_board(PATTERN, square=36, shift=(230.0, 0.0))  # cut by the frame
    fast, seen = _scales_used(monkeypatch, img)
    full, _ = _scales_used(monkeypatch, img, quick=False)
    assert seen == [2, 1] and fast.found and not fast.complete
    np.testing.assert_array_equal(fast.ids, full.ids)
    np.testing.assert_array_equal(fast.corners, full.corners)


def _frames(shifts, size=(1280, 720)):
    return [synthetic_board(PATTERN, square=40, size=size, angle=10.0 + 0.5 * k, shift=s) for k, s in enumerate(shifts)]


def test_the_tracker_follows_a_moving_board_and_finds_it_again_after_it_left():
    shifts = [(-200.0 + 12 * k, 5.0 * k) for k in range(5)]
    frames = _frames(shifts)
    frames.append(np.full((720, 1280), 200, np.uint8))  # the board has left
    frames += _frames([(100.0, -40.0), (108.0, -36.0), (116.0, -32.0)])
    track = Tracker(PATTERN)
    how = []
    for img in frames:
        det = track(img)
        how.append(track.how)
        want = detect_corners(img, PATTERN)
        assert det.complete == want.complete and det.image_size == (1280, 720)
        if det.complete:
            np.testing.assert_array_equal(det.ids, want.ids)
            assert np.abs(det.corners - want.corners).max() < 0.05
    # a board's first move (no motion known yet) is 9 px: beyond the saddle fit's reach, so the region
    assert how[:5] == ["frame", "region", "follow", "follow", "follow"]
    assert how[5:] == ["", "frame", "region", "follow"]


def test_the_tracker_searches_the_region_when_the_board_jumps():
    a, b = _frames([(0.0, 0.0), (30.0, 25.0)])  # 30 px: too far for the saddle fit from where it was
    track = Tracker(PATTERN)
    assert track(a).complete and track(b).complete and track.how == "region"


@pytest.mark.parametrize("shape", [(1, 1), (5, 5), (7, 640), (480, 3)])
def test_tiny_frames_and_a_change_of_size_are_no_board_not_a_crash(shape):
    track = Tracker(PATTERN)
    assert track(synthetic_board(PATTERN, size=(640, 480))).complete
    det = track(np.zeros(shape, np.uint8))
    assert not det.found and det.image_size == shape[::-1] and track.how == ""


def test_a_region_of_less_than_8_px_is_none_and_corners_outside_are_not_followed():
    assert search_box(np.array([[0.0, 0.0]]), (1, 1), 0.0) is None
    assert search_box(np.array([[0.0, 0.0]]), (640, 480), 3.0) == (0, 0, 16, 16)
    assert search_box(np.zeros((0, 2)), (640, 480), 3.0) is None
    assert search_box(np.array([[np.nan, 1.0]]), (640, 480), 3.0) is None
    img = synthetic_board(PATTERN)
    corners = detect_corners(img, PATTERN).corners
    assert follow(img, corners - [0.0, 1000.0], PATTERN) is None
    assert follow(img[:1, :1], corners, PATTERN) is None


def test_a_board_whose_corners_slid_by_one_square_bends_its_lattice():
    img = synthetic_board(PATTERN, square=40, angle=0.0)
    corners = detect_corners(img, PATTERN).corners
    assert lattice_bent(corners, PATTERN) < 0.05
    slid = corners.copy()
    slid[13] = corners[14]  # one corner refined onto its neighbour
    assert lattice_bent(slid, PATTERN) > 0.9


def test_the_tracker_takes_colour_frames_and_paths(tmp_path):
    import cv2

    frames = [cv2.cvtColor(f, cv2.COLOR_GRAY2BGR) for f in _frames([(0.0, 0.0), (2.0, 1.0), (4.0, 2.0)], (640, 480))]
    cv2.imwrite(str(tmp_path / "f2.png"), frames[2])
    track = Tracker(PATTERN)
    got = [track(frames[0]), track(frames[1]), track(str(tmp_path / "f2.png"))]
    assert all(d.complete for d in got) and track.how == "follow"
    want = detect_corners(frames[2], PATTERN)
    assert np.abs(got[2].corners - want.corners).max() < 0.05


def _noisy(base: np.ndarray, sigma: float, seed: int) -> np.ndarray:
    """base (H, W) uint8 with Gaussian read noise of ``sigma`` grey levels."""
    noise = np.random.default_rng(seed).normal(0.0, sigma, base.shape)
    return np.clip(base + noise, 0, 255).astype(np.uint8)


def _background(shape) -> np.ndarray:
    """A textured (H, W) uint8 scene without a board: smooth blobs of grey."""
    import cv2

    rng = np.random.default_rng(0)
    return cv2.GaussianBlur(rng.uniform(40, 220, shape).astype(np.float32), (0, 0), 9).astype(np.uint8)


def test_a_scene_is_changed_by_a_small_board_entering_and_not_by_a_cameras_noise():
    from aicalib_tf.detect.track import STILL_LEVEL, scene_changed, scene_thumbnail

    base = _background((480, 640))
    a, b = (scene_thumbnail(_noisy(base, 8.0, s)) for s in (1, 2))  # heavy read noise, same scene
    assert not scene_changed(a, b)
    entered = base.copy()
    entered[:40, :40] = np.where((np.arange(40)[:, None] // 10 + np.arange(40)[None] // 10) % 2, 60, 180)
    assert scene_changed(a, scene_thumbnail(_noisy(entered, 8.0, 3)))  # a 40 px corner of a board
    assert scene_changed(a, scene_thumbnail(_noisy(base[:, :600], 8.0, 4)))  # another size
    dimmer = scene_thumbnail(np.clip(base.astype(int) - int(STILL_LEVEL) - 1, 0, 255).astype(np.uint8))
    assert scene_changed(scene_thumbnail(base), dimmer)  # the exposure moved
    float_frame = scene_thumbnail(base.astype(np.float32) / 255.0)
    assert np.abs(float_frame - scene_thumbnail(base)).max() < 0.01  # grey levels of 255 from any frame


def test_a_still_scene_without_a_board_is_searched_once_then_again_every_still_max_frames(monkeypatch):
    from aicalib_tf.detect import track as track_module
    from aicalib_tf.detect.track import STILL_MAX

    calls = []
    search = track_module.detect_corners
    monkeypatch.setattr(track_module, "detect_corners", lambda *a, **k: calls.append(1) or search(*a, **k))
    base = _background((480, 640))
    track = Tracker(PATTERN)
    hows = []
    for k in range(STILL_MAX + 3):
        det = track(_noisy(base, 3.0, k))
        hows.append(track.how)
        assert not det.found and det.image_size == (640, 480)
    assert hows == [""] + ["still"] * STILL_MAX + ["", "still"]
    assert len(calls) == 2
    board = synthetic_board(PATTERN, size=(640, 480))  # the board comes into view: searched at once
    assert track(board).complete and track.how == "frame" and len(calls) == 3
