import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from aicalib_tf.geometry.image_circle import ImageCircle, circle_fov_deg
from aicalib_tf.geometry.lens import Lens

_spec = importlib.util.spec_from_file_location("circle_fov_bench", Path(__file__).parents[2] / "benchmarks" / "circle_fov.py")
cf = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(cf)

F = 300.0
K = np.array([[F, 0, 639.5], [0, F, 479.5], [0, 0, 1]])
CIRCLE = ImageCircle(639.5, 479.5, F * math.radians(92.5))  # an ideal 185° equidistant lens's circle


def test_the_continuation_past_the_boards_reach_follows_the_models_slope_there():
    # θd(θ) = θ(1 + k1 θ²): past 60° the polynomial bends; the rim is continued with θd's slope over 58–60°
    k1, reach = -0.03, 60.0
    lens = Lens("equidistant", K, [k1, 0.0, 0.0, 0.0], (1280, 960))
    theta_d = lambda deg: math.radians(deg) * (1 + k1 * math.radians(deg) ** 2)  # noqa: E731
    slope = (theta_d(reach) - theta_d(reach - cf.EXTEND_STEP_DEG)) / cf.EXTEND_STEP_DEG
    expected = 2 * (reach + (CIRCLE.radius / F - theta_d(reach)) / slope)
    assert cf.continued_fov_deg(lens, CIRCLE, reach) == pytest.approx(expected, abs=1e-3)
    assert abs(circle_fov_deg(lens, CIRCLE) - expected) > 5  # the polynomial's own rim is elsewhere
    assert cf.continued_fov_deg(lens, CIRCLE, 120.0) == circle_fov_deg(lens, CIRCLE)  # rim within reach: the model
    assert cf.continued_fov_deg(lens, CIRCLE, math.nan) == circle_fov_deg(lens, CIRCLE)
    ideal = Lens("equidistant", K, None, (1280, 960))
    assert cf.continued_fov_deg(ideal, CIRCLE, 50.0) == pytest.approx(185.0, abs=1e-6)  # a straight r(θ) is unchanged
