"""Batches over a process pool: the same results as one process, in order, failures as values."""

import json
import os
from pathlib import Path

import pytest

from aicalib_tf.detect.batch import MIN_ITEMS_PER_WORKER, default_workers, map_images, worker_count

DATA = Path(__file__).resolve().parents[1] / "data" / "opencv_left"


def _setup(offset):
    pid = os.getpid()

    def work(item):
        if item < 0:
            return ("failed", item)
        return (item + offset, pid)
    return work


def test_pool_results_are_in_order_and_match_one_process():
    items = [5, -1, 3, 8, 0, 2, 7]
    serial = list(map_images(items, _setup, (10,), workers=1))
    pooled = list(map_images(items, _setup, (10,), workers=2))
    assert [r[0] for r in serial] == [r[0] for r in pooled] == [15, "failed", 13, 18, 10, 12, 17]
    assert {r[1] for r in serial if r[0] != "failed"} == {os.getpid()}
    assert os.getpid() not in {r[1] for r in pooled if r[0] != "failed"}  # the work ran in the workers


def test_worker_count_is_bounded_by_items_and_checked():
    assert worker_count(4, 2) == 2 and worker_count(1, 10) == 1 and worker_count(None, 1) == 1
    assert worker_count(None, MIN_ITEMS_PER_WORKER - 1) == 1  # a small batch runs in this process
    assert worker_count(None, 100 * MIN_ITEMS_PER_WORKER) == default_workers()
    with pytest.raises(ValueError, match="--workers must be >= 1, got 0"):
        worker_count(0, 3)


def test_detect_cli_with_two_workers_writes_what_one_process_writes(tmp_path, capsys):
    from aicalib_tf.detect.__main__ import main

    bad = tmp_path / "broken.jpg"
    bad.write_bytes(b"not an image")
    files = [str(DATA / "left01.jpg"), str(bad), str(DATA / "left02.jpg"), str(DATA / "left03.jpg")]
    outputs = {}
    for workers in (1, 2):
        out = tmp_path / f"w{workers}"
        assert main(files + ["--pattern", "9x6", "--out", str(out), "--quiet", "--workers", str(workers)]) == 0
        printed = capsys.readouterr().out
        assert "4 images: 3 full boards" in printed and "1 unreadable" in printed and "broken.jpg" in printed
        outputs[workers] = {p.name: json.loads(p.read_text()) for p in sorted(out.glob("*.json"))}
    assert list(outputs[1]) == ["left01.json", "left02.json", "left03.json"]
    assert outputs[1] == outputs[2]
