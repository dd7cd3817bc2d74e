"""data_gen.sensor: the optical and sensor laws of real cameras and other renderers."""

import numpy as np
import pytest

from data_gen.degrade import CIRCLE_STEPS, PIPELINE_ORDER, apply_degradations, gaussian_blur, gaussian_noise, shot_noise
from data_gen.sensor import (astigmatism, bayer_demosaic, circle_edge, disc_kernel, field_defocus, lateral_ca,
                             tone_curve, unsharp)

CIRCLE = {"cx": 31.5, "cy": 31.5, "radius": 32.0}


def _step(size: int = 64, axis: int = 1, at: int | None = None) -> np.ndarray:
    """(size, size) float32: 0.2 left of column ``at`` (default the middle), 0.8 from it on (axis 1)."""
    img = np.full((size, size), 0.2, np.float32)
    at = size // 2 if at is None else at
    if axis == 1:
        img[:, at:] = 0.8
    else:
        img[at:, :] = 0.8
    return img


def _width(profile: np.ndarray) -> int:
    """Pixels of a rising edge profile between 10% and 90% of its swing."""
    lo, hi = profile.min(), profile.max()
    t = (profile - lo) / (hi - lo)
    return int(np.count_nonzero((t > 0.1) & (t < 0.9)))


def test_circle_edge_keeps_the_inside_and_is_black_from_black_at_on():
    img = np.ones((64, 64), np.float32)
    out = circle_edge(img, None, black_at=0.9, width=0.2, **CIRCLE)
    yy, xx = np.mgrid[0:64, 0:64]
    rho = np.hypot(xx - 31.5, yy - 31.5) / 32.0
    assert np.all(out[rho <= 0.7] == 1.0) and np.all(out[rho >= 0.9] == 0.0)
    ring = (rho > 0.7) & (rho < 0.9)
    assert np.all((out[ring] > 0) & (out[ring] < 1))
    order = np.argsort(rho[ring])
    assert np.all(np.diff(out[ring][order]) <= 1e-6)  # never brighter further out
    with pytest.raises(ValueError, match="width"):
        circle_edge(img, None, black_at=0.5, width=0.6, **CIRCLE)


def test_disc_kernel_is_a_flat_topped_disc_of_its_radius():
    k = disc_kernel(3.0)
    assert k.shape == (7, 7) and k.sum() == pytest.approx(1.0, abs=1e-6)
    assert np.ptp(k[2:5, 2:5]) == 0.0  # flat top, unlike a Gaussian
    assert k[3, 0] > 0 and k[0, 0] == 0.0  # reaches 3 px along the axes, not to the box's corners
    # spread per axis of a disc of radius r: r / 2
    c = np.arange(-3, 4)
    assert np.sqrt((k.sum(axis=0) * c ** 2).sum()) == pytest.approx(1.5, rel=0.05)


def test_field_defocus_grows_towards_the_rim_and_keeps_a_flat_field():
    flat = np.full((64, 64), 0.5, np.float32)
    out = field_defocus(flat, None, radius_centre=1.0, radius_rim=4.0, power=1.0, **CIRCLE)
    assert np.allclose(out, 0.5, atol=1e-6)
    img = _step()
    out = field_defocus(img, None, radius_centre=0.5, radius_rim=5.0, power=1.0, **CIRCLE)
    centre = _width(out[32, 24:40])  # the edge crosses the circle's centre ...
    rim = _width(field_defocus(_step(axis=0, at=60), None, radius_centre=0.5, radius_rim=5.0, power=1.0,
                               **CIRCLE)[50:64, 32])  # ... and near its rim
    assert centre <= 1 and rim >= 4
    uniform = field_defocus(img, None, radius_centre=3.0, radius_rim=3.0, power=1.0, **CIRCLE)
    assert np.allclose(uniform[:, 20:44], field_defocus(img, None, radius_centre=3.0, radius_rim=3.0 + 1e-9,
                                                        power=1.0, **CIRCLE)[:, 20:44], atol=1e-5)


def test_lateral_ca_spreads_a_rim_edge_by_its_shift_and_leaves_the_centre():
    flat = np.full((64, 64), 0.4, np.float32)
    assert np.allclose(lateral_ca(flat, None, shift=2.0, power=1.0, **CIRCLE), 0.4, atol=1e-6)
    assert np.array_equal(lateral_ca(_step(), None, shift=0.0, power=1.0, **CIRCLE), _step())
    edge = _step(axis=1, at=58)  # a radial step near the rim, along the row through the centre
    out = lateral_ca(edge, None, shift=3.0, power=1.0, **CIRCLE)
    row = out[31, 50:64]
    assert _width(row) >= 4 and _width(edge[31, 50:64]) == 0
    # the red image lies further out: left of the edge the red part is still dark, the blue one already bright
    assert out[31, 56] == pytest.approx(0.2 + 0.114 * 0.6, abs=0.01)  # 2.3 px in: only blue sees the bright side
    assert out[31, 59] == pytest.approx(0.8 - 0.299 * 0.6, abs=0.01)  # 0.5 px out: red still sees the dark side
    centre = _step(at=32)
    assert np.allclose(lateral_ca(centre, None, shift=3.0, power=2.0, **CIRCLE)[28:36, 28:36], centre[28:36, 28:36],
                       atol=0.02)


def test_astigmatism_blurs_along_the_radius_and_along_the_circle_apart():
    yy, xx = np.mgrid[0:128, 0:128]
    rad = np.hypot(xx - 63.5, yy - 63.5)
    img = np.where((rad > 40) & (rad < 52), 0.8, 0.2).astype(np.float32)  # a ring: edges across the radius
    img[(np.abs(yy - 63.5) < 10) & (xx < 30)] = 0.8  # a spoke: edges along the radius, 56 px out at column 8
    circle = {"cx": 63.5, "cy": 63.5, "radius": 56.0}
    radial = astigmatism(img, None, sigma_radial=3.0, sigma_tangential=0.0, power=1.0, **circle)
    tangential = astigmatism(img, None, sigma_radial=0.0, sigma_tangential=3.0, power=1.0, **circle)
    ring, spoke = (slice(63, 64), slice(108, 124)), (slice(46, 62), slice(8, 9))  # profiles across each edge
    assert _width(radial[ring].ravel()) >= 5 and _width(tangential[ring].ravel()) <= 2  # 2: the polar resampling
    assert _width(tangential[spoke].ravel()) >= 5 and _width(radial[spoke].ravel()) <= 2
    assert np.array_equal(astigmatism(img, None, sigma_radial=0.0, sigma_tangential=0.0, power=1.0, **circle), img)
    assert np.array_equal(radial[54:74, 54:74], img[54:74, 54:74])  # σ under 0.25 px near the centre: unchanged


@pytest.mark.parametrize("method", ["bilinear", "edge"])
def test_the_mosaic_round_trip_keeps_a_flat_field_and_the_mean_grey(method):
    flat = np.full((32, 32), 0.37, np.float32)
    assert np.allclose(bayer_demosaic(flat, None, gain_r=0.5, gain_b=0.7, method=method), 0.37, atol=2e-4)
    board = np.kron((np.indices((8, 8)).sum(axis=0) % 2).astype(np.float32), np.ones((6, 6), np.float32)) * 0.6 + 0.2
    out = bayer_demosaic(board, None, gain_r=0.5, gain_b=0.7, method=method)
    assert out[4:-4, 4:-4].mean() == pytest.approx(board[4:-4, 4:-4].mean(), abs=0.002)
    assert np.abs(out - board).max() > 0.02  # but the edges are not what they were


def test_the_mosaic_aliases_fine_stripes_and_clips_at_full_well():
    stripes = np.tile(np.array([0.2, 0.8], np.float32), (32, 16))  # a 2-px period: the R sites see only 0.2
    out = bayer_demosaic(stripes, None, gain_r=0.6, gain_b=0.6, method="bilinear")
    assert np.abs(out[4:-4, 4:-4] - stripes[4:-4, 4:-4]).mean() > 0.1
    bright = bayer_demosaic(np.full((16, 16), 1.5, np.float32), None, gain_r=0.5, gain_b=0.5)
    assert bright.max() <= 1.0 + 1e-4 < 1.5
    with pytest.raises(ValueError, match="method"):
        bayer_demosaic(stripes, None, gain_r=0.5, gain_b=0.5, method="vng")


def test_photon_noise_through_the_mosaic_grows_with_the_signal():
    rng = np.random.default_rng(3)
    std = []
    for level in (0.1, 0.4, 0.9):
        raw = gaussian_noise(shot_noise(np.full((64, 64), level, np.float32), rng, photons=200.0), rng, sigma=1.0)
        std.append(float(bayer_demosaic(raw, None, gain_r=0.6, gain_b=0.7)[4:-4, 4:-4].std()))
    assert std[0] < std[1] < std[2]
    assert std[2] / std[0] == pytest.approx(3.0, rel=0.35)  # Poisson: σ grows as the square root of the light


def test_tone_curve_lifts_the_dark_rim_and_keeps_black_and_white():
    ramp = np.linspace(0.0, 1.0, 11, dtype=np.float32)[None, :]
    for law in ("srgb", "gamma"):
        out = tone_curve(ramp, None, law=law, gamma=2.2)[0]
        assert out[0] == 0.0 and out[-1] == pytest.approx(1.0) and np.all(np.diff(out) > 0)
        assert np.all(out[1:-1] > ramp[0, 1:-1])  # every dark and mid tone is lifted
    assert tone_curve(np.array([[0.25]], np.float32), None, law="gamma", gamma=2.0)[0, 0] == pytest.approx(0.5)
    # a board at 10% of the light by the rim: 0.02 / 0.8 in linear light, 35 grey levels apart once encoded
    dark = tone_curve(np.array([[0.002, 0.08]], np.float32), None)[0]
    assert (dark[1] - dark[0]) * 255 > 3 * (0.08 - 0.002) * 255
    assert tone_curve(np.array([[1.7, -0.2]], np.float32), None)[0] == pytest.approx([1.0, 0.0], abs=1e-6)
    with pytest.raises(ValueError, match="law"):
        tone_curve(ramp, None, law="filmic")


def test_unsharp_overshoots_an_edge_and_keeps_a_flat_field():
    assert np.allclose(unsharp(np.full((16, 16), 0.3, np.float32), None, amount=1.0, sigma=1.5), 0.3, atol=1e-6)
    img = gaussian_blur(_step(), None, sigma=0.7)
    out = unsharp(img, None, amount=1.0, sigma=1.5)
    assert out.max() > 0.85 and out.min() < 0.15  # a bright and a dark halo
    assert out.mean() == pytest.approx(img.mean(), abs=1e-3)


def test_the_laws_run_in_a_camera_order_and_circle_laws_follow_the_circle():
    order = PIPELINE_ORDER.index
    assert order("circle_edge") < order("field_defocus") < order("lateral_ca") < order("shot_noise")
    assert order("gaussian_noise") < order("bayer_demosaic") < order("tone_curve") < order("unsharp") < order("jpeg")
    assert {"circle_edge", "field_defocus", "lateral_ca", "astigmatism"} <= set(CIRCLE_STEPS)
    steps = [{"name": "tone_curve", "law": "srgb", "gamma": 2.2}, {"name": "bayer_demosaic", "gain_r": 0.5,
             "gain_b": 0.6, "method": "edge"}, {"name": "circle_edge", "black_at": 1.0, "width": 0.1, **CIRCLE}]
    out = apply_degradations(np.full((64, 64), 0.18, np.float32), steps, np.random.default_rng(0))
    assert out.dtype == np.uint8 and out[32, 32] == round(0.4613 * 255) and out[0, 0] == 0
