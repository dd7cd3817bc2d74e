"""Circle grid descriptions: OpenCV's object points, the id lattice, the text form and its errors."""

import numpy as np
import pytest

from aicalib_tf.geometry.circles import CircleGrid, is_circles, parse_board


def test_asymmetric_points_follow_opencv_sample():
    b = parse_board("circles:4x11,spacing=20mm,asymmetric")
    pts = b.object_points()
    cols, rows = b.grid
    want = [((2 * j + i % 2) * 20.0, i * 20.0, 0.0) for i in range(rows) for j in range(cols)]
    assert np.allclose(pts, want)
    assert b.pattern_size == (8, 11) and b.square_size == 20.0 and b.unit == "mm"
    assert b.diameter == pytest.approx(20 * np.sqrt(2) / 2)
    assert parse_board(b.describe()).diameter == pytest.approx(b.diameter, rel=1e-9)


def test_symmetric_grid_is_the_lattice():
    b = parse_board("circles:7x6,spacing=2cm,symmetric,diameter=8mm")
    assert b.pattern_size == (7, 6) and b.unit == "cm" and b.diameter == pytest.approx(0.8)
    ids = b.circle_ids()
    assert ids[:3].tolist() == [[0, 0], [1, 0], [2, 0]] and ids[7].tolist() == [0, 1]
    assert is_circles(" Circles:7x6,spacing=1,symmetric") and not is_circles("aprilgrid:6x6")


@pytest.mark.parametrize("text, field", [
    ("circles:4x11,asymmetric", "spacing"),
    ("circles:4x11,spacing=20mm", "layout"),
    ("circles:4x11,spacing=20mm,hexagonal", "hexagonal"),
    ("circles:7x6,spacing=20mm,symmetric,diameter=20mm", "diameter"),
    ("circles:4x11,spacing=20mm,asymmetric,diameter=30mm", "diameter"),
    ("circles:4x11,spacing=twenty,asymmetric", "spacing"),
    ("circles:x11,spacing=20mm,asymmetric", "COLSxROWS"),
])
def test_bad_specs_name_the_field(text, field):
    with pytest.raises(ValueError, match=field):
        parse_board(text)


def test_bad_spec_exits_2_with_one_line(capsys):
    from aicalib_tf.calibrate import main

    assert main(["x.png", "--board", "circles:7x6,spacing=20mm,symmetric,diameter=25mm"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "diameter" in err[0]


def test_too_small_grid():
    with pytest.raises(ValueError, match="grid"):
        CircleGrid((2, 2), 10.0, "symmetric")


def test_rigs_refuse_circle_grids(capsys):
    from aicalib_tf.calibrate import main

    assert main(["--rig", "a=x/*.png", "b=y/*.png", "--board", "circles:4x11,spacing=20mm,asymmetric"]) == 2
    assert "photos of one camera" in capsys.readouterr().err
