"""Coarse-to-fine detection (aicalib_tf.detect.pyramid and its use in detect_corners: quick passes, then the scales)."""

import numpy as np
import pytest

from aicalib_tf.detect.pyramid import Frame, downscale, refine_full, scales, to_full
from aicalib_tf.io import as_gray_float
from data_gen import make_sample


@pytest.mark.parametrize("size, want", [((640, 480), [1]), ((1599, 1200), [1]), ((1600, 1200), [2, 1]),
                                        ((1920, 1080), [2, 1]), ((8000, 6000), [8, 4, 2]), ((5656, 4242), [4, 2]),
                                            ((4000, 4000), [4, 2, 1]), ((32, 32), [1])])
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
    out, ok = refine_full(gray, coarse)
    err = np.linalg.norm(out - s.corners, axis=1)
    assert ok.all() and np.median(err) < 0.03 and err.max() < 0.2
    flat = np.array([[5.0, 5.0], [60.0, 5.0]])  # no corner in the blank top-left of the frame
    out, ok = refine_full(np.zeros((100, 100), np.float32), flat)
    assert not ok.any() and np.array_equal(out, flat.astype(np.float32))


def test_downscale_of_a_side_shorter_than_the_factor_is_empty():
    # cv2.resize raised on the empty size: detect_corners crashed on an 8000×1 image
    assert downscale(np.zeros((1, 8000), np.float32), 8).shape == (0, 1000)
    assert downscale(np.zeros((8000, 7), np.float32), 8).shape == (1000, 0)


@pytest.mark.parametrize("shape", [(37, 54), (1080, 1920), (37, 54, 3), (40, 33, 4), (1, 8000), (8000, 7, 3)])
@pytest.mark.parametrize("factor", [2, 4, 8])
def test_downscale_of_uint8_pixels_is_the_block_mean_of_the_gates_grey(shape, factor):
    # the block means come straight from the bytes: the same grey levels as converting first
    a = np.random.default_rng(sum(shape) + factor).integers(0, 256, shape).astype(np.uint8)
    got, want = downscale(a, factor), downscale(as_gray_float(a), factor)
    assert got.dtype == np.float32 and got.shape == want.shape == (shape[0] // factor, shape[1] // factor)
    np.testing.assert_allclose(got, want, atol=1e-6, rtol=0)
    assert got.size == 0 or (got.min() >= 0.0 and got.max() <= 1.0)


@pytest.mark.parametrize("shape", [(480, 640), (37, 55), (2, 2), (40, 33, 3), (9, 7, 4)])
def test_the_half_size_loop_gives_the_exact_block_sums(shape):
    # f = 2 has its own loop: the same integer sums, the same scaling, bit for bit
    a = np.random.default_rng(sum(shape)).integers(0, 256, shape).astype(np.uint8)
    h, w = shape[0] // 2, shape[1] // 2
    blocks = a[: 2 * h, : 2 * w].reshape(h, 2, w, 2, -1).astype(np.int64).sum(axis=(1, 3))
    sums = blocks[..., 0] if a.ndim == 2 else 0.114 * blocks[..., 0] + 0.587 * blocks[..., 1] + 0.299 * blocks[..., 2]
    want = np.minimum(sums * (1.0 / (255.0 * 4)), 1.0).astype(np.float32)
    assert np.array_equal(downscale(a, 2), want)


@pytest.mark.parametrize("raw", [np.arange(7 * 9 * 3, dtype=np.uint8).reshape(7, 9, 3),
                                 np.linspace(0, 1, 63, dtype=np.float32).reshape(7, 9)])
def test_a_frames_region_is_that_region_of_the_whole_image_converted(raw):
    frame = Frame(raw)
    whole = as_gray_float(raw)
    assert frame.size == (9, 7)
    # OpenCV's colour conversion rounds a region's last pixels in another order: equal within 1e-7
    np.testing.assert_allclose(frame.region(2, 1, 8, 6), whole[1:6, 2:8], atol=1e-7, rtol=0)
    np.testing.assert_array_equal(frame.reduced(1), whole)
    np.testing.assert_array_equal(frame.region(2, 1, 8, 6), whole[1:6, 2:8])  # once converted whole, its region


pytest.importorskip("keras")


def test_a_large_uint8_frame_found_by_the_quick_pass_is_never_converted_whole(monkeypatch):
    import aicalib_tf.detect.pyramid as pyramid
    from aicalib_tf.detect.pipeline import detect_corners

    s = make_sample("clean", 4, 0, size=(1920, 1080), pattern=(9, 6))
    converted = []
    real = pyramid.as_gray_float
    monkeypatch.setattr(pyramid, "as_gray_float", lambda a: converted.append(a.shape[0] * a.shape[1]) or real(a))
    det = detect_corners(s.image, (9, 6))
    monkeypatch.undo()
    assert det.complete and converted and max(converted) < 0.25 * 1920 * 1080  # the board's region alone
    as_float = detect_corners(as_gray_float(s.image), (9, 6))  # converted whole first: the same board
    np.testing.assert_allclose(det.corners, as_float.corners, atol=1e-3)


@pytest.mark.parametrize("shape", [(1, 8000), (7, 8000), (8000, 1)])
def test_a_long_thin_image_is_no_board_not_a_crash(shape):
    from aicalib_tf.detect.pipeline import detect_corners

    for pattern in (None, (9, 6)):
        det = detect_corners(np.zeros(shape, np.uint8), pattern)
        assert not det.found and det.image_size == shape[::-1]


def _tilted_board(cols, rows, quad, size, square=40):
    """A (cols+1)×(rows+1)-square board warped onto quad ((4, 2) px, outer corners TL TR BR BL) on
    grey paper in a (width, height) uint8 image, and its inner corners (cols·rows, 2) px."""
    import cv2

    sq_w, sq_h = (cols + 1) * square, (rows + 1) * square
    yy, xx = np.mgrid[0:sq_h, 0:sq_w]
    ink = (((yy // square) + (xx // square)) % 2 == 0).astype(np.float32)
    src = np.float32([[0, 0], [sq_w, 0], [sq_w, sq_h], [0, sq_h]]) - 0.5
    hom = cv2.getPerspectiveTransform(src, np.float32(quad))
    ink = cv2.warpPerspective(ink, hom, size, flags=cv2.INTER_AREA)
    inside = cv2.warpPerspective(np.ones((sq_h, sq_w), np.float32), hom, size)
    img = np.full(size[::-1], 0.55, np.float32)
    centre = np.float32(quad).mean(0)
    paper = (np.float32(quad) - centre) * 1.12 + centre
    cv2.fillPoly(img, [np.round(paper * 16).astype(np.int32)], 0.95, cv2.LINE_AA, shift=4)
    img = img * (1 - inside) + inside * (0.95 - 0.85 * ink)
    inner = np.float32([[(c + 1) * square, (r + 1) * square] for r in range(rows) for c in range(cols)]) - 0.5
    return np.round(np.clip(img, 0, 1) * 255).astype(np.uint8), cv2.perspectiveTransform(inner[None], hom)[0]


def test_without_a_pattern_a_coarse_scales_sub_grid_does_not_hide_the_whole_board():
    from aicalib_tf.detect.pipeline import detect_corners

    # a 9x6 board tilted away: its far squares (~10 px wide, ~6 px tall) are too small at half
    # scale, where only its 9x5 near rows form a complete grid
    quad = [[911, 447.5], [1009, 447.5], [1065, 552.5], [855, 552.5]]
    img, truth = _tilted_board(9, 6, quad, (1920, 1080))
    det = detect_corners(img, None)
    assert det.complete and sorted(det.pattern_size) == [6, 9]
    assert np.abs(np.sort(det.corners, axis=0) - np.sort(truth, axis=0)).max() < 0.5


def test_a_large_image_is_detected_at_a_coarse_scale_as_accurately_as_at_full(monkeypatch):
    import aicalib_tf.detect.pipeline as detect

    s = make_sample("clean", 4, 0, size=(1920, 1080), pattern=(9, 6))
    tried = []
    real = detect._detect_at
    monkeypatch.setattr(detect, "_detect_at", lambda g, *a, **k: tried.append(g.shape) or real(g, *a, **k))
    det = detect.detect_corners(s.image, (9, 6))
    assert det.complete and det.image_size == (1920, 1080)
    assert tried == [(135, 240)]  # found by the first quick pass (factor 8): full size never searched
    from aicalib_tf.bench.metrics import board_detection_outcome

    outcome, err = board_detection_outcome(det.corners, s.corners, (9, 6))
    assert outcome == "hit" and np.median(err) < 0.02


def test_a_board_too_small_for_the_coarse_scale_is_found_at_full_size(monkeypatch):
    import aicalib_tf.detect.pipeline as detect

    s = make_sample("clean", 0, 0, size=(640, 480), pattern=(9, 6))
    small = detect.detect_corners(s.image, (9, 6))
    assert small.complete
    # the 640×480 image shrunk to squares of ~4.4 px inside a plain 1920×1080 frame: ~2.2 px at the
    # coarse scale, too thin for the network (at ~5 px, half size 320×240, the coarse scale finds it)
    import cv2

    img = cv2.resize(s.image, (280, 210), interpolation=cv2.INTER_AREA)
    frame = np.full((1080, 1920), int(np.median(img)), np.uint8)
    frame[400:610, 800:1080] = img
    tried = []
    real = detect._detect_at
    monkeypatch.setattr(detect, "_detect_at", lambda g, *a, **k: tried.append(g.shape) or real(g, *a, **k))
    det = detect.detect_corners(frame, (9, 6))
    assert tried == [(135, 240), (270, 480), (540, 960), (1080, 1920)]  # the quick passes, then the scales
    assert det.complete
    truth = (s.corners + 0.5) * (280 / 640) - 0.5 + [800, 400]
    from aicalib_tf.bench.metrics import board_detection_outcome

    assert board_detection_outcome(det.corners, truth, (9, 6))[0] == "hit"


def test_a_board_whose_corner_the_full_image_refinement_cannot_place_is_searched_finer(monkeypatch):
    import aicalib_tf.detect.pipeline as detect

    s = make_sample("clean", 4, 0, size=(1920, 1080), pattern=(9, 6))
    real = detect.refine_full

    def one_fails(gray, pts, max_shift=2.0):
        out, ok = real(gray, pts, max_shift)
        ok[7] = False
        return out, ok

    tried = []
    real_at = detect._detect_at
    monkeypatch.setattr(detect, "refine_full", one_fails)
    monkeypatch.setattr(detect, "_detect_at", lambda g, *a, **k: tried.append(g.shape) or real_at(g, *a, **k))
    det = detect.detect_corners(s.image, (9, 6))
    # the quick passes (factors 8 and 4) and the coarse scale all fail the refinement: found again at full size
    assert tried == [(135, 240), (270, 480), (540, 960), (1080, 1920)] and det.complete


def test_the_quick_passes_run_the_default_networks_quick_network():
    # the shipped detector network comes with a smaller one for the quick passes; the finer scales,
    # and a network loaded from a path (no quick network), run the network itself
    from aicalib_tf.cnn.model import MODELS_DIR, load_model
    from aicalib_tf.detect.pipeline import detect_corners

    model = load_model("default_int8")
    assert model.quick is not None and model.quick.aicalib_path.endswith("quick_int8.tflite")
    alone = load_model(MODELS_DIR / "default_int8.tflite")
    assert alone.quick is None
    s = make_sample("clean", 2, 0, size=(640, 480), pattern=(9, 6))
    seen = []

    class Spy:  # a model whose two networks record the input shapes they are run on
        kind = "map"

        def __init__(self, net, tag):
            self.net, self.tag = net, tag
            self.quick = None

        def __call__(self, x):
            seen.append((self.tag, x.shape[1:3]))
            return self.net(x)

    spy = Spy(model, "default")
    spy.quick = Spy(model.quick, "quick")
    det = detect_corners(s.image, (9, 6), model=spy)
    assert det.complete and seen == [("quick", (240, 320))]  # found by the quick pass at 320×240
    ref = detect_corners(s.image, (9, 6), model=alone)  # the default network's quick pass
    assert ref.complete
    np.testing.assert_array_equal(det.ids, ref.ids)
    np.testing.assert_allclose(det.corners, ref.corners, atol=1e-2)  # both refined on the full image
    seen.clear()
    small = make_sample("clean", 2, 0, size=(320, 240), pattern=(9, 6))  # no quick pass at 320×240
    assert detect_corners(small.image, (9, 6), model=spy).complete and {t for t, _ in seen} == {"default"}
