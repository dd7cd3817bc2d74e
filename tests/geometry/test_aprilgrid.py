"""Kalibr's AprilGrid description: the text form, Kalibr's target files, the lattice and the layout."""

import numpy as np
import pytest

from aicalib_tf.geometry.aprilgrid import (
    AprilGrid, Checkerboard, corner_count, layout_image, load_board, parse_board, read_kalibr_target)


def kalibr_points(cols, rows, tag, spacing):
    """Kalibr's corner positions (its own frame: y up from the bottom-left tag), row-major by corner row."""
    pts = []
    for r in range(2 * rows):
        for c in range(2 * cols):
            pts.append(((c // 2) * (1 + spacing) * tag + (c % 2) * tag, (r // 2) * (1 + spacing) * tag + (r % 2) * tag))
    return np.array(pts)


def test_parse_and_describe_round_trip():
    b = parse_board("aprilgrid:6x5,tag=88mm,spacing=0.3,family=tag36h11,first=4")
    assert (b.tags, b.tag, b.spacing, b.first_id, b.unit) == ((6, 5), 88.0, 0.3, 4, "mm")
    assert b.fraction == (3, 10) and b.square_size == pytest.approx(8.8)
    assert b.pattern_size == (5 * 13 + 11, 4 * 13 + 11)
    assert parse_board(b.describe()) == b


def test_lattice_points_are_kalibrs_corners():
    for spec, (cols, rows, tag, sp) in [("aprilgrid:6x6,tag=88mm,spacing=0.3", (6, 6, 88.0, 0.3)),
                                       ("aprilgrid:4x3,tag=0.05m,spacing=0.25", (4, 3, 0.05, 0.25))]:
        b = parse_board(spec)
        ours = b.object_points()
        theirs = kalibr_points(cols, rows, tag, sp)
        height = (rows - 1) * (1 + sp) * tag + tag
        # ours is Kalibr's with y flipped about the grid's height; rows counted from the top
        ours_as_kalibr = np.c_[ours[:, 0], height - ours[:, 1]]
        assert np.allclose(np.sort(ours_as_kalibr.view(complex).ravel()), np.sort(theirs.view(complex).ravel()))
        # ids on the lattice: every corner's id is a whole lattice position
        assert np.allclose(ours[:, :2] / b.square_size, b.corner_ids())


def test_tag_ids_number_from_the_bottom_left():
    b = parse_board("aprilgrid:3x2,tag=10mm,spacing=0.5")
    assert b.tag_cell(0).tolist() == [0, 1] and b.tag_cell(2).tolist() == [2, 1] and b.tag_cell(3).tolist() == [0, 0]
    # the tag's top-left corner on the page, printed upright (rotation 0)
    assert b.tag_corner_ids(3, rotation=0)[0].tolist() == [0, 0]
    assert b.tag_corner_ids(0, rotation=0).tolist() == [[0, 3], [2, 3], [2, 5], [0, 5]]


@pytest.mark.parametrize("spec, field", [
    ("aprilgrid:6x6,tag=88mm,spacing=1", "spacing"), ("aprilgrid:6x6,tag=88mm,spacing=0", "spacing"),
    ("aprilgrid:6x6,tag=88mm,spacing=1.5", "spacing"), ("aprilgrid:6x6,tag=88mm,spacing=0.3,family=tag99h1", "family"),
    ("aprilgrid:6x6,spacing=0.3", "tag="), ("aprilgrid:6x6,tag=88mm", "spacing="),
    ("aprilgrid:6x6,tag=88mm,spacing=0.3333", "spacing"), ("aprilgrid:6x6,tag=88mm,spacing=0.3,first=586", "first"),
    ("aprilgrid:6x6,tag=88qq,spacing=0.3", "tag="), ("aprilgrid:1x6,tag=88mm,spacing=0.3", "tags"),
])
def test_bad_specs_name_the_field(spec, field):
    with pytest.raises(ValueError, match=field):
        parse_board(spec)


def test_kalibr_yaml_aprilgrid_and_checkerboard(tmp_path):
    f = tmp_path / "april_6x6.yaml"
    f.write_text("target_type: 'aprilgrid' #gridtype\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\n")
    b = load_board(str(f))
    assert isinstance(b, AprilGrid) and b.tags == (6, 6) and b.tag == 0.088 and b.unit == "m" and b.spacing == 0.3
    assert corner_count(str(f)) == 144 and corner_count("charuco:5x5,square=1,marker=0.5,dict=DICT_4X4_50") is None
    c = tmp_path / "checker.yaml"
    c.write_text("target_type: 'checkerboard'\ntargetCols: 9\ntargetRows: 6\nrowSpacingMeters: 0.025\ncolSpacingMeters: 0.025\n")
    assert read_kalibr_target(str(c)) == Checkerboard((9, 6), 0.025, "m")


@pytest.mark.parametrize("text, field", [
    ("target_type: 'circlegrid'\ntargetCols: 6\n", "target_type"),
    ("target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\n", "tagSpacing"),
    ("target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 1.2\n", "tagSpacing: "),
    ("target_type: aprilgrid\ntagCols: 1\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\n", "tagCols, tagRows: "),
    ("target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\nrowSpacingMeters: 0.02\ncolSpacingMeters: 0.03\n",
     "rowSpacingMeters"),
    ("target_type: aprilgrid\ntagCols: six\n", "tagCols"),
])
def test_bad_kalibr_yaml_names_the_field(tmp_path, text, field):
    f = tmp_path / "target.yaml"
    f.write_text(text)
    with pytest.raises(ValueError, match=field) as e:
        load_board(str(f))
    assert str(f) in str(e.value)


def test_layout_has_corner_squares_and_tags():
    b = parse_board("aprilgrid:2x2,tag=80mm,spacing=0.3")
    q, m = 4, 3 * 4 + 4
    img = layout_image(b, q, m)
    a, d = b.fraction
    assert img.shape == ((2 * a + 2 * d) * q - a * q + 2 * m,) * 2
    g, t = a * q, d * q
    # the square at the first tag's top-left corner is black, the gaps beside it white
    assert (img[m - g: m, m - g: m] == 0).all()
    assert (img[m - g: m, m + 2: m + t - 2] == 255).all() and (img[m + 2: m + t - 2, m - g: m] == 255).all()
    # a tag's two-bit border is black
    bit = t // (b.bits + 4)
    assert (img[m: m + 2 * bit, m: m + t] == 0).all()


@pytest.mark.parametrize("board, field", [("aprilgrid:6x6,tag=88mm,spacing=1", "spacing"),
                                          ("aprilgrid:6x6,tag=88mm,spacing=0.3,family=tag99", "family")])
def test_calibrate_refuses_a_bad_grid_in_one_line(tmp_path, capsys, board, field):
    from aicalib_tf.calibrate import main

    assert main([str(tmp_path / "x.png"), "--board", board, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and field in err[0]
    f = tmp_path / "target.yaml"
    f.write_text("target_type: circlegrid\n")
    assert main([str(tmp_path / "x.png"), "--board", str(f)]) == 2
    assert "target_type" in capsys.readouterr().err


def test_printed_tags_are_kalibrs_codes_upright():
    from aicalib_tf.geometry.aprilgrid import tag_image

    b = parse_board("aprilgrid:6x6,tag=88mm,spacing=0.3")
    # tag36h11's first codes (the AprilTag family), read from the printed tag: rows from the top,
    # most significant bit first, a set bit white, inside the two-bit border
    for tag_id, code in [(0, 0xD5D628584), (1, 0xD97F18B49), (2, 0xDD280910E)]:
        img = tag_image(b, tag_id, 10 * 10)
        cells = img[25::10, 25::10][:6, :6] > 127
        assert int("".join("1" if v else "0" for v in cells.ravel()), 2) == code
