import numpy as np

from aicalib_tf.detect.sampling import sample_bilinear


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
