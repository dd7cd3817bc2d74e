import importlib.util
from pathlib import Path

import numpy as np

_spec = importlib.util.spec_from_file_location(
    "board_thickness", Path(__file__).parents[2] / "benchmarks" / "board_thickness.py")
bt = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bt)


def _grid(u, v, cols=9, rows=6):
    return np.array([c * np.asarray(u) + r * np.asarray(v) for r in range(rows) for c in range(cols)], float)


def test_a_face_on_square_is_as_thick_as_its_side():
    np.testing.assert_allclose(bt.square_thickness(_grid([12.0, 0.0], [0.0, 12.0])), 12.0)


def test_a_sheared_square_is_as_thick_as_its_height_across_the_longest_side():
    # sides 10 px along x and 10 px at 30° to it: the height across either side is 10·sin 30° = 5 px
    v = 10.0 * np.array([np.cos(np.pi / 6), np.sin(np.pi / 6)])
    np.testing.assert_allclose(bt.square_thickness(_grid([10.0, 0.0], v)), 5.0)
