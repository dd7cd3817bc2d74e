"""python -m aicalib_tf.evaluate: end to end on a tiny setting, every output file; scoring; arguments."""

import csv
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from aicalib_tf.bench.conditions import all_conditions, named_conditions, select_conditions
from aicalib_tf.bench.detectors import Found, score_detection
from aicalib_tf.evaluate import main
from aicalib_tf.bench.photos import consensus_reference, degrade_photo, PHOTO_DEGRADATIONS
from aicalib_tf.bench.report import RESULT_COLUMNS, SUMMARY_COLUMNS

DATA = Path(__file__).resolve().parents[1] / "data" / "opencv_left"


def _grid(cols=9, rows=6):
    c, r = np.meshgrid(np.arange(cols), np.arange(rows))
    return np.stack([c.ravel() * 20.0 + 50, r.ravel() * 20.0 + 40], axis=1), np.stack([c.ravel(), r.ravel()], axis=1)


def _header(path: Path) -> list[str]:
    with open(path, newline="") as f:
        return next(csv.reader(f))


def _rows(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _check_links(report: Path) -> list[str]:
    text = report.read_text()
    links = re.findall(r"\]\(([^)]+)\)", text)
    assert links, "report.md links no figures"
    for link in links:
        target = report.parent / link
        assert target.is_file() and target.stat().st_size > 1000, f"broken or empty link {link}"
        assert target.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    return links


def test_quick_suite_end_to_end_writes_every_file(tmp_path, monkeypatch):
    import aicalib_tf.bench.runner as runner
    from aicalib_tf.bench.timing import retime_slowest

    # one more timing of each kept image instead of two (the two rounds are checked on their own below)
    monkeypatch.setattr(runner, "retime_slowest", lambda slowest, dets: retime_slowest(slowest, dets, runs=1))
    out = tmp_path / "rep"
    rc = main(["--quick", "--limit", "1", "--detectors", "cnn,opencv", "--out", str(out), "--quiet"])
    assert rc == 0
    for name in ("results.csv", "summary.csv", "calibration.csv", "report.md", "config.json"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    assert _header(out / "results.csv") == RESULT_COLUMNS
    assert _header(out / "summary.csv") == SUMMARY_COLUMNS
    results = _rows(out / "results.csv")
    conds = {c.name for c in all_conditions()} | {"calib"}
    assert {r["condition"] for r in results} == conds  # every named condition, sweep level and calib
    assert {r["detector"] for r in results} == {"cnn", "opencv"}
    assert all(0 < float(r["time_ms"]) <= float(r["time_first_ms"]) for r in results)
    assert {r["outcome"] for r in results} <= {"hit", "wrong", "partial", "miss", "false_board", "false_partial", "none"}
    clean = [r for r in results if r["condition"] == "clean"]
    assert all(r["outcome"] == "hit" for r in clean)
    summary = _rows(out / "summary.csv")
    assert len(summary) == 2 * len(conds)
    calib = _rows(out / "calibration.csv")
    assert len(calib) == 4 * 2 and {"fx_pct", "pp_px", "dist_field_mean_px", "rms_px", "status"} <= set(calib[0])
    assert any(r["status"] == "ok" for r in calib)
    links = _check_links(out / "report.md")
    names = {Path(x).name for x in links}
    assert {"sweep_noise.png", "sweep_blur.png", "sweep_contrast.png", "sweep_jpeg.png", "sweep_distortion.png",
            "sweep_tilt.png", "error_histogram.png", "time.png"} <= names
    assert any(n.startswith("example_") for n in names)
    text = (out / "report.md").read_text()
    assert "## Headline" in text and "## Targets (cnn)" in text and "python -m aicalib_tf.evaluate" in text
    assert "| first-run max ms |" in text  # the time table shows the slowest first timing too
    cfg = json.loads((out / "config.json").read_text())
    assert re.fullmatch(r"[0-9a-f]{64}", cfg["models"]["cnn"]["sha256"])
    assert {"python", "numpy", "opencv", "tensorflow", "keras", "cpu"} <= set(cfg["versions"])
    cpu = cfg["versions"]["cpu"]  # the machine behind the times, where /proc/cpuinfo names it
    assert f"CPUs ({cpu or 'CPU model unknown'})" in text
    assert len(cfg["conditions"]) == len(conds) - 1 and cfg["image_counts"]["clean"] == 1
    assert not list(out.rglob("*.tmp"))  # atomic writes leave no temporaries


def test_photos_with_degradations(tmp_path):
    photos = tmp_path / "photos"
    photos.mkdir()
    for name in ("left01.jpg", "left02.jpg", "left03.jpg"):
        shutil.copy(DATA / name, photos / name)
    (photos / "notes.txt").write_text("not an image")
    (photos / "broken.png").write_bytes(b"not a png")
    out = tmp_path / "rep"
    rc = main(["--images", str(photos), "--pattern", "9x6", "--degrade", "--detectors", "cnn,opencv",
               "--out", str(out), "--quiet"])
    assert rc == 0
    for name in ("results.csv", "agreement.csv", "calibration.csv", "degrade.csv", "references.csv", "report.md",
                 "config.json"):
        assert (out / name).is_file(), name
    rows = _rows(out / "results.csv")
    assert len(rows) == 3 * len(PHOTO_DEGRADATIONS) * 2  # broken.png is skipped and reported
    assert "broken.png" in (out / "report.md").read_text()
    deg = _rows(out / "degrade.csv")
    assert {r["degradation"] for r in deg} == set(PHOTO_DEGRADATIONS)
    clean = {r["detector"]: float(r["full_board_rate"]) for r in deg if r["degradation"] == "clean"}
    assert clean == {"cnn": 1.0, "opencv": 1.0}
    agree = _rows(out / "agreement.csv")
    assert len(agree) == 3 and all(float(a["max_px"]) < 1.0 for a in agree)
    cal = _rows(out / "calibration.csv")
    assert [c["status"] for c in cal] == ["ok", "ok"]
    _check_links(out / "report.md")


@pytest.mark.parametrize("argv, message", [
    (["--detectors", "cnn,yolo"], "unknown detector"),
    (["--conditions", "clean,foggy"], "unknown condition"),
    (["--limit", "0"], "--limit"),
    (["--images", "."], "--pattern"),
    (["--pattern", "9x6"], "go with --images"),
    (["--images", "/no/such/folder", "--pattern", "9x6"], "not a folder"),
    (["--images", ".", "--pattern", "9"], "pattern"),
    (["--images", str(Path(__file__).parent), "--pattern", "9x6"], "no images"),
    (["--model", "/no/such.keras", "--detectors", "cnn"], "not found"),
])
def test_bad_arguments_exit_2(argv, message, capsys, tmp_path):
    assert main(argv + ["--out", str(tmp_path / "x")]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_score_detection_outcomes():
    truth, ids = _grid()
    vis = np.ones(54, bool)
    row, e = score_detection(Found(truth[::-1] + 0.1, ids, True), truth, vis, True, (9, 6))
    assert row["outcome"] == "hit" and row["recall"] == 1.0 and e.shape == (54,) and row["wrong_ids"] == 0
    bad = truth.copy()
    bad[3] += 5.0
    row, e = score_detection(Found(bad, ids, True), truth, vis, True, (9, 6))
    assert row["outcome"] == "wrong" and e.size == 0 and row["err_max"] == pytest.approx(5 * np.sqrt(2))
    row, e = score_detection(Found(truth[:20], ids[:20], False), truth, vis, True, (9, 6))
    assert row["outcome"] == "partial" and row["correct"] == 20 and row["recall"] == pytest.approx(20 / 54)
    row, _ = score_detection(Found(np.zeros((0, 2)), np.zeros((0, 2), int), False), truth, vis, True, (9, 6))
    assert row["outcome"] == "miss"
    row, _ = score_detection(Found(truth, ids, True), None, None, False, (9, 6))
    assert row["outcome"] == "false_board"
    row, _ = score_detection(Found(np.zeros((0, 2)), np.zeros((0, 2), int), False), None, None, False, (9, 6))
    assert row["outcome"] == "none"


def test_consensus_reference_rule():
    truth, _ = _grid()
    ref, rule, members = consensus_reference({"cnn": truth + 0.2, "opencv": truth[::-1]}, (9, 6))
    assert rule == "consensus" and members == ["cnn", "opencv"]
    np.testing.assert_allclose(ref, truth + 0.1)
    ref, rule, members = consensus_reference({"cnn": truth, "opencv": truth + 0.5, "opencv-sb": truth + 5.0}, (9, 6))
    assert rule == "consensus" and members == ["cnn", "opencv"]
    assert consensus_reference({"cnn": truth, "opencv": truth + 3.0}, (9, 6))[1] == "disagree"
    ref, rule, _ = consensus_reference({"opencv-sb": truth}, (9, 6))
    assert rule == "single" and np.array_equal(ref, truth)
    # cnn and report share the CNN pipeline's refinement: one vote between them
    ref, rule, members = consensus_reference({"cnn": truth, "report": truth, "opencv": truth + 0.3}, (9, 6))
    assert rule == "consensus" and members == ["cnn", "report", "opencv"]
    np.testing.assert_allclose(ref, truth + 0.15)
    ref, rule, members = consensus_reference({"cnn": truth, "report": truth, "opencv": truth + 0.3,
                                              "opencv-sb": truth + 3.0}, (9, 6))
    assert members == ["cnn", "report", "opencv"]
    assert consensus_reference({"cnn": truth, "report": truth + 0.2}, (9, 6))[1] == "single"
    assert consensus_reference({"cnn": truth, "report": truth + 5.0}, (9, 6))[1] == "disagree"
    assert consensus_reference({}, (9, 6))[:2] == (None, "none")


def test_photo_degradations_are_seeded_and_uint8():
    gray = np.tile(np.linspace(0, 1, 64, dtype=np.float32), (48, 1))
    for name in PHOTO_DEGRADATIONS:
        a = degrade_photo(gray, name, np.random.default_rng(3))
        b = degrade_photo(gray, name, np.random.default_rng(3))
        assert a.dtype == np.uint8 and a.shape == gray.shape and np.array_equal(a, b)
    with pytest.raises(ValueError, match="unknown degradation"):
        degrade_photo(gray, "fog", np.random.default_rng(0))


def test_condition_selection():
    assert [c.name for c in select_conditions("noise")] == [f"sweep-noise-{s}" for s in (0, 10, 20, 30, 40, 50, 60)]
    assert select_conditions("named") == named_conditions()
    assert [c.name for c in select_conditions("clean,clean,blur3")] == ["clean", "blur3"]
    with pytest.raises(ValueError, match="unknown condition"):
        select_conditions("fog")
    names = [c.name for c in all_conditions()]
    assert len(names) == len(set(names))


def test_detectors_warm_up_once_per_image_size_before_timing():
    from aicalib_tf.bench.runner import run_synthetic

    seen = []

    def counting(img):
        seen.append(img.shape)
        return Found(np.zeros((0, 2)), np.zeros(0, np.int64), False)

    conds = select_conditions("clean,hd1080,noise20")
    out = run_synthetic(conds, {"counting": counting}, {"named": 2, "sweep": 1, "hd": 1, "calib_views": 3},
                        with_calibration=False, progress=False)
    # two untimed calls (clean, occluded) at 640x480, two timed; two untimed at 1920x1080, one timed;
    # two timed at 640x480; then every image (fewer than 20 per size) timed twice more, round robin
    assert seen == [(480, 640)] * 4 + [(1080, 1920)] * 3 + [(480, 640)] * 2 + ([(480, 640)] * 4 + [(1080, 1920)]) * 2
    assert len(out["rows"]) == 5 and all(r["time_runs"] == 3 for r in out["rows"])
    assert all(r["time_first_ms"] >= r["time_ms"] for r in out["rows"])


def test_rendering_workers_give_the_same_images_in_the_same_order():
    """Two processes render (two conditions at a time); the detector still sees every image in order, here."""
    from aicalib_tf.bench.runner import run_synthetic

    def run(workers):
        seen = []

        def counting(img):
            seen.append(int(img.astype(np.int64).sum()))
            return Found(np.zeros((0, 2)), np.zeros(0, np.int64), False)
        out = run_synthetic(select_conditions("clean,noise20,blur3"), {"counting": counting},
                            {"named": 2, "sweep": 1, "hd": 1, "calib_views": 3}, with_calibration=False,
                            progress=False, workers=workers)
        # 2 warm-up calls and 6 timed images, in order; then the re-timing, ordered by time
        return seen[:8], sorted(seen[8:]), [(r["condition"], r["index"], r["seed"]) for r in out["rows"]]

    assert run(1) == run(2)


def test_the_slowest_images_are_timed_again_and_keep_their_least_time(monkeypatch):
    import aicalib_tf.bench.timing as ev

    def row(det, ms, w=640):
        return {"detector": det, "width": w, "height": 480, "time_ms": ms, "time_first_ms": ms, "time_runs": 1}

    slowest = {}
    rows = [row("a", ms) for ms in (5.0, 50.0, 7.0, 40.0, 6.0)] + [row("a", 90.0, w=1920), row("b", 30.0)]
    for k, r in enumerate(rows):
        ev.keep_slowest(slowest, [r], np.full((2, 2), k, np.uint8), k=2)
    # later runs: image 1 (a one-off 50 ms stall) takes 6 ms, image 3 is slow every time
    later = {1: [6.0, 8.0], 3: [41.0, 39.0], 5: [95.0, 91.0], 6: [31.0, 29.0]}
    monkeypatch.setattr(ev, "time_detector", lambda fn, img: (None, later[int(img[0, 0])].pop(0)))
    assert ev.retime_slowest(slowest, {"a": None, "b": None}) == 4
    assert [r["time_ms"] for r in rows] == [5.0, 6.0, 7.0, 39.0, 6.0, 90.0, 29.0]
    assert [r["time_runs"] for r in rows] == [1, 3, 1, 3, 1, 3, 3]
    assert [r["time_first_ms"] for r in rows] == [5.0, 50.0, 7.0, 40.0, 6.0, 90.0, 30.0]
    assert all(not v for v in later.values())


def test_targets_flag_what_a_run_misses():
    from aicalib_tf.bench.targets import check_targets

    def summ(cond, det, **kw):
        base = {"condition": cond, "detector": det, "boards": 10, "detection_rate": 1.0, "err_median": 0.01,
                "recall": 1.0, "wrong_ids": 0, "wrong": 0, "false_boards": 0}
        return {**base, **kw}

    summary = pd.DataFrame([summ("clean", "cnn"), summ("clean", "opencv", detection_rate=0.9),
                            summ("barrel", "cnn", detection_rate=0.9), summ("barrel", "opencv", detection_rate=0.95),
                            summ("occluded", "cnn", recall=0.99, wrong_ids=1), summ("clutter", "cnn", boards=0)])
    times = [5.0] * 9 + [16.0]  # slowest 3.2x the median
    results = pd.DataFrame({"detector": "cnn", "width": 640, "height": 480, "time_ms": times})
    t = check_targets(summary, results).set_index("target")["met"]
    assert t["clean: full boards 100%, median error <= 0.03 px"]
    assert not t["barrel: full boards >= 97%"]
    assert not t["barrel: detection at least OpenCV's best"] and t["clean: detection at least OpenCV's best"]
    assert not t["occluded: recall >= 95%, 0 wrong ids"]
    assert t["clutter: 0 false boards"] and t["no wrong full board on any condition"]
    assert t["640×480: median <= 10 ms"] and not t["640×480: slowest <= 3× median"]
    assert "1920×1080: median <= 40 ms" not in t.index  # no such images in the run
