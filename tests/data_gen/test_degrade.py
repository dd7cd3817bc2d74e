"""Each degradation does what it says, measured."""

import numpy as np
import pytest

from data_gen import degrade as D
from data_gen.occlude import HIDE_MARGIN_PX, draw_occluders, occluded, sample_occluders
from data_gen.sample import make_sample

FLAT = np.full((240, 320), 0.5, np.float32)


def _rng():
    return np.random.default_rng(0)


@pytest.mark.parametrize("sigma", [5.0, 20.0, 40.0])
def test_gaussian_noise_std_matches_sigma(sigma):
    out = D.gaussian_noise(FLAT, _rng(), sigma=sigma) * 255
    assert out.std() == pytest.approx(sigma, rel=0.02)
    assert abs(out.mean() - 127.5) < 0.5


def test_shot_noise_follows_poisson():
    photons = 400.0
    out = D.shot_noise(FLAT, _rng(), photons=photons)
    assert out.std() == pytest.approx(np.sqrt(0.5 / photons), rel=0.03)


def _edge():
    img = np.zeros((64, 64), np.float32)
    img[:, 32:] = 1.0
    return img


def _edge_width(img):
    row = img[32]
    return int(np.sum((row > 0.1) & (row < 0.9)))


def test_blurs_widen_an_edge_with_their_severity():
    assert _edge_width(D.gaussian_blur(_edge(), _rng(), sigma=1.0)) < _edge_width(D.gaussian_blur(_edge(), _rng(), sigma=3.0))
    g = D.gaussian_blur(_edge(), _rng(), sigma=2.0)
    # A Gaussian edge profile: the 10–90% width is 2.56 σ.
    assert _edge_width(g) == pytest.approx(2.56 * 2.0, abs=1.5)
    assert _edge_width(D.motion_blur(_edge(), _rng(), length=9.0, angle=0.0)) >= 6
    assert _edge_width(D.motion_blur(_edge(), _rng(), length=9.0, angle=90.0)) == 0  # along the edge
    assert _edge_width(D.defocus(_edge(), _rng(), radius=3.0)) >= 4
    for fn, kw in [(D.gaussian_blur, {"sigma": 2.0}), (D.motion_blur, {"length": 7.0}), (D.defocus, {"radius": 3.0})]:
        assert fn(FLAT, _rng(), **kw).mean() == pytest.approx(0.5, abs=1e-4)  # energy preserved


def test_contrast_and_exposure():
    img = np.linspace(0, 1, 100, dtype=np.float32)[None, :].repeat(4, 0)
    low = D.contrast(img, _rng(), factor=0.2)
    assert np.ptp(low) == pytest.approx(0.2, abs=1e-5)
    over = D.quantize(D.exposure(img, _rng(), gain=2.0))
    assert (over == 255).mean() == pytest.approx(0.5, abs=0.02)  # clipped highlights
    under = D.quantize(D.exposure(img, _rng(), gain=0.1))
    assert under.max() <= 26


def test_shading():
    grad = D.illumination_gradient(FLAT, _rng(), strength=0.6)
    assert grad.max() == pytest.approx(0.5, abs=1e-3) and grad.min() == pytest.approx(0.2, abs=1e-3)
    vig = D.vignetting(FLAT, _rng(), strength=0.4)
    assert vig[0, 0] == pytest.approx(0.3, abs=1e-3) and vig[120, 160] == pytest.approx(0.5, abs=1e-3)
    sh = D.shadow(FLAT, _rng(), strength=0.5, softness=0.0)
    vals = np.unique(np.round(sh, 3))
    assert 0.25 in vals and 0.5 in vals  # a hard shadow: lit and shaded levels


def test_jpeg_and_salt_pepper():
    rng = np.random.default_rng(1)
    img = D.gaussian_blur(rng.random((128, 128)).astype(np.float32), rng, sigma=1.5)
    e15 = np.abs(D.jpeg(img, rng, quality=15) - img).mean()
    e90 = np.abs(D.jpeg(img, rng, quality=90) - img).mean()
    assert e15 > 2 * e90 > 0
    sp = D.salt_pepper(FLAT, rng, fraction=0.05)
    assert ((sp == 0) | (sp == 1)).mean() == pytest.approx(0.05, abs=0.005)
    assert (sp == 0).mean() == pytest.approx((sp == 1).mean(), abs=0.005)


def test_pipeline_orders_steps_and_rejects_unknown():
    steps = [{"name": "gaussian_noise", "sigma": 10.0}, {"name": "gaussian_blur", "sigma": 3.0}]
    out = D.apply_degradations(FLAT, steps, _rng())
    assert out.dtype == np.uint8
    # Blur runs before noise, so the noise is not smoothed away.
    assert out.astype(float).std() == pytest.approx(10.0, rel=0.1)
    with pytest.raises(ValueError, match="unknown degradation"):
        D.apply_degradations(FLAT, [{"name": "sepia"}], _rng())


def test_occluder_hides_exactly_the_corners_flagged_invisible():
    n_hidden = 0
    for i in range(8):
        s = make_sample("occluded", 3, i)
        polys = [np.array(p) for p in s.label["occluders"]]
        assert polys
        c, v = s.corners, s.visible
        hidden = occluded(c, polys)
        n_hidden += hidden.sum()
        assert not np.any(v & hidden)
        # Every invisible in-frame corner is within the hiding margin of an occluder.
        w, h = s.label["image_size"]
        inside = (c[:, 0] >= 0) & (c[:, 0] <= w - 1) & (c[:, 1] >= 0) & (c[:, 1] <= h - 1)
        assert np.array_equal(~v & inside, hidden & inside)
    assert n_hidden > 0


def test_occluder_paint_covers_its_polygon():
    rng = np.random.default_rng(0)
    pts = np.array([[100.0, 100.0], [200.0, 100.0], [150.0, 180.0]])
    polys = sample_occluders(rng, pts, severity=0.3)
    img = draw_occluders(np.zeros((240, 320), np.float32), polys, [0.5] * len(polys))
    centre = polys[0].mean(axis=0)
    assert img[int(centre[1]), int(centre[0])] > 0
    assert occluded(centre[None], polys)[0]
    far = polys[0].max(axis=0) + HIDE_MARGIN_PX + 5
    assert not occluded(far[None], polys)[0]
