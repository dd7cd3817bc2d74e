from pathlib import Path

import cv2
import numpy as np
import pytest

from aicalib_tf.io import ImageError, atomic_write_text, load_image, to_gray_float


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


# ---- the image gate under hostile input -------------------------------------------------------------

import struct as _struct
import zlib as _zlib

from hypothesis import given as _given, settings as _settings, strategies as _st


def _png_header_only(w: int, h: int) -> bytes:
    """A PNG whose header claims w x h px, with one tiny compressed row (a decompression bomb's shape)."""
    def chunk(kind, data):
        return _struct.pack(">I", len(data)) + kind + data + _struct.pack(">I", _zlib.crc32(kind + data) & 0xFFFFFFFF)
    ihdr = _struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", _zlib.compress(b"\0" * (w + 1))) + chunk(b"IEND", b"")


def test_a_decompression_bomb_is_refused_from_its_header_fast_and_small(tmp_path):
    import resource
    import time

    from aicalib_tf.io import ImageError, load_image

    path = tmp_path / "bomb.png"
    path.write_bytes(_png_header_only(30000, 30000))
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    with pytest.raises(ImageError, match="30000x30000 px is over the limit"):
        load_image(path)
    assert time.perf_counter() - t0 < 1.0
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before < 100 * 1024  # KiB: nothing decoded


def test_the_pixel_cap_is_configurable(tmp_path, monkeypatch):
    from aicalib_tf.io import ImageError, load_image

    path = tmp_path / "small.png"
    cv2.imwrite(str(path), np.zeros((40, 50), np.uint8))
    monkeypatch.setenv("AICALIB_MAX_PIXELS", "1000")
    with pytest.raises(ImageError, match="50x40 px is over the limit of 0.001 MP"):
        load_image(path)
    monkeypatch.setenv("AICALIB_MAX_PIXELS", "2000")
    assert load_image(path).shape == (40, 50)


def test_an_unreadable_file_is_an_image_error_naming_it(tmp_path, monkeypatch):
    from aicalib_tf.io import ImageError, load_image

    path = tmp_path / "locked.png"
    cv2.imwrite(str(path), np.zeros((4, 4), np.uint8))

    def denied(*a, **k):
        raise PermissionError(13, "Permission denied", str(path))
    monkeypatch.setattr(np, "fromfile", denied)
    with pytest.raises(ImageError, match="locked.png: Permission denied"):
        load_image(path)


@_settings(max_examples=150, deadline=None)
@_given(data=_st.one_of(
    _st.binary(max_size=300),
    _st.builds(lambda w, h, tail: _png_header_only(w, h)[: 33 + tail], _st.integers(1, 70000), _st.integers(1, 70000),
               _st.integers(0, 60)),
    _st.builds(lambda cut: cv2.imencode(".jpg", np.full((32, 32), 128, np.uint8))[1].tobytes()[:cut], _st.integers(0, 700)),
))
def test_any_bytes_give_a_grey_image_or_an_image_error(tmp_path_factory, data):
    from aicalib_tf.io import ImageError, load_image

    path = tmp_path_factory.mktemp("fuzz") / "x.img"
    path.write_bytes(data)
    try:
        img = load_image(path)
    except ImageError as exc:
        assert "x.img" in str(exc)
        return
    assert img.dtype == np.float32 and img.ndim == 2 and np.isfinite(img).all()


@_settings(max_examples=60, deadline=None)
@_given(dtype=_st.sampled_from([np.bool_, np.int8, np.int32, np.int64, np.float16, np.float32, np.float64,
                                np.complex64, np.uint8, np.uint16]),
        shape=_st.lists(_st.integers(0, 5), min_size=0, max_size=4))
def test_any_array_gives_a_grey_image_or_an_image_error(dtype, shape):
    from aicalib_tf.io import ImageError, load_image

    a = np.zeros(shape, dtype)
    try:
        img = load_image(a)
    except ImageError:
        return
    assert img.dtype == np.float32 and img.ndim == 2


@pytest.mark.parametrize("dtype, channels", [(np.uint8, 0), (np.uint16, 0), (np.uint8, 3), (np.float64, 0), (np.float32, 4)])
def test_to_gray_float_scales_exactly_into_a_new_array(dtype, channels):
    rng = np.random.default_rng(3)
    shape = (37, 53) if not channels else (37, 53, channels)
    top = np.iinfo(dtype).max if np.dtype(dtype).kind == "u" else 1.0
    a = (rng.integers(0, top + 1, shape) if np.dtype(dtype).kind == "u" else rng.random(shape)).astype(dtype)
    want = a.astype(np.float32) * np.float32(1.0 / top)
    if channels:
        want = cv2.cvtColor(want, cv2.COLOR_BGRA2GRAY if channels == 4 else cv2.COLOR_BGR2GRAY)
    got = to_gray_float(a)
    assert got.dtype == np.float32 and got.min() >= 0.0 and got.max() <= 1.0
    np.testing.assert_array_equal(got, np.clip(want, 0.0, 1.0))
    assert not np.shares_memory(got, a)


def test_read_image_checks_like_load_image_and_leaves_the_pixels_as_they_are(tmp_path):
    from aicalib_tf.io import ImageError, load_image, read_image

    colour = np.random.default_rng(2).integers(0, 256, (12, 17, 3)).astype(np.uint8)
    path = tmp_path / "c.png"
    cv2.imwrite(str(path), colour)
    raw = read_image(path)
    assert raw.dtype == np.uint8 and raw.shape == (12, 17, 3) and np.array_equal(raw, colour)
    assert read_image(colour[:, :, :1]).shape == (12, 17)  # one channel: its grey
    np.testing.assert_array_equal(load_image(path), to_gray_float(raw))
    for bad in (np.zeros((4, 4, 2), np.uint8), np.full((3, 3), 2.0, np.float32)):
        with pytest.raises(ImageError):
            read_image(bad)


def _tree(root: Path) -> None:
    """A folder of images with hidden entries, a linked folder outside, and two symbolic-link loops."""
    for name in ("x.png", "a/y.png", "a/b/z.png", "a/.dot.png", ".hid/v.png", "a/b/.h/w.png", "other/q.png"):
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_bytes(b"")
    (root / "tree" / "a").mkdir(parents=True)
    for name in ("x.png", "a", ".hid"):
        (root / name).rename(root / "tree" / name)
    (root / "tree" / "a" / "b" / "up").symlink_to("../..")  # a loop back to the tree's top
    (root / "tree" / "a" / "self").symlink_to(".")  # a loop onto itself
    (root / "tree" / "a" / "ext").symlink_to(root / "other")  # a folder outside the tree: followed once
    (root / "tree" / "ext2").symlink_to(root / "other")
    (root / "tree" / "a" / "b" / "out").symlink_to(root)  # the folder above the tree (holding it): walked once
    (root / "stray.png").write_bytes(b"")


def test_a_recursive_glob_over_symlink_loops_ends_and_takes_each_folder_once(tmp_path):
    import time

    from aicalib_tf.io import expand_images

    _tree(tmp_path)
    t0 = time.monotonic()
    got = expand_images([str(tmp_path / "tree" / "**" / "*.png")])
    assert time.monotonic() - t0 < 2.0
    rel = sorted(str(Path(p).relative_to(tmp_path / "tree")) for p in got)
    assert rel == ["a/b/out/stray.png", "a/b/z.png", "a/y.png", "ext2/q.png", "x.png"]  # no hidden names, as glob


def test_a_recursive_glob_matches_what_glob_gives_on_a_tree_without_loops(tmp_path, monkeypatch):
    import glob

    from aicalib_tf.io import expand_images

    for name in ("x.png", "a/y.jpg", "a/b/z.png", "a/.d.png", "c/d/e/f.png", ".h/g.png"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_bytes(b"")
    monkeypatch.chdir(tmp_path)
    for pattern in ("**/*.png", "**/*.*", "*/**/*.png", "**/b/*.png", "**/.*", "a/**/*", str(tmp_path / "**" / "*.jpg")):
        assert expand_images([pattern]) == sorted(p.rstrip("/") for p in glob.glob(pattern, recursive=True)), pattern


@pytest.mark.parametrize("text, shown", [
    ("http://user:secret@host/cam.mjpg", "http://user:***@host/cam.mjpg"),
    ("error: rtsp://admin:p@ss:w0rd@10.0.0.1:554/s: cannot open", "error: rtsp://admin:***@10.0.0.1:554/s: cannot open"),
    ("rtsp://admin@host/s and HTTPS://:tok@h/x", "rtsp://admin@host/s and HTTPS://:***@h/x"),
    ("http://host:8080/a.mp4 photos/left:01.png", "http://host:8080/a.mp4 photos/left:01.png"),
    ("rtsp://cam/live?user=admin&password=hunter2&channel=1", "rtsp://cam/live?user=admin&password=***&channel=1"),
    ("http://h/s.mjpg?TOKEN=abc#x", "http://h/s.mjpg?TOKEN=***#x"),
    ("error: rtsp://h/s?pwd=a:b: cannot open", "error: rtsp://h/s?pwd=***: cannot open"),
])
def test_a_urls_password_is_redacted(text, shown):
    from aicalib_tf.io import redact_credentials

    assert redact_credentials(text) == shown


@pytest.mark.parametrize("command", ["calibrate", "detect"])
def test_calibrate_and_detect_end_over_a_symlink_loop(tmp_path, command):
    import os
    import shutil
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    (tmp_path / "photos" / "a").mkdir(parents=True)
    (tmp_path / "photos" / "a" / "up").symlink_to("..")
    (tmp_path / "photos" / "a" / "twice").symlink_to("../..")
    shutil.copy(root / "tests" / "data" / "opencv_left" / "left01.jpg", tmp_path / "photos" / "a")
    args = [str(tmp_path / "photos" / "**" / "*.jpg"), "--pattern", "9x6", "--out", str(tmp_path / "out")]
    args += ["--detector", "opencv"] if command == "calibrate" else []
    proc = subprocess.run([sys.executable, "-m", f"aicalib_tf.{command}", *args], capture_output=True, text=True,
                          timeout=120, cwd=root, env=dict(os.environ, PYTHONPATH=str(root)))
    if command == "calibrate":  # one photo found, once: too few views
        assert proc.returncode == 2 and "error: 1 usable views" in proc.stderr, proc.stderr
    else:
        assert proc.returncode == 0 and "1 images: 1 full boards" in proc.stdout + proc.stderr, proc.stderr


def test_a_recursive_glob_goes_any_depth_and_any_number_of_double_stars(tmp_path):
    import time

    from aicalib_tf.io import expand_images

    deep = tmp_path
    for _ in range(1200):  # glob.glob(recursive=True) raises RecursionError here
        deep = deep / "d"
        deep.mkdir()
    (deep / "x.png").write_bytes(b"")
    try:
        t0 = time.monotonic()
        assert expand_images([str(tmp_path / "**" / "*.png")]) == [str(deep / "x.png")]
        assert expand_images([str(tmp_path / "/".join(["**"] * 12) / "d" / "*.png")]) == [str(deep / "x.png")]
        assert time.monotonic() - t0 < 5.0
    finally:  # removed from the bottom up: pytest's own clean-up (shutil.rmtree) recurses too deep here
        (deep / "x.png").unlink()
        while deep != tmp_path:
            deep.rmdir()
            deep = deep.parent
