"""geometry.pose: the rotation that best maps a lens's projections onto pixels."""

import numpy as np
import pytest

from aicalib_tf.geometry import lens as L
from aicalib_tf.geometry.pose import best_rotation


@pytest.mark.parametrize("model, dist", [("plumb_bob", [-0.2, 0.05, 1e-3, -1e-3, 0.0]), ("equidistant", [0.02, -0.01, 3e-3, -1e-3])])
def test_best_rotation_recovers_a_known_rotation(model, dist):
    import cv2

    lens = L.Lens(model, [[400.0, 0, 320], [0, 400.0, 240], [0, 0, 1]], dist, (640, 480))
    rays = lens.unproject(np.stack(np.meshgrid(np.linspace(0, 639, 16), np.linspace(0, 479, 12)), -1).reshape(-1, 2))
    R_true = cv2.Rodrigues(np.array([0.004, -0.007, 0.002]))[0]
    R = best_rotation(lens, rays, lens.project(rays @ R_true.T))
    assert np.abs(R - R_true).max() < 1e-10
