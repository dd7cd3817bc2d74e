"""calib.coverage: uncovered regions and the image circle's rim (synthetic views of a circular fisheye)."""

from __future__ import annotations

import numpy as np

from aicalib_tf.calib.coverage import rim_gaps, uncovered_regions
from aicalib_tf.calib.fit import View
from aicalib_tf.geometry import lens as L
from aicalib_tf.geometry.image_circle import ImageCircle
from tests.calib.synthetic import synthetic_views

SIZE = (640, 480)
# a 185° equidistant lens on 640x480 whose image circle (radius 161 px) leaves the corners black
CIRCLE_LENS = L.Lens("equidistant", [[100.0, 0, 319.5], [0, 100.0, 239.5], [0, 0, 1]], [0.0, 0.0, 0.0, 0.0], SIZE)
CIRCLE = ImageCircle(319.5, 239.5, 100.0 * np.radians(92.5))


def test_regions_outside_the_image_circle_are_not_uncovered_and_its_rim_is_checked():
    central = [v for v in synthetic_views(CIRCLE_LENS, 30, 0.0, seed=4, distance=(0.2, 0.3))
               if np.all(CIRCLE.contains(v.corners, -0.3 * CIRCLE.radius))]
    assert central
    assert set(uncovered_regions(central, SIZE)) >= {"top-left", "bottom-right"}
    assert not {"top-left", "top-right", "bottom-left", "bottom-right"} & set(uncovered_regions(central, SIZE, CIRCLE))
    assert set(rim_gaps(central, SIZE, CIRCLE)) == {"right", "bottom-right", "bottom", "bottom-left", "left",
                                                    "top-left", "top", "top-right"}
    rim = View("rim", np.array([[319.5 + 150.0, 239.5]]), np.array([[0, 0]]))
    assert "right" not in rim_gaps(central + [rim], SIZE, CIRCLE)
