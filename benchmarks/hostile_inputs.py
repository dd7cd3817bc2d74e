"""Hostile-input campaign over the command lines: every case must keep the property.

    .venv/bin/python benchmarks/hostile_inputs.py [--only SUBSTRING] [--list]

The property, for every case: exit 0, 1 or 2; on exit 2 exactly one ``error:`` line; no
traceback, no "unexpected ... bug" line; every JSON file written is strict (no NaN/Infinity);
and a command that fails leaves none of its output files (a complete set or none).

Cases cover ``compare`` (sizes, models, NaN/inf/huge values, splined camera.json with missing or
corrupt undistort maps, pickled .npy), ``handeye`` (malformed poses: count, non-rotations, NaN,
units, degenerate motions), ``board`` (aprilgrid/circles/charuco specs: huge, zero, negative,
contradictory fields, unknown family, Kalibr YAML of another target, YAML aliases, non-UTF-8),
``calibrate`` (``--flex auto`` with degenerate views, ``--model splined_equidistant`` with too few
views, images 16-bit / alpha / 1×N, each ``--board`` type, a truncated video), ``check`` (a
splined or flex camera.json, corrupt fields) and ``detect``. Each runs in-process through the
module's ``main(argv)``; the script prints one line per failing case and the counts.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import io
import json
import os
import pickle
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
PHOTOS = sorted((ROOT / "tests" / "data" / "opencv_left").glob("left*.jpg"))


def _strict_json(path: Path) -> str | None:
    def bad(name):
        raise ValueError(f"non-finite {name}")
    try:
        json.loads(path.read_text(), parse_constant=bad)
    except (ValueError, UnicodeDecodeError) as exc:
        return f"{path.name}: {exc}"
    return None


def run_case(module: str, argv: list[str], outputs: list[Path], expect: set[int] | None = None) -> tuple[bool, str]:
    """Run ``module.main(argv)`` in-process; (ok, why) for the property."""
    import importlib

    main = importlib.import_module(module).main
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse
            code = exc.code if isinstance(exc.code, int) else 2
        except BaseException as exc:  # noqa: BLE001 - the campaign records it
            return False, f"raised {type(exc).__name__}: {exc}"
    text = err.getvalue()
    errors = [line for line in text.splitlines() if line.startswith("error") or ": error: " in line]  # argparse's too
    why = []
    if code not in (0, 1, 2):
        why.append(f"exit {code}")
    if expect is not None and code not in expect:
        why.append(f"exit {code}, expected {sorted(expect)}")
    if "Traceback" in text or "a bug in aicalib_tf" in text:
        why.append("traceback/unexpected: " + (errors[-1] if errors else text.strip().splitlines()[-1])[:300])
    if code == 2 and len(errors) != 1:
        why.append(f"{len(errors)} error lines: {text.strip()[-300:]}")
    present = [p for p in outputs if p.exists()]
    if code == 2 and present:
        why.append(f"left {[p.name for p in present]} after exit 2")
    if code in (0, 1) and outputs and len(present) != len(outputs):
        why.append(f"incomplete outputs: missing {[p.name for p in outputs if not p.exists()]}")
    for p in present:
        if p.is_file() and p.suffix == ".json":
            bad = _strict_json(p)
            if bad:
                why.append(bad)
        if p.is_dir():
            for q in p.rglob("*.json"):
                bad = _strict_json(q)
                if bad:
                    why.append(bad)
    tail = errors[-1] if errors else ""
    return not why, "; ".join(why) if why else f"exit {code} {tail[:160]}"


# ---------------------------------------------------------------- fixtures

def _calibrations(root: Path) -> dict[str, Path]:
    """Folders holding camera.json of plumb_bob, splined and flex fits of synthetic views (640×480)."""
    import dataclasses

    from aicalib_tf.calib.files import save_calibration
    from aicalib_tf.calib.fit import fit_views
    from aicalib_tf.geometry import lens as L
    from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views

    size = (640, 480)
    lens = L.Lens("plumb_bob", [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]], [-0.25, 0.08, 0.001, -0.0005, 0.0], size)
    views = synthetic_views(lens, 16, 0.2, seed=3)
    out = {}
    for name, model, flex in (("a", "plumb_bob", "off"), ("b", "plumb_bob", "off"), ("spline", "splined_equidistant", "off"),
                              ("flex", "plumb_bob", "auto"), ("ds", "ds", "off")):
        sub = views[0::2] if name != "b" else views[1::2]
        cal = fit_views(views if name == "spline" else sub, PATTERN, SQUARE, size, model, flex=flex)
        (root / name).mkdir()
        save_calibration(cal, root / name)
        out[name] = root / name
    big = dataclasses.replace(fit_views(views[0::2], PATTERN, SQUARE, size, "plumb_bob"), image_size=(1280, 960))
    (root / "big").mkdir()
    save_calibration(big, root / "big")
    out["big"] = root / "big"
    return out


def _mutated(root: Path, src: Path, name: str, edit) -> Path:
    """A copy of folder ``src`` whose camera.json went through ``edit(doc)`` (in place, or returns text)."""
    import shutil

    dst = root / name
    shutil.copytree(src, dst)
    doc = json.loads((dst / "camera.json").read_text())
    text = edit(doc)
    if isinstance(text, bytes):
        (dst / "camera.json").write_bytes(text)
    else:
        (dst / "camera.json").write_text(text if isinstance(text, str) else json.dumps(doc))
    (dst / "camera.yaml").unlink(missing_ok=True)
    return dst


def _set(path: list, value):
    def edit(doc):
        node = doc
        for key in path[:-1]:
            node = node[key]
        if value is _DELETE:
            del node[path[-1]]
        else:
            node[path[-1]] = value
    return edit


_DELETE = object()


def _camera_json_cases(root: Path, cals: dict[str, Path]) -> list[tuple[str, Path]]:
    a, spline = cals["a"], cals["spline"]
    doc = json.loads((a / "camera.json").read_text())
    sdoc = json.loads((spline / "camera.json").read_text())
    cases = [("text NaN fx", _mutated(root, a, "m_nan", lambda d: (a / "camera.json").read_text().replace(
        str(doc["camera_matrix"][0][0]), "NaN", 1))),
             ("fx 1e300", _mutated(root, a, "m_huge", _set(["camera_matrix", 0, 0], 1e300))),
             ("fx -500", _mutated(root, a, "m_neg", _set(["camera_matrix", 0, 0], -500.0))),
             ("fx true", _mutated(root, a, "m_bool", _set(["camera_matrix", 0, 0], True))),
             ("K 2x2", _mutated(root, a, "m_k22", _set(["camera_matrix"], [[1, 0], [0, 1]]))),
             ("dist 1e308", _mutated(root, a, "m_dist", _set(["distortion_coefficients", 0], 1e308))),
             ("no model field", _mutated(root, a, "m_nomodel", _set(["distortion_model"], _DELETE)) if "distortion_model" in doc
              else _mutated(root, a, "m_nomodel", _set(["model"], _DELETE))),
             ("image size 0x0", _mutated(root, a, "m_size0", _set(["image_width"], 0)) if "image_width" in doc
              else _mutated(root, a, "m_size0", _set(["image_size"], [0, 0]))),
             ("camera.json not UTF-8", _mutated(root, a, "m_latin", lambda d: b"\xff\xfe{\x00")),
             ("camera.json a list", _mutated(root, a, "m_list", lambda d: "[1, 2, 3]")),
             ("camera.json 50 nested lists", _mutated(root, a, "m_deep", lambda d: "[" * 50000 + "]" * 50000)),
             ("camera.json empty", _mutated(root, a, "m_empty", lambda d: "")),
             ]
    layout = sdoc.get("lens_layout")
    n_dist = len(sdoc["distortion_coefficients"])
    cases += [("spline: lens_layout removed", _mutated(root, spline, "s_nolayout", _set(["lens_layout"], _DELETE))),
              ("spline: lens_layout a string", _mutated(root, spline, "s_strlayout", _set(["lens_layout"], "x"))),
              ("spline: coefficients truncated", _mutated(root, spline, "s_trunc", _set(["distortion_coefficients"],
                                                                                       sdoc["distortion_coefficients"][:3]))),
              ("spline: coefficients 1e308", _mutated(root, spline, "s_huge", _set(["distortion_coefficients"],
                                                                                   [1e308] * n_dist))),
              ("spline: model name of 1e9 knots", _mutated(root, spline, "s_knots", _set(["distortion_model"],
                                                          "splined_equidistant_nx=100000_ny=100000_fov=120_smooth=1"))),
              ("spline: model name fov 0", _mutated(root, spline, "s_fov0", _set(["distortion_model"],
                                                    "splined_equidistant_nx=4_ny=4_fov=0_smooth=1")))]
    if isinstance(layout, dict):
        for k, v in layout.items():
            cases.append((f"spline: lens_layout.{k} negative", _mutated(root, spline, f"s_neg_{k}",
                                                                        _set(["lens_layout", k], -1 if not isinstance(v, str) else "-1"))))
    return cases


def _spline_map_cases(root: Path, spline: Path) -> list[tuple[str, Path]]:
    import shutil

    out = []
    for name, action in (("maps missing", "rm"), ("map garbage", "garbage"), ("map pickled", "pickle"),
                         ("map wrong shape", "shape")):
        dst = root / f"maps_{action}"
        shutil.copytree(spline, dst)
        for f in dst.glob("undistort_map_*.npy"):
            if action == "rm":
                f.unlink()
            elif action == "garbage":
                f.write_bytes(b"\x93NUMPY garbage" * 10)
            elif action == "pickle":
                np.save(f, np.array([{"a": 1}], dtype=object), allow_pickle=True)
            else:
                np.save(f, np.zeros((3, 3), np.float32))
        out.append((name, dst))
    return out


def _write(path: Path, data) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(data, bytes):
        path.write_bytes(data)
    else:
        path.write_text(data)
    return path


def _pose_lines(n: int, fn) -> str:
    rows = ["image,x,y,z,qx,qy,qz,qw"]
    for i, photo in enumerate(PHOTOS[:n]):
        rows.append(",".join([photo.name, *(str(v) for v in fn(i))]))
    return "\n".join(rows) + "\n"


def _handeye_cases(root: Path, cals: dict[str, Path]) -> list[tuple[str, str, list[str], list[Path]]]:
    rng = np.random.default_rng(0)

    def good(i):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        return [0.4 + 0.05 * i, 0.01 * i, 0.3, *q]

    posefiles = {
        "poses: 3 rows for 13 images": _pose_lines(3, good),
        "poses: NaN x": _pose_lines(13, lambda i: [float("nan"), 0, 0, 0, 0, 0, 1]),
        "poses: millimetres": _pose_lines(13, lambda i: [400 + i, 10, 300, 0, 0, 0, 1]),
        "poses: zero quaternion": _pose_lines(13, lambda i: [0.4, 0, 0.3, 0, 0, 0, 0]),
        "poses: all identical": _pose_lines(13, lambda i: [0.4, 0, 0.3, 0, 0, 0, 1]),
        "poses: pure translations": _pose_lines(13, lambda i: [0.4 + 0.02 * i, 0.01 * i, 0.3, 0, 0, 0, 1]),
        "poses: one rotation axis": _pose_lines(13, lambda i: [0.4, 0, 0.3, 0, 0, np.sin(0.1 * i), np.cos(0.1 * i)]),
        "poses: 1e308": _pose_lines(13, lambda i: [1e308, 0, 0, 0, 0, 0, 1]),
        "poses: header only": "image,x,y,z,qx,qy,qz,qw\n",
        "poses: not UTF-8": b"\xff\xfe\x00image,x\n",
        "poses: columns missing": "image,x,y\nleft01.jpg,1,2\n",
        "poses: words": _pose_lines(13, lambda i: ["a", "b", "c", "d", "e", "f", "g"]),
    }
    json_files = {
        "poses: non-rotation matrix": json.dumps([{"image": p.name, "matrix": np.diag([2.0, 2.0, 2.0, 1.0]).tolist()}
                                                  for p in PHOTOS]),
        "poses: reflection matrix": json.dumps([{"image": p.name, "matrix": np.diag([1.0, 1.0, -1.0, 1.0]).tolist()}
                                                for p in PHOTOS]),
        "poses: matrix 3x3": json.dumps([{"image": p.name, "matrix": np.eye(3).tolist()} for p in PHOTOS]),
        "poses: matrix of 15 numbers": json.dumps([{"image": p.name, "matrix": list(range(15))} for p in PHOTOS]),
        "poses: JSON dict of junk": json.dumps({"poses": {"a": 1}}),
        "poses: deep JSON": "[" * 100000 + "]" * 100000,
    }
    yaml_files = {
        "poses: YAML aliases": "%YAML:1.0\n---\na: &a [1, 2, 3]\nposes: *a\n",
        "poses: YAML not OpenCV": "poses:\n  - {image: left01.jpg, x: 1}\n  - !!python/object:os.system [ls]\n",
        "poses: YAML 1000 brackets deep": "%YAML:1.0\n---\nposes: " + "[" * 1000 + "]" * 1000 + "\n",
        "poses: YAML 100000 brackets deep": "%YAML:1.0\n---\nposes: " + "[" * 100000 + "]" * 100000 + "\n",
        "poses: YAML 3000 blocks deep": "%YAML:1.0\n---\n" + "".join("  " * i + f"k{i}:\n" for i in range(3000)),
        "poses: YAML !!binary": "%YAML:1.0\n---\nposes: !!binary |\n  AAAA\n",
    }
    cases = []
    common = ["--pattern", "9x6", "--square", "25mm", "--setup", "eye-in-hand", "--detector", "opencv", "--quiet"]
    for i, (name, text) in enumerate({**posefiles, **{k: v for k, v in json_files.items()},
                                     **yaml_files}.items()):
        ext = ".json" if name in json_files else ".yaml" if name in yaml_files else ".csv"
        pf = _write(root / f"poses{i}{ext}", text)
        out = root / f"he{i}"
        cases.append((name, "aicalib_tf.handeye", [str(p) for p in PHOTOS] + ["--poses", str(pf), "--out", str(out),
                                                                              *common], [out]))
    pf = _write(root / "good.csv", posefiles["poses: one rotation axis"].replace("left01.jpg", "left01.jpg", 1))
    dup = _write(root / "dup.csv", _pose_lines(13, good) + _pose_lines(2, good).split("\n", 1)[1])
    other = _write(root / "other.csv", _pose_lines(13, good).replace("left", "right"))
    extra = [(["--robot-sigma", v], pf) for v in ("nan", "-1deg,1mm", "0deg,0mm", "1e308deg,1mm", "abc")]
    extra += [(["--intrinsics", str(cals[k] / "camera.json")], pf) for k in ("spline", "big", "flex")]
    extra += [(["--intrinsics", str(root)], pf), ([], dup), ([], other)]
    for i, (args, poses) in enumerate(extra):
        out = root / f"hx{i}"
        cases.append((f"handeye {' '.join(args)[:60]} {poses.name}", "aicalib_tf.handeye",
                      [str(p) for p in PHOTOS] + ["--poses", str(poses), "--out", str(out), *common, *args], [out]))
    return cases


BOARD_SPECS = [
    "aprilgrid:6x6,tag=88mm,spacing=0.3", "aprilgrid:0x6,tag=88mm,spacing=0.3", "aprilgrid:6x6,tag=0mm,spacing=0.3",
    "aprilgrid:6x6,tag=-5mm,spacing=0.3", "aprilgrid:6x6,tag=88mm,spacing=1.0", "aprilgrid:6x6,tag=88mm,spacing=5",
    "aprilgrid:6x6,tag=88mm,spacing=-0.3", "aprilgrid:6x6,tag=88mm,spacing=nan", "aprilgrid:6x6,tag=1e308mm,spacing=0.3",
    "aprilgrid:100000x100000,tag=1mm,spacing=0.3", "aprilgrid:6x6,tag=88mm,spacing=0.3,family=tag99h99",
    "aprilgrid:6x6,tag=88mm,spacing=0.3,first=-1", "aprilgrid:6x6,tag=88mm,spacing=0.3,first=586",
    "aprilgrid:6x6,tag=88mm,spacing=0.3,tag=10mm", "aprilgrid:6x6,tag=inf mm,spacing=0.3",
    "circles:4x11,spacing=20mm,asymmetric", "circles:4x11,spacing=20mm,symmetric,diameter=20mm",
    "circles:4x11,spacing=20mm,symmetric,diameter=30mm", "circles:4x11,spacing=0mm,asymmetric",
    "circles:4x11,spacing=20mm,asymmetric,symmetric", "circles:1x1,spacing=20mm,symmetric",
    "circles:4x11,spacing=20mm", "circles:4x11,spacing=20mm,symmetric,diameter=-1mm",
    "circles:99999x99999,spacing=1mm,symmetric", "circles:4x11,spacing=1e308mm,symmetric",
    "charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100", "charuco:11x8,square=30mm,marker=30mm,dict=DICT_5X5_100",
    "charuco:11x8,square=30mm,marker=40mm,dict=DICT_5X5_100", "charuco:11x8,square=30mm,marker=22mm,dict=DICT_4X4_50",
    "charuco:11x8,square=30mm,marker=22mm,dict=DICT_NOPE", "charuco:1x1,square=30mm,marker=22mm,dict=DICT_5X5_100",
    "charuco:11x8,square=1e308mm,marker=22mm,dict=DICT_5X5_100", "charuco:11x8,square=30mm,marker=22mm,first=1000",
    "charuco:11x8,square=30,marker=22,dict=DICT_5X5_100", "charuco:11x8,square=30mm,marker=0mm,dict=DICT_5X5_100",
    "charuco:,,,", "charuco:11x8", "charuco:5x4,square=30mm,marker=22mm,dict=DICT_5X5_100,square=40mm",
    "charuco:5x4,square=30mm,marker=22mm,dict=DICT_5X5_100,legacy,legacy", "charuco:5x4,square=30mm,marker=22mm,dict=DICT_5X5_100,first=-3",
    "charuco:5x4,square=30mm,marker=22mm,dict=DICT_4X4_50,first=45", "aprilgrid:3x3,tag=30mm,spacing=0.3,family=tag16h5,first=29", "\u00e9\u00e9:1x1", "aprilgrid:6x6,tag=88mm,spacing=0.3," + "x=1," * 10000,
]


def _kalibr_files(root: Path) -> list[tuple[str, Path]]:
    files = {
        "kalibr checkerboard target": "target_type: 'checkerboard'\ntargetCols: 6\ntargetRows: 7\nrowSpacingMeters: 0.06\n"
                                      "colSpacingMeters: 0.06\n",
        "kalibr circlegrid target": "target_type: 'circlegrid'\ntargetCols: 6\ntargetRows: 7\nspacingMeters: 0.02\n"
                                    "asymmetricGrid: False\n",
        "kalibr aprilgrid zero tag": "target_type: 'aprilgrid'\ntagCols: 6\ntagRows: 6\ntagSize: 0\ntagSpacing: 0.3\n",
        "kalibr aprilgrid spacing 2": "target_type: 'aprilgrid'\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 2\n",
        "kalibr aprilgrid huge": "target_type: 'aprilgrid'\ntagCols: 1000000\ntagRows: 1000000\ntagSize: 0.088\n"
                                 "tagSpacing: 0.3\n",
        "kalibr YAML aliases": "a: &a ['lol','lol','lol','lol','lol','lol','lol','lol','lol']\n"
                               "b: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]\nc: &c [*b,*b,*b,*b,*b,*b,*b,*b,*b]\n"
                               "d: &d [*c,*c,*c,*c,*c,*c,*c,*c,*c]\ne: &e [*d,*d,*d,*d,*d,*d,*d,*d,*d]\n"
                               "target_type: 'aprilgrid'\ntagCols: *e\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\n",
        "kalibr not UTF-8": b"target_type: '\xff\xfe'\ntagCols: 6\n",
        "kalibr python tag": "target_type: !!python/object/apply:os.system ['true']\ntagCols: 6\n",
        "kalibr list": "- 1\n- 2\n",
        "kalibr empty": "",
    }
    return [(name, _write(root / f"target{i}.yaml", text)) for i, (name, text) in enumerate(files.items())]


def _images(root: Path) -> dict[str, Path]:
    """Variants of one photo: 16-bit, alpha, 16-bit alpha, 1×N, N×1, 2×2, float TIFF."""
    img = cv2.imread(str(PHOTOS[0]), cv2.IMREAD_GRAYSCALE)
    bgr = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    variants = {
        "16bit.png": img.astype(np.uint16) * 257,
        "alpha.png": np.dstack([bgr, np.full(img.shape, 255, np.uint8)]),
        "alpha0.png": np.dstack([bgr, np.zeros(img.shape, np.uint8)]),
        "16bit_alpha.png": np.dstack([bgr, np.full(img.shape, 255, np.uint8)]).astype(np.uint16) * 257,
        "row.png": img[:1, :],
        "col.png": img[:, :1],
        "tiny.png": img[:2, :2],
        "float.tiff": img.astype(np.float32) / 255.0,
        "float_nan.tiff": np.full(img.shape, np.nan, np.float32),
    }
    out = {}
    for name, arr in variants.items():
        path = root / "images" / name
        path.parent.mkdir(exist_ok=True)
        cv2.imwrite(str(path), arr)
        out[name] = path
    return out


def _video(root: Path, truncate: float) -> Path:
    path = root / f"video_{int(truncate * 100)}.avi"
    frames = [cv2.imread(str(p)) for p in PHOTOS[:8]]
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 5.0, frames[0].shape[1::-1])
    for f in frames:
        for _ in range(3):
            w.write(f)
    w.release()
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * truncate)])
    return path


def build_cases(root: Path) -> list[tuple[str, str, list[str], list[Path]]]:
    """(name, module, argv, output paths) of every case; fixtures are written under ``root``."""
    cals = _calibrations(root)
    cases = []
    n = 0

    def compare(name, a, b, *extra):
        nonlocal n
        n += 1
        png, js = root / f"cmp{n}.png", root / f"cmp{n}.json"
        cases.append((f"compare: {name}", "aicalib_tf.compare", [str(a), str(b), "--out", str(png), "--json", str(js),
                                                                  *extra], [png, js]))

    def check(name, cal, *sources):
        nonlocal n
        n += 1
        js = root / f"check{n}.json"
        cases.append((f"check: {name}", "aicalib_tf.check", [str(cal), *map(str, sources), "--out", str(js),
                                                              "--detector", "opencv", "--workers", "1"], [js]))

    a, b, spline = cals["a"], cals["b"], cals["spline"]
    compare("same", a, b)
    compare("other size", a, cals["big"])
    compare("plumb_bob vs spline", a, spline)
    compare("spline vs ds", spline, cals["ds"])
    compare("flex vs plain", cals["flex"], a)
    for grid in ("0x0", "1x1", "-3x2", "100000x100000", "axb", "2x2"):
        compare(f"--grid {grid}", a, b, "--grid", grid)
    for cb in ("nan", "-1", "inf", "0", "1e308"):
        compare(f"--cbmax {cb}", a, b, "--cbmax", cb)
    for name, folder in _camera_json_cases(root, cals) + _spline_map_cases(root, spline):
        compare(name, a if "spline" not in name and "map" not in name else spline, folder)
    compare("ROS camera_info", a, a / "camera_info.yaml")
    compare("empty folder", a, _write(root / "emptyf" / "x.txt", "").parent)
    compare("a YAML with aliases", a, _write(root / "alias.yaml", "%YAML:1.0\n---\na: &x 1\ncamera_matrix: *x\n"))
    compare("a YAML not UTF-8", a, _write(root / "latin.yaml", b"%YAML:1.0\n---\ncamera_matrix: \xff\n"))
    compare("a JPEG as camera.yaml", a, _write(root / "photo.yaml", PHOTOS[0].read_bytes()))
    photos = PHOTOS[:6]
    for name, folder in (("splined camera.json", spline), ("flex camera.json", cals["flex"]), ("ds camera.json", cals["ds"])):
        check(name, folder, *photos)
    for name, folder in _camera_json_cases(root / "chk", cals)[:8]:
        check(name, folder, *photos)
    check("a truncated video", a, _video(root, 0.5))
    check("an empty video", a, _write(root / "empty.avi", b""))
    for opt, values in (("--alpha", ("0", "1", "nan", "-1")), ("--every", ("0", "-1")), ("--max-frames", ("0",))):
        for v in values:
            check(f"{opt} {v}", a, *photos, opt, v)
    check("calibration of another size", cals["big"], *photos)
    n += 1
    png = root / f"cmp{n}.png"
    cases.append(("compare: --json in a missing folder", "aicalib_tf.compare",
                  [str(a), str(b), "--out", str(png), "--json", str(root / "nope" / "x.json")], [png]))
    png2 = root / f"cmp{n}b.png"
    cases.append(("compare: --json a folder", "aicalib_tf.compare",
                  [str(a), str(b), "--out", str(png2), "--json", str(root)], [png2]))
    cases.append(("compare: --json over camera.json", "aicalib_tf.compare",
                  [str(a), str(b), "--out", str(root / "cmpc.png"), "--json", str(a / "camera.json")], [root / "cmpc.png"]))
    cases.append(("compare: --out and --json the same", "aicalib_tf.compare",
                  [str(a), str(b), "--out", str(root / "same.x"), "--json", str(root / "same.x")], [root / "same.x"]))
    cases.append(("compare: --out a folder", "aicalib_tf.compare",
                  [str(a), str(b), "--out", str(root), "--json", str(root / "cmpx.json")], [root / "cmpx.json"]))
    cases.append(("check: --out a folder", "aicalib_tf.check", [str(a), *map(str, photos), "--out", str(root),
                                                                "--detector", "opencv", "--workers", "1"], []))
    cases.append(("check: --out in a missing folder", "aicalib_tf.check",
                  [str(a), *map(str, photos), "--out", str(root / "nope2" / "c.json"), "--detector", "opencv",
                   "--workers", "1"], [root / "nope2" / "c.json"]))
    cases.append(("calibrate: --out an existing file", "aicalib_tf.calibrate",
                  [*map(str, PHOTOS), "--pattern", "9x6", "--detector", "opencv", "--out", str(PHOTOS[0].parent / "SHA256SUMS"),
                   "--quiet", "--workers", "1", "--model", "plumb_bob"], []))
    check("photos that are not there", a, root / "nothere" / "*.jpg")
    check("a folder as a photo", a, root)
    fs_bad = {"FileStorage matrix 1e9 rows": "%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n   rows: 1000000000\n"
                                             "   cols: 1000000000\n   dt: d\n   data: [ 1. ]\n",
              "FileStorage matrix of NaN": "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n"
                                           "camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
                                           "   data: [ .nan, 0., 320., 0., .nan, 240., 0., 0., 1. ]\n",
              "FileStorage deep": "%YAML:1.0\n---\n" + "".join("  " * i + f"k{i}:\n" for i in range(300)),
              "FileStorage truncated": (a / "camera.yaml").read_text()[:200]}
    for name, text in fs_bad.items():
        compare(name, a, _write(root / "fs" / f"{len(cases)}.yaml", text))
    cases += _handeye_cases(root / "he", cals)
    good = "aprilgrid:3x3,tag=30mm,spacing=0.3"
    for i, extra in enumerate((["--dpi", "0"], ["--dpi", "-1"], ["--dpi", "nan"], ["--dpi", "1e9"], ["--paper", "a9"],
                               ["--paper", ""])):
        out = root / "boards" / f"opt{i}.png"
        cases.append((f"board: {' '.join(extra)}", "aicalib_tf.board", [good, "--out", str(out), *extra], [out]))
    for name, out in (("--out .txt", root / "boards" / "b.txt"), ("--out a folder", root / "boards"),
                      ("--out in a missing folder", root / "nope" / "b.png"), ("--out .pdf", root / "boards" / "ok.pdf")):
        cases.append((f"board: {name}", "aicalib_tf.board", [good, "--out", str(out)], [out] if out.suffix else []))
    for i, spec in enumerate(BOARD_SPECS):
        out = root / "boards" / f"b{i}.png"
        cases.append((f"board: {spec[:60]}", "aicalib_tf.board", [spec, "--out", str(out)], [out]))
    for name, path in _kalibr_files(root / "kalibr"):
        out = root / "boards" / f"k_{path.stem}.png"
        cases.append((f"board: {name}", "aicalib_tf.board", [str(path), "--out", str(out)], [out]))
        cases.append((f"calibrate --board {name}", "aicalib_tf.calibrate",
                      [str(p) for p in PHOTOS[:4]] + ["--board", str(path), "--out", str(root / f"cal_{path.stem}"),
                                                      "--quiet", "--workers", "1"], [root / f"cal_{path.stem}"]))
    images = _images(root)
    boards = {"chessboard": ["--pattern", "9x6"], "charuco": ["--board", "charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100"],
              "aprilgrid": ["--board", "aprilgrid:6x6,tag=88mm,spacing=0.3"],
              "circles": ["--board", "circles:4x11,spacing=20mm,asymmetric"]}
    for bname, bargs in boards.items():
        for iname, path in images.items():
            out = root / "det" / f"{bname}_{path.stem}"
            cases.append((f"detect {bname} {iname}", "aicalib_tf.detect.__main__", [str(path), *bargs, "--out", str(out), "--quiet",
                                                                             "--workers", "1"], [out]))
        out = root / f"calimg_{bname}"
        cases.append((f"calibrate {bname} odd images", "aicalib_tf.calibrate",
                      [*map(str, images.values()), *bargs, "--out", str(out), "--quiet", "--workers", "1",
                       "--detector", "opencv"], [out]))
    same = [str(PHOTOS[0])] * 0
    for i in range(6):  # one photo six times: degenerate views
        dup = root / "dup" / f"d{i}.jpg"
        dup.parent.mkdir(exist_ok=True)
        dup.write_bytes(PHOTOS[0].read_bytes())
        same.append(str(dup))
    for name, extra in (("--flex auto, one view six times", ["--flex", "auto"]),
                        ("splined, 4 views", ["--model", "splined_equidistant"]),
                        ("splined, one view six times", ["--model", "splined_equidistant"])):
        out = root / f"cal_{len(cases)}"
        srcs = same if "six" in name else [str(p) for p in PHOTOS[:4]]
        cases.append((f"calibrate {name}", "aicalib_tf.calibrate", [*srcs, "--pattern", "9x6", "--square", "25mm",
                                                                    "--out", str(out), "--quiet", "--workers", "1",
                                                                    "--detector", "opencv", *extra], [out]))
    for name, data in (("empty", b""), ("garbage", bytes(range(256)) * 20), ("truncated", None)):
        model = root / f"{name}.tflite"
        model.write_bytes(data if data is not None else (ROOT / "models" / "default.tflite").read_bytes()[:50000])
        out = root / f"det_model_{name}"
        cases.append((f"detect --model a {name} .tflite", "aicalib_tf.detect.__main__",
                      [str(PHOTOS[0]), "--pattern", "9x6", "--out", str(out), "--model", str(model), "--quiet"], [out]))
    out = root / "cal_video"
    cases.append(("calibrate a truncated video", "aicalib_tf.calibrate",
                  [str(_video(root, 0.4)), "--pattern", "9x6", "--out", str(out), "--quiet", "--detector", "opencv"], [out]))
    out = root / "cal_flex_ok"
    cases.append(("calibrate --flex auto, 13 photos", "aicalib_tf.calibrate",
                  [*map(str, PHOTOS), "--pattern", "9x6", "--square", "25mm", "--out", str(out), "--quiet", "--workers", "1",
                   "--detector", "opencv", "--flex", "auto", "--model", "plumb_bob"], [out]))
    return cases


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", default="", help="run the cases whose name holds this text")
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    args = ap.parse_args(argv)
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "3")
    with tempfile.TemporaryDirectory(prefix="hostile-") as tmp:
        cases = [c for c in build_cases(Path(tmp)) if args.only in c[0]]
        if args.list:
            print("\n".join(c[0] for c in cases))
            return 0
        failed, codes = 0, {}
        for name, module, case_argv, outputs in cases:
            t0 = time.perf_counter()
            ok, why = run_case(module, case_argv, outputs)
            code = why.split()[1] if why.startswith("exit ") else "?"
            codes[code] = codes.get(code, 0) + 1
            failed += not ok
            print(f"{'ok  ' if ok else 'FAIL'} {time.perf_counter() - t0:5.1f}s {name}: {why}", flush=True)
        print(f"{len(cases)} cases, {len(cases) - failed} hold the property, {failed} fail; exits {codes}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
