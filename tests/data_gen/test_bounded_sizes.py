"""data_gen refuses what it cannot render in bounded memory or time, in one line and exit 2, before any work."""

from __future__ import annotations

import pytest

from data_gen import __main__ as data_gen_cli
from data_gen import video


def _one_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.mark.parametrize("size", ["8000x8000", "4001x3000"])
def test_a_size_beyond_the_pixel_bound_is_refused(tmp_path, capsys, size):
    """8000x8000, the documented maximum side, once ran out of memory at 7.2 GB with a traceback."""
    code = data_gen_cli.main(["--out", str(tmp_path / "d"), "--count", "1", "--preset", "clean", "--size", size])
    line = _one_line(capsys.readouterr().err)
    assert code == 2 and "12,000,000" in line and size in line
    assert not (tmp_path / "d").exists()


@pytest.mark.parametrize("seconds", ["1e9", "inf", "40000"])
def test_video_seconds_are_bounded_like_count(tmp_path, capsys, seconds):
    """--seconds 1e9 ran until killed."""
    code = video.main(["--out", str(tmp_path / "v"), "--seconds", seconds, "--quiet"])
    line = _one_line(capsys.readouterr().err)
    assert code == 2 and "1,000,000 frames" in line
    assert not (tmp_path / "v").exists()


def test_video_size_beyond_the_pixel_bound_is_refused(tmp_path, capsys):
    code = video.main(["--out", str(tmp_path / "v"), "--size", "11000x11000", "--quiet"])
    assert code == 2 and "121,000,000 pixels" in _one_line(capsys.readouterr().err)
