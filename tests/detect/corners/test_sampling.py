import numpy as np

from aicalib_tf.detect.corners.sampling import sample_bilinear


def test_samples_do_not_depend_on_how_many_points_are_asked_together():
    # a few points go to cv2.remap as one short row, many as rows of 4096: each sample is its own
    rng = np.random.default_rng(4)
    g = rng.random((50, 70)).astype(np.float32)
    xy = rng.uniform(-3, 72, (9000, 2))
    every = sample_bilinear(g, xy)
    assert every.shape == (9000,) and every.dtype == np.float32
    for m in (1, 3, 40, 4096, 4097):
        np.testing.assert_array_equal(sample_bilinear(g, xy[:m]), every[:m])
    assert sample_bilinear(g, xy[:0]).shape == (0,)


def test_samples_are_bilinear_with_the_border_replicated():
    g = np.arange(12, dtype=np.float32).reshape(3, 4)  # value = 4·y + x
    got = sample_bilinear(g, np.array([[1.5, 0.5], [0.0, 0.0], [-2.0, 1.0], [3.0, 5.0]]))
    np.testing.assert_allclose(got, [3.5, 0.0, 4.0, 11.0], atol=1 / 32)


def _reference_windows(g, pts, radius):
    """sample_windows' values worked out in numpy: each sample's bilinear formula, edge pixels clamped."""
    h, w = g.shape
    d = np.arange(-radius, radius + 1)
    out = []
    for x, y in pts:
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = x - x0, y - y0
        rows, cols = (y0 + d).astype(int), (x0 + d).astype(int)
        r0, r1 = np.clip(rows, 0, h - 1), np.clip(rows + 1, 0, h - 1)
        c0, c1 = np.clip(cols, 0, w - 1), np.clip(cols + 1, 0, w - 1)

        def along_x(r):  # float32 differences, then float64 as the compiled code does
            a, b = g[r][:, c0], g[r][:, c1]
            return a.astype(np.float64) + fx * (b - a).astype(np.float64)

        top, bot = along_x(r0), along_x(r1)
        out.append((top + fy * (bot - top)).ravel())
    return np.array(out)


def test_windows_inside_the_image_and_across_its_border_are_the_bilinear_formula_bit_for_bit():
    # windows wholly inside the image take a path that reuses each pixel row's interpolation; the
    # values must be those of the per-sample formula, as near the border
    from aicalib_tf.detect.corners.sampling import sample_windows

    rng = np.random.default_rng(7)
    g = rng.random((40, 50)).astype(np.float32)
    pts = np.column_stack([rng.uniform(-4, 54, 300), rng.uniform(-4, 44, 300)])
    for radius in (1, 3, 5):
        got = sample_windows(g, pts, radius)
        np.testing.assert_array_equal(got, _reference_windows(g, pts, radius))
