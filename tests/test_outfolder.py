"""aicalib_tf.outfolder: the --out checks, the swap, the lock, and kills during the write phase."""

from __future__ import annotations

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
WRITER = """
import sys, time
from aicalib_tf.outfolder import OutputFolder
from aicalib_tf.io import atomic_write_text
out, run = sys.argv[1], sys.argv[2]
with OutputFolder(out, "calibration") as f:
    print("writing", flush=True)
    for name in {files!r}:
        atomic_write_text(f.path / name, run * 2000)
        time.sleep(0.01)
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


def test_a_second_run_replaces_the_whole_set(tmp_path):
    out = tmp_path / "c"
    _write(out, "run00001")
    (out / "undistorted_old.png").write_text("x")  # a file the new run does not write
    _write(out, "run00002")
    assert _run_ids(out) == {"run00002"} and not (out / "undistorted_old.png").exists()


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
    """60 runs killed (SIGKILL) at spread-out moments after their write phase began."""
    out = tmp_path / "c"
    _write(out, "run00000")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    kills, outcomes = 60, set()
    for k in range(1, kills + 1):
        run = f"run{k:05d}"
        before = _run_ids(out)
        proc = subprocess.Popen([sys.executable, "-c", WRITER, str(out), run], stdout=subprocess.PIPE, env=env)
        assert proc.stdout.readline().strip() == b"writing"
        time.sleep((k % 10) * 0.007)  # from the first file to past the swap
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        ids = _run_ids(out) if out.exists() else set()
        assert ids in (before, {run}), f"kill {k}: a mix of runs {ids}"
        assert len([n for n in FILES if (out / n).exists()]) == len(FILES)
        outcomes.add("new" if ids == {run} else "old")
    assert outcomes == {"old", "new"}  # the kills landed both before and after the swap
    _write(out, "run99999")  # the next run cleans up what the killed ones left
    assert not list(tmp_path.glob(".aicalib-*.tmp-*")) and not list(tmp_path.glob(".aicalib-*.old-*"))
