import numpy as np

from aicalib_tf.detect.corners.candidates import saddle_points


def test_strongest_saddle_is_the_x_junction():
    # a 2x2 checker with its junction between pixels 29/30 (x) and 19/20 (y): at (29.5, 19.5)
    img = np.zeros((40, 60), np.float32)
    img[:20, :30] = 1.0
    img[20:, 30:] = 1.0
    pts = saddle_points(img, max_points=5)
    assert pts.dtype == np.int32 and pts.shape[1] == 2
    x, y = pts[0]
    assert abs(x - 29.5) <= 0.5 and abs(y - 19.5) <= 0.5


def test_no_saddles_in_a_flat_image():
    assert saddle_points(np.full((30, 30), 0.5, np.float32)).shape == (0, 2)
