import numpy as np
import pytest

pytest.importorskip("keras")

from aicalib_tf.cnn.training_data import (  # noqa: E402
    CROP_SIZE,
    CornerMapBatches,
    PatchBatches,
    _dihedral,
    _warp_crop,
    halve,
    render_pool,
    shade_crop,
    squeeze_matrix,
)
from aicalib_tf.cnn.corner_map import decode_map  # noqa: E402


@pytest.fixture(scope="module")
def pool():
    return render_pool(10, seed=3, workers=1, progress=False)


def test_pool_holds_images_and_visible_corners(pool):
    assert pool.images.shape == (10, 480, 640) and pool.images.dtype == np.uint8
    assert len(pool.corners) == 10
    assert sum(len(c) for c in pool.corners) > 0
    assert len(pool.corners[-1]) == 0  # the last tenth is board-free clutter
    for c in pool.corners:
        assert c.shape[1:] == (2,)
        assert np.all((c >= -0.5) & (c <= [639.5, 479.5]))


@pytest.mark.parametrize("k", range(8))
def test_dihedral_moves_points_with_the_pixels(k):
    img = np.zeros((16, 16), np.float32)
    pts = np.array([[3.0, 5.0], [12.0, 1.0]], np.float32)
    for x, y in pts.astype(int):
        img[y, x] = 1.0
    out, moved = _dihedral(img, pts, k)
    for x, y in moved:
        assert out[int(y), int(x)] == 1.0
    assert out.sum() == 2.0


@pytest.mark.parametrize("squeeze, shrink, shade", [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)])
def test_crop_batches_are_deterministic_and_labels_sit_on_x_junctions(pool, squeeze, shrink, shade):
    a = CornerMapBatches(pool, batch_size=8, steps=3, seed=5, squeeze=squeeze, shrink=shrink, shade=shade)
    b = CornerMapBatches(pool, batch_size=8, steps=3, seed=5, squeeze=squeeze, shrink=shrink, shade=shade)
    x1, y1 = a[1]
    x2, y2 = b[1]
    np.testing.assert_array_equal(x1, x2)
    np.testing.assert_array_equal(y1, y2)
    assert x1.shape == (8, CROP_SIZE, CROP_SIZE, 1) and y1.shape == (8, CROP_SIZE // 4, CROP_SIZE // 4, 3)
    assert not np.array_equal(a[2][0], x1)
    a.on_epoch_end()
    assert not np.array_equal(a[1][0], x1)  # a new epoch gives new crops
    # labelled corners are X-junctions of the crop: diagonal quadrants agree and differ from the
    # other diagonal. Noise can be strong, so compare the average contrast with random places.
    def diag_contrast(img, x, y):
        q = [img[y - 3 : y - 1, x - 3 : x - 1].mean(), img[y - 3 : y - 1, x + 2 : x + 4].mean(),
             img[y + 2 : y + 4, x + 2 : x + 4].mean(), img[y + 2 : y + 4, x - 3 : x - 1].mean()]
        return abs((q[0] + q[2]) - (q[1] + q[3]))

    rng = np.random.default_rng(0)
    at_corners, at_random = [], []
    for img, target in zip(x1[..., 0], y1):
        for x, y in decode_map(target, 0.5)[0]:
            if 4 <= x < CROP_SIZE - 5 and 4 <= y < CROP_SIZE - 5:
                at_corners.append(diag_contrast(img, int(round(x)), int(round(y))))
                at_random.append(diag_contrast(img, *rng.integers(4, CROP_SIZE - 5, 2)))
    assert len(at_corners) > 10
    assert np.mean(at_corners) > 2.5 * np.mean(at_random)


@pytest.mark.parametrize("angle, ratio", [(0.0, 1.0), (0.4, 2.0), (2.0, 3.0)])
def test_warped_crop_moves_points_with_the_pixels(angle, ratio):
    # a smooth blob's centroid in the warped crop is where its centre's point went
    a = squeeze_matrix(angle, ratio)
    assert np.isclose(np.linalg.det(a), 1.0) and np.allclose(np.linalg.svd(a)[1], [np.sqrt(ratio), 1 / np.sqrt(ratio)])
    yy, xx = np.mgrid[0:200, 0:300]
    for px, py in [(150.3, 100.7), (171.2, 88.9)]:
        img = (200 * np.exp(-((xx - px) ** 2 + (yy - py) ** 2) / (2 * 3.0**2))).astype(np.float32)
        crop, moved = _warp_crop(img, np.array([[px, py]], np.float32), a, (140.0, 95.0), 128)
        w = crop / crop.sum()
        ys, xs = np.mgrid[0:128, 0:128]
        np.testing.assert_allclose([(w * xs).sum(), (w * ys).sum()], moved[0], atol=0.01)


@pytest.mark.parametrize("option", ["squeeze", "shrink", "shade"])
def test_squeeze_or_shrink_zero_draws_the_crops_drawn_before(pool, option):
    plain = CornerMapBatches(pool, batch_size=4, steps=1, seed=2)
    off = CornerMapBatches(pool, batch_size=4, steps=1, seed=2, **{option: 0.0})
    on = CornerMapBatches(pool, batch_size=4, steps=1, seed=2, **{option: 1.0})
    np.testing.assert_array_equal(plain[0][0], off[0][0])
    assert not np.array_equal(plain[0][0], on[0][0])


def test_shade_dims_blurs_and_quantises_a_crop_without_moving_its_corner():
    # an X-junction of 20 and 200 grey levels at the crop's centre pixel
    img = np.full((128, 128), 20, np.uint8)
    img[:64, :64] = img[64:, 64:] = 200
    rng = np.random.default_rng(0)
    contrasts, sharp = [], []
    for _ in range(200):
        out = shade_crop(img, rng)
        assert out.shape == img.shape and out.dtype == np.float32
        assert out.min() >= 0 and out.max() <= 255 and np.array_equal(out, np.rint(out))
        q = [out[54:62, 54:62].mean(), out[54:62, 66:74].mean(), out[66:74, 66:74].mean(), out[66:74, 54:62].mean()]
        contrasts.append((q[0] + q[2] - q[1] - q[3]) / 2)  # the junction stays an X: diagonals alike
        sharp.append(abs(out[63, 60] - out[64, 60]))  # the step across an edge, near the junction
    contrasts = np.array(contrasts)
    assert np.all(contrasts > 0)  # no law turns the junction over or off
    assert np.percentile(contrasts, 10) < 30 and np.percentile(contrasts, 90) > 80  # dim to nearly full swing (180)
    assert np.percentile(sharp, 25) < 0.5 * np.percentile(sharp, 90)  # some crops blurred, some sharp


def test_halving_moves_points_with_the_pixels():
    # a smooth blob's centroid at half size is where its centre's point went
    yy, xx = np.mgrid[0:120, 0:161]
    px, py = 70.3, 51.8
    img = (250 * np.exp(-((xx - px) ** 2 + (yy - py) ** 2) / (2 * 4.0**2))).astype(np.uint8)
    small, moved = halve(img, np.array([[px, py], [0.0, 0.0]], np.float32))
    assert small.shape == (60, 80) and small.dtype == np.uint8
    w = small.astype(np.float64) / small.sum()
    ys, xs = np.mgrid[0:60, 0:80]
    np.testing.assert_allclose([(w * xs).sum(), (w * ys).sum()], moved[0], atol=0.05)
    np.testing.assert_allclose(moved[1], [-0.25, -0.25])  # pixel (0, 0)'s centre: a quarter pixel before block 0's


def test_patch_batches_are_balanced(pool):
    pb = PatchBatches(pool, batch_size=16, steps=2, seed=1)
    x, y = pb[0]
    assert x.shape == (16, 32, 32, 1) and y.shape == (16, 1)
    assert y.sum() == 8
    np.testing.assert_array_equal(pb[0][0], x)


def test_parse_mix_normalises_shares_and_names_bad_parts():
    from aicalib_tf.cnn.training_data import parse_mix

    assert parse_mix("train") == [("train", 1.0)]
    assert parse_mix("train:3,distorted:1") == [("train", 0.75), ("distorted", 0.25)]
    for spec, words in [("nope", "unknown preset 'nope'"), ("train:0", "must be > 0"), ("train:x", "'x'"),
                        ("train,train", "twice")]:
        with pytest.raises(ValueError, match=words):
            parse_mix(spec)


def test_a_mixed_pool_renders_each_preset_its_share(pool):
    from data_gen import make_sample

    mixed = render_pool(10, seed=3, preset="train:0.5,distorted:0.5", workers=1, progress=False)
    # 9 board scenes split 5 / 4 (largest remainder first), then the clutter image
    assert np.array_equal(mixed.images[:5], pool.images[:5])  # preset 0 renders what a single preset does
    d0 = make_sample("distorted", 3, 1_000_000, size=(640, 480))
    assert np.array_equal(mixed.images[5], d0.image)
    assert np.array_equal(mixed.images[9], pool.images[9])
