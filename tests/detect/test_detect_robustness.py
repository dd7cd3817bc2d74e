"""Property-based robustness of detect_corners: random images, sizes, dtypes and patterns.

The large images run in a child process under an address-space limit (:mod:`tests.detect.bounded`):
a detector whose memory grows past it fails the test instead of taking the machine's memory.
"""

import numpy as np
import pytest

pytest.importorskip("keras")
hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from aicalib_tf.detect.pipeline import detect_corners  # noqa: E402
from aicalib_tf.cnn.model import MODELS_DIR, load_model  # noqa: E402
from data_gen import make_sample  # noqa: E402
from tests.detect.bounded import BoundedDetector  # noqa: E402

pytestmark = pytest.mark.skipif(not (MODELS_DIR / "default.keras").is_file(), reason="no shipped default model")
MODEL = None


def _model():
    global MODEL
    if MODEL is None:
        MODEL = load_model("default")
    return MODEL


@pytest.fixture(scope="module")
def bounded():
    detector = BoundedDetector(model="default")
    yield detector
    detector.close()


def _draw_image(draw, sizes, block_max: int, board_size=(320, 240)):
    """One image: a resized real board, noise, checker-like blocks or a constant; u8, u16 or BGR."""
    import cv2

    kind = draw(st.sampled_from(["noise", "board", "blocks", "constant"]))
    seed = draw(st.integers(0, 10_000))
    rng = np.random.default_rng(seed)
    w, h = draw(sizes)
    if kind == "board":  # a real board, resized to a random size
        img = make_sample(draw(st.sampled_from(["clean", "hard", "partial"])), seed % 50, 0, size=board_size).image
        img = cv2.resize(img, (w, h))
    elif kind == "noise":
        img = rng.integers(0, 256, (h, w), dtype=np.uint8)
    elif kind == "blocks":  # checker-like blocks of random sizes: many false junctions
        s = int(rng.integers(2, block_max))
        yy, xx = np.mgrid[0:h, 0:w]
        img = (((yy // s) + (xx // s)) % 2 * 255).astype(np.uint8)
    else:
        img = np.full((h, w), int(rng.integers(0, 256)), np.uint8)
    dtype = draw(st.sampled_from(["u8", "u16", "bgr"]))
    if dtype == "u16":
        img = img.astype(np.uint16) * 257
    elif dtype == "bgr":
        img = np.repeat(img[:, :, None], 3, axis=2)
    return img


@st.composite
def images(draw):
    return _draw_image(draw, st.tuples(st.integers(1, 400), st.integers(1, 400)), 20)


@st.composite
def large_images(draw):
    """Longer side 1600–3400 px: the coarse-to-fine path (aicalib_tf.detect.pyramid), thin images too."""
    long_side, short_side = draw(st.integers(1600, 3400)), draw(st.integers(1, 3400))
    size = (long_side, short_side) if draw(st.booleans()) else (short_side, long_side)
    return _draw_image(draw, st.just(size), 40, board_size=(640, 480))


patterns = st.tuples(st.integers(3, 12), st.integers(3, 9)) | st.none()


def _check_invariants(img, pattern, detect=None):
    det = detect(img, pattern) if detect is not None else detect_corners(img, pattern, model=_model())
    h, w = img.shape[:2]
    n = len(det.corners)
    assert det.corners.shape == (n, 2) and det.ids.shape == (n, 2) and det.scores.shape == (n,)
    assert det.image_size == (w, h)
    if n:
        assert np.all(np.isfinite(det.corners))
        assert np.all((det.corners >= -0.5) & (det.corners <= np.array([w - 0.5, h - 0.5])))
        cols, rows = det.pattern_size
        assert np.all((det.ids >= 0) & (det.ids < np.array([cols, rows])))
        assert len({tuple(i) for i in det.ids.tolist()}) == n  # ids unique
    if det.complete:
        assert n == det.pattern_size[0] * det.pattern_size[1]
    if pattern is not None and det.found:
        assert det.pattern_size == pattern


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(img=images(), pattern=patterns)
def test_invariants_hold_on_any_image(img, pattern):
    _check_invariants(img, pattern)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                                                   HealthCheck.function_scoped_fixture])
@given(img=large_images(), pattern=patterns)
def test_invariants_hold_on_large_images(bounded, img, pattern):
    _check_invariants(img, pattern, bounded)
