"""The one error path of the command lines (aicalib_tf.cli) and a fuzz of their argument space.

The property: whatever the arguments, a command line exits 0 or 2, and on 2 its stderr is one
``error:`` line (argparse's usage errors aside), never a traceback.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from aicalib_tf import calibrate
from aicalib_tf.cli import run_main
from aicalib_tf.detect import __main__ as detect_cli

ROOT = Path(__file__).resolve().parents[1]
LEFT = ROOT / "tests" / "data" / "opencv_left"


def _one_error_line(err: str) -> None:
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith(("note:", "warning:"))]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err


def test_an_unexpected_exception_is_one_line_that_asks_for_a_report(capsys):
    def body():
        raise KeyError("x") if False else ZeroDivisionError("division by zero")

    assert run_main(body) == 2
    err = capsys.readouterr().err
    _one_error_line(err)
    assert "please report" in err and "ZeroDivisionError" in err


def test_debug_shows_the_traceback(capsys):
    assert run_main(lambda: 1 / 0, debug=True) == 2
    assert "Traceback" in capsys.readouterr().err


def test_an_os_error_names_the_file(capsys):
    def body():
        open("/nonexistent/dir/file.txt")

    assert run_main(body) == 2
    assert capsys.readouterr().err.strip() == "error: /nonexistent/dir/file.txt: No such file or directory"


@pytest.mark.parametrize("case", ["file", "under_file", "dev_null", "dangling", "too_long", "foreign"])
def test_calibrate_refuses_a_bad_out_before_any_work(tmp_path, capsys, case):
    (tmp_path / "f").write_text("x")
    os.symlink(tmp_path / "nowhere", tmp_path / "link")
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("mine")
    out = {"file": tmp_path / "f", "under_file": tmp_path / "f" / "sub", "dev_null": "/dev/null",
           "dangling": tmp_path / "link", "too_long": tmp_path / ("y" * 300), "foreign": tmp_path / "mine"}[case]
    code = calibrate.main([str(LEFT / "left01.jpg"), "--pattern", "9x6", "--out", str(out), "--quiet"])
    assert code == 2
    _one_error_line(capsys.readouterr().err)
    assert (tmp_path / "mine" / "notes.txt").read_text() == "mine"


def test_detect_with_a_bad_pattern_leaves_no_out(tmp_path, capsys):
    out = tmp_path / "det"
    assert detect_cli.main([str(LEFT / "left01.jpg"), "--pattern", "1x1", "--out", str(out)]) == 2
    _one_error_line(capsys.readouterr().err)
    assert not out.exists()


def test_detect_goes_on_past_unreadable_files_and_names_them(tmp_path, capsys):
    (tmp_path / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\nnot really")
    out = tmp_path / "det"
    code = detect_cli.main([str(LEFT / "left01.jpg"), str(tmp_path / "broken.png"), str(tmp_path / "a missing.png"),
                            "--pattern", "9x6", "--out", str(out), "--quiet", "--workers", "1"])
    text = capsys.readouterr().out
    assert code == 0 and "2 unreadable" in text and "broken.png" in text and "a missing.png: no such file" in text
    assert (out / "left01.json").exists()


def test_calibrate_reads_non_utf8_and_bracketed_file_names(tmp_path):
    """File names that are not UTF-8 (once a crash in the preview) and a literal '[' in a name."""
    folder = os.fsencode(tmp_path)
    for k, name in enumerate(["left01.jpg", "left02.jpg", "left03.jpg", "left04.jpg", "left05.jpg", "left06.jpg"]):
        target = os.path.join(folder, b"photo_\xff\xfe_%d.jpg" % k) if k % 2 else os.path.join(folder, b"shot[%d].jpg" % k)
        shutil.copyfile(LEFT / name, target)
    images = [os.fsdecode(os.path.join(folder, n)) for n in sorted(os.listdir(folder))]
    proc = subprocess.run([sys.executable, "-m", "aicalib_tf.calibrate", *images, "--pattern", "9x6", "--model",
                           "plumb_bob", "--out", str(tmp_path / "c"), "--quiet"], capture_output=True, cwd=ROOT,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert proc.returncode == 0, proc.stderr.decode(errors="replace")
    assert b"6 images: 6 used" in proc.stdout
    assert (tmp_path / "c" / "undistorted.png").exists()


_TEXT = st.text(alphabet=st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"), max_size=12)
_OPTION_VALUES = {
    "--pattern": st.one_of(st.sampled_from(["9x6", "1x1", "0x0", "9x", "x", "99999999999999999999x6", "9×6"]), _TEXT),
    "--square": st.one_of(st.sampled_from(["25mm", "0", "-25", "1e30", "nan", "inf", "25furlong", "1e-30"]), _TEXT),
    "--model": st.one_of(st.sampled_from(["auto", "plumb_bob", "equidistant", "nonsense", "a,b", "default"]), _TEXT),
    "--detector": st.sampled_from(["cnn", "opencv", "bogus"]),
    "--resize-policy": st.sampled_from(["error", "skip", "crop", "scale", "bogus"]),
    "--workers": st.sampled_from(["1", "0", "-3", "many"]),
}


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(options=st.dictionaries(st.sampled_from(sorted(_OPTION_VALUES)), st.none(), max_size=4).flatmap(
    lambda keys: st.fixed_dictionaries({k: _OPTION_VALUES[k] for k in keys})),
    images=st.lists(st.sampled_from(["missing.jpg", "garbage.png", "*.nothing", "[", ""]), min_size=0, max_size=2))
def test_calibrate_argument_fuzz_exits_0_or_2_with_one_line(tmp_path, capsys, options, images):
    capsys.readouterr()  # the fixture lives across examples: start from an empty capture
    (tmp_path / "garbage.png").write_bytes(os.urandom(64))
    argv = [str(tmp_path / i) if i else i for i in images] + ["--out", str(tmp_path / "out"), "--quiet"]
    for key, value in options.items():
        argv += [key, value]
    if "--pattern" not in options:
        argv += ["--pattern", "9x6"]
    try:
        code = calibrate.main(argv)
    except SystemExit as exc:  # argparse's own usage error
        code = exc.code
        assert code == 2
        return
    err = capsys.readouterr().err
    assert code == 2
    _one_error_line(err)
    assert not (tmp_path / "out").exists()


def test_out_of_memory_is_one_line_and_debug_shows_its_traceback(capsys):
    def body():
        raise MemoryError()

    assert run_main(body) == 2
    _one_error_line(capsys.readouterr().err)
    assert run_main(body, debug=True) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: out of memory") and "Traceback" in err and "MemoryError" in err
