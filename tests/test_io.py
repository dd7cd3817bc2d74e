from pathlib import Path

import numpy as np
import pytest

from aicalib_tf.io import ImageError, atomic_write_text, load_image


def test_gate_accepts_gray_colour_uint8_uint16(tmp_path):
    g = np.full((4, 5), 255, np.uint8)
    assert load_image(g).dtype == np.float32 and load_image(g).max() == 1.0
    assert load_image(np.full((4, 5, 3), 65535, np.uint16)).shape == (4, 5)
    assert load_image(np.zeros((4, 5, 4), np.uint8)).max() == 0.0


@pytest.mark.parametrize(
    "arr, msg",
    [
        (np.zeros((0, 5), np.uint8), "empty"),
        (np.zeros((4, 5, 2), np.uint8), "shape"),
        (np.array([[np.nan, 0.0]]), "NaN"),
        (np.zeros((4, 4), np.int64), "dtype"),
    ],
)
def test_gate_rejects_bad_arrays(arr, msg):
    with pytest.raises(ImageError, match=msg):
        load_image(arr)


def test_gate_names_the_bad_file(tmp_path):
    bad = tmp_path / "broken.jpg"
    bad.write_bytes(b"\xff\xd8\xff\xe0 not really a jpeg")
    with pytest.raises(ImageError, match="broken.jpg"):
        load_image(bad)
    with pytest.raises(ImageError, match="no such file"):
        load_image(tmp_path / "missing.png")


def test_atomic_write_leaves_no_temporary_files(tmp_path):
    p = atomic_write_text(tmp_path / "a" / "x.txt", "hello")
    assert p.read_text() == "hello"
    assert [f.name for f in p.parent.iterdir()] == ["x.txt"]


def test_float_images_outside_0_1_are_an_error():
    with pytest.raises(ImageError, match=r"\[0, 1\].*255"):
        load_image(np.full((4, 4), 255.0, np.float32))


def test_truncated_jpeg_is_refused_by_name(tmp_path):
    from aicalib_tf.io import ImageError, load_image

    data = (Path(__file__).resolve().parent / "data" / "opencv_left" / "left01.jpg").read_bytes()
    (tmp_path / "cut.jpg").write_bytes(data[: len(data) * 3 // 4])
    with pytest.raises(ImageError, match="cut.jpg: truncated JPEG"):
        load_image(tmp_path / "cut.jpg")


def test_expand_images_globs_sorts_and_dedupes(tmp_path):
    from aicalib_tf.io import expand_images

    for n in ("b.jpg", "a.jpg", "c.png"):
        (tmp_path / n).write_bytes(b"x")
    got = expand_images([str(tmp_path / "*.jpg"), str(tmp_path / "a.jpg"), str(tmp_path / "missing.png")])
    assert [Path(p).name for p in got] == ["a.jpg", "b.jpg", "missing.png"]
