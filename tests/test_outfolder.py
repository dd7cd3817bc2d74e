"""aicalib_tf.outfolder: the --out checks, the swap, the lock, and kills during the write phase."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from aicalib_tf.outfolder import MARKER, OutputFolder, check_out_path

ROOT = Path(__file__).resolve().parents[1]
FILES = ("camera.yaml", "camera.json", "camera_info.yaml", "report.png", "report.txt")

# A writer that fills a folder with one run's files slowly, so that a kill lands inside the write phase.
# One process imports the package once and forks a fresh writer for each run name read from stdin
# (a new interpreter per run spent ~0.2 s of CPU on imports, 60 times): the writer prints its pid and
# "writing", and this process prints "done" once it has ended, killed or not.
WRITERS = """
import os, sys, time
from aicalib_tf.outfolder import OutputFolder
from aicalib_tf.io import atomic_write_text
out = sys.argv[1]
for line in iter(sys.stdin.readline, ""):
    pid = os.fork()
    if pid == 0:
        with OutputFolder(out, "calibration") as f:
            print(os.getpid(), "writing", flush=True)
            for name in {files!r}:
                atomic_write_text(f.path / name, line.strip() * 2000)
                time.sleep(0.01)
        os._exit(0)
    os.waitpid(pid, 0)
    print("done", flush=True)
""".format(files=FILES)


def _run_ids(folder: Path) -> set[str]:
    return {(folder / n).read_text()[:8] for n in FILES if (folder / n).exists()}


def _write(out: Path, run: str) -> None:
    with OutputFolder(out) as f:
        for name in FILES:
            (f.path / name).write_text(run * 2000)


def test_new_folder_gets_the_files_and_the_marker_and_nothing_is_left_beside(tmp_path):
    _write(tmp_path / "c", "run00001")
    assert _run_ids(tmp_path / "c") == {"run00001"} and (tmp_path / "c" / MARKER).exists()
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.endswith(".lock")) == ["c"]


def test_a_second_run_replaces_the_whole_set_of_the_first_runs_files(tmp_path):
    out = tmp_path / "c"
    with OutputFolder(out) as f:
        for name in (*FILES, "undistorted_old.png"):
            (f.path / name).write_text("run00001" * 2000)
    _write(out, "run00002")  # does not write undistorted_old.png: the first run's copy goes
    assert _run_ids(out) == {"run00002"} and not (out / "undistorted_old.png").exists()
    assert json.loads((out / MARKER).read_text()) == {"kind": "output", "files": sorted(FILES)}


def test_the_users_files_in_a_written_folder_are_kept(tmp_path):
    out = tmp_path / "c"
    _write(out, "run00001")
    (out / "notes.txt").write_text("mine")
    (out / "undistorted_extra.png").write_text("mine too")  # a name aicalib_tf could write, but this run did not
    (out / "sub").mkdir()
    (out / "sub" / "a.txt").write_text("deep")
    os.symlink("notes.txt", out / "link")
    _write(out, "run00002")
    _write(out, "run00003")
    assert _run_ids(out) == {"run00003"}
    assert (out / "notes.txt").read_text() == "mine" and (out / "undistorted_extra.png").read_text() == "mine too"
    assert (out / "sub" / "a.txt").read_text() == "deep" and os.readlink(out / "link") == "notes.txt"
    assert json.loads((out / MARKER).read_text())["files"] == sorted(FILES)
    assert sorted(p.name for p in tmp_path.iterdir() if not p.name.endswith(".lock")) == ["c"]


def test_a_users_file_with_the_name_of_a_new_file_stops_the_run_and_keeps_the_folder(tmp_path):
    out = tmp_path / "c"
    with OutputFolder(out) as f:
        (f.path / "camera.yaml").write_text("run00001")
    (out / "report.txt").write_text("my own report")  # the next run writes report.txt
    with pytest.raises(ValueError, match=r"report\.txt: a file aicalib_tf did not write"):
        _write(out, "run00002")
    assert (out / "report.txt").read_text() == "my own report" and (out / "camera.yaml").read_text() == "run00001"
    assert not list(tmp_path.glob(".aicalib-*.tmp-*"))


def test_an_older_marker_without_a_file_list_keeps_unknown_names(tmp_path):
    out = tmp_path / "c"
    out.mkdir()
    (out / MARKER).write_text("calibration\n")  # the marker of an older version
    for name in ("camera.yaml", "undistorted_a.png", "notes.txt"):
        (out / name).write_text("old")
    _write(out, "run00005")
    assert _run_ids(out) == {"run00005"} and (out / "notes.txt").read_text() == "old"
    assert not (out / "undistorted_a.png").exists()


def test_an_error_leaves_the_old_folder_untouched(tmp_path):
    out = tmp_path / "c"
    _write(out, "run00001")
    with pytest.raises(RuntimeError):
        with OutputFolder(out) as f:
            (f.path / "camera.yaml").write_text("half")
            raise RuntimeError("boom")
    assert _run_ids(out) == {"run00001"}
    assert not list(tmp_path.glob(".aicalib-*.tmp-*"))


@pytest.mark.parametrize("case", ["file", "under_file", "dev_null", "dangling", "too_long", "empty"])
def test_bad_out_is_refused_before_any_work(tmp_path, case):
    (tmp_path / "f").write_text("x")
    os.symlink(tmp_path / "nowhere", tmp_path / "link")
    out = {"file": tmp_path / "f", "under_file": tmp_path / "f" / "sub", "dev_null": Path("/dev/null"),
           "dangling": tmp_path / "link", "too_long": tmp_path / ("x" * 300), "empty": ""}[case]
    with pytest.raises((ValueError, OSError)) as err:
        OutputFolder(out)
    assert str(out) in str(err.value) or case in ("empty", "too_long")
    assert (tmp_path / "f").read_text() == "x"


def test_a_folder_of_someone_elses_files_is_not_replaced(tmp_path):
    (tmp_path / "photos").mkdir()
    (tmp_path / "photos" / "left01.jpg").write_text("a photo")
    with pytest.raises(ValueError, match="did not write"):
        OutputFolder(tmp_path / "photos")
    assert (tmp_path / "photos" / "left01.jpg").read_text() == "a photo"


def test_an_older_calibration_folder_without_the_marker_is_replaceable(tmp_path):
    out = tmp_path / "c"
    out.mkdir()
    for name in ("camera.yaml", "camera.json", "undistorted_left01.png"):
        (out / name).write_text("old")
    _write(out, "run00003")
    assert _run_ids(out) == {"run00003"}


def test_two_runs_into_one_folder_do_not_mix(tmp_path):
    first = OutputFolder(tmp_path / "c")
    with pytest.raises(ValueError, match="another run"):
        OutputFolder(tmp_path / "c")
    first.abort()
    _write(tmp_path / "c", "run00004")  # the lock is free again
    assert _run_ids(tmp_path / "c") == {"run00004"}


def test_a_symlink_to_a_folder_replaces_the_target(tmp_path):
    (tmp_path / "real").mkdir()
    os.symlink(tmp_path / "real", tmp_path / "link")
    assert check_out_path(tmp_path / "link") == (tmp_path / "real").resolve()


def test_kills_inside_the_write_phase_leave_the_old_set_or_the_new_set(tmp_path):
    """60 runs killed (SIGKILL) at spread-out moments after their write phase began; the user's file survives."""
    out = tmp_path / "c"
    _write(out, "run00000")
    (out / "notes.txt").write_text("the user's")  # kept through every kill
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    writers = subprocess.Popen([sys.executable, "-c", WRITERS, str(out)], stdin=subprocess.PIPE,
                               stdout=subprocess.PIPE, env=env, text=True)
    kills, outcomes = 60, set()
    for k in range(1, kills + 1):
        run = f"run{k:05d}"
        before = _run_ids(out)
        writers.stdin.write(run + "\n")
        writers.stdin.flush()
        pid, said = writers.stdout.readline().split()
        assert said == "writing"
        time.sleep((k % 10) * 0.007 * (1 + k // 20))  # from the first file to past the swap (longer later: a busy machine)
        try:
            os.kill(int(pid), signal.SIGKILL)
        except ProcessLookupError:  # it had finished and was waited for
            pass
        assert writers.stdout.readline().strip() == "done"  # the writer has ended
        ids = _run_ids(out) if out.exists() else set()
        assert ids in (before, {run}), f"kill {k}: a mix of runs {ids}"
        assert len([n for n in FILES if (out / n).exists()]) == len(FILES)
        assert (out / "notes.txt").read_text() == "the user's", f"kill {k}"
        outcomes.add("new" if ids == {run} else "old")
    writers.stdin.close()
    assert writers.wait(timeout=60) == 0
    assert outcomes == {"old", "new"}  # the kills landed both before and after the swap
    _write(out, "run99999")  # the next run cleans up what the killed ones left
    assert not list(tmp_path.glob(".aicalib-*.tmp-*")) and not list(tmp_path.glob(".aicalib-*.old-*"))


def test_calibrate_twice_into_one_folder_keeps_the_users_notes(tmp_path, capsys):
    from aicalib_tf.calibrate import main

    out = tmp_path / "calib"
    args = [str(ROOT / "tests" / "data" / "opencv_left" / "left0[1-5].jpg"), "--pattern", "9x6", "--square", "25mm",
            "--detector", "opencv", "--model", "plumb_bob", "--out", str(out)]
    assert main(args) == 0
    (out / "notes.txt").write_text("lens cap was dusty")
    os.utime(out / "camera.json", (0, 0))
    assert main(args) == 0, capsys.readouterr().err
    assert (out / "notes.txt").read_text() == "lens cap was dusty" and (out / "camera.json").stat().st_mtime > 0
    written = json.loads((out / MARKER).read_text())["files"]
    assert "camera.json" in written and written == sorted(p.name for p in out.iterdir() if p.name not in (MARKER, "notes.txt"))


@pytest.mark.parametrize("marker", ['{"kind": "x", "files": [{}]}', '{"files": "camera.yaml"}', "[1, 2]", "\0\0",
                                    '{"files": ["notes.txt", "camera.yaml"]}'])
def test_a_strange_marker_never_costs_a_users_file(tmp_path, marker):
    out = tmp_path / "c"
    out.mkdir()
    (out / MARKER).write_text(marker)
    (out / "notes.txt").write_text("mine")
    (out / "camera.yaml").write_text("old")
    _write(out, "run00006")
    assert _run_ids(out) == {"run00006"}
    if "notes.txt" in marker:  # the marker says a run wrote notes.txt: it goes like the rest of that run
        assert not (out / "notes.txt").exists()
    else:
        assert (out / "notes.txt").read_text() == "mine"
