import numpy as np

from aicalib_tf.detect.opencv import opencv_classic, opencv_sb
from data_gen import make_sample


def test_opencv_baselines_find_a_clean_board_and_miss_an_empty_image():
    s = make_sample("clean", 0, 0, pattern=(9, 6))
    for detector in (opencv_classic, opencv_sb):
        ok, corners = detector(s.image, (9, 6))
        assert ok and corners.shape == (54, 2)
        ok, corners = detector(np.full((120, 160), 128, np.uint8), (9, 6))
        assert not ok and corners is None
