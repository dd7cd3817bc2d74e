"""The layout's rules (docs/architecture.md), checked on the source with ast.

* no import cycles between modules (imports inside functions count too);
* geometry, calib, guided and the frame sources never import TensorFlow or Keras, and importing them (and fitting a
  camera) leaves TensorFlow unloaded;
* detection, calibration and the guided loop never import the benchmark (the detector registry is
  detect's); data_gen takes only geometry and the shared leaf helpers (the image gate, strict JSON,
  the command lines' error path), which import nothing else of the package;
* the frame sources take only the image gate, and the guided loop sits above calib (nothing
  below it imports it);
* detect's stages import only the stages below them: corners < chessboard < charuco < boards < the
  pipeline's top-level modules; the single-camera calibration imports neither ``calib.rig`` nor
  ``calib.handeye``, and those two do not import each other;
* no module over 450 lines; no function over about 60 lines without a ``# size:`` comment that
  says why.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("aicalib_tf", "data_gen")
MAX_MODULE_LINES = 450  # no exceptions
MAX_FUNCTION_LINES = 60
SIZE_NOTE = "# size:"  # a comment that says why a function is longer than the limit
# detect's stages, lowest first; a module outside them (pipeline, pyramid, track, batch, ...) is the top
DETECT_STAGES = ("corners", "chessboard", "charuco", "boards")
# the one arrow up: the AprilGrid reader returns the pipeline's result type (imported inside a function)
DETECT_STAGE_EXCEPTIONS = {("aicalib_tf.detect.boards.aprilgrid", "aicalib_tf.detect.detection")}  # its result type
# leaf helpers every room, data_gen included, may import: they import nothing else of the package
SHARED_LEAVES = ("aicalib_tf.io", "aicalib_tf.jsonio", "aicalib_tf.cli")


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


MODULES = _modules()


def _is_package(name: str) -> bool:
    return MODULES.get(name, Path()).name == "__init__.py"


def _imports(name: str) -> set[str]:
    """The modules ``name`` imports anywhere in its source (relative imports resolved)."""
    path = MODULES[name]
    base = name if _is_package(name) else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            mod = node.module or ""
            if node.level:
                anchor = base.split(".")
                anchor = anchor[: len(anchor) - (node.level - 1)]
                mod = ".".join(anchor + ([mod] if mod else []))
            for a in node.names:  # `from pkg import submodule` imports the submodule
                found.add(f"{mod}.{a.name}" if f"{mod}.{a.name}" in MODULES else mod)
    return found


GRAPH = {name: {m for m in _imports(name) if m in MODULES and m != name} for name in MODULES}


def _cycles() -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(GRAPH[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(GRAPH):
        if v not in index:
            visit(v)
    return out


def _reach(start: str) -> set[str]:
    seen, todo = set(), [start]
    while todo:
        for w in GRAPH[todo.pop()]:
            if w not in seen:
                seen.add(w)
                todo.append(w)
    return seen


def _in(name: str, room: str) -> bool:
    return name == room or name.startswith(room + ".")


def test_the_walk_sees_the_package():
    assert "aicalib_tf.detect.pipeline" in MODULES and "aicalib_tf.geometry.pattern" in MODULES
    assert "aicalib_tf.geometry.pattern" in GRAPH["aicalib_tf.calib.fit"]
    for sub in (*(f"aicalib_tf.detect.{s}" for s in DETECT_STAGES), "aicalib_tf.calib.rig", "aicalib_tf.calib.handeye"):
        assert _is_package(sub) and sum(_in(m, sub) for m in MODULES) > 1, sub


def test_no_import_cycles():
    assert _cycles() == []


def test_the_cycle_finder_finds_a_cycle(monkeypatch):
    monkeypatch.setitem(GRAPH, "aicalib_tf.geometry.pattern", GRAPH["aicalib_tf.geometry.pattern"] | {"aicalib_tf.calib.fit"})
    cycles = _cycles()
    assert any({"aicalib_tf.calib.fit", "aicalib_tf.geometry.pattern"} <= set(c) for c in cycles), cycles


@pytest.mark.parametrize("room", ["aicalib_tf.geometry", "aicalib_tf.calib", "aicalib_tf.guided", "aicalib_tf.sources"])
def test_geometry_and_calib_never_import_tensorflow(room):
    for name in MODULES:
        if _in(name, room):
            bad = {m for m in _imports(name) if m.split(".")[0] in ("tensorflow", "keras")}
            assert not bad, f"{name} imports {bad}"


def test_fitting_a_camera_leaves_tensorflow_unloaded():
    code = (
        "import sys, numpy as np\n"
        "import aicalib_tf.geometry.pattern, aicalib_tf.geometry.camera, aicalib_tf.geometry.pose\n"
        "import aicalib_tf.calib.fit, aicalib_tf.calib.files, aicalib_tf.calib.report\n"
        "from aicalib_tf.calib.fit import View, calibrate_camera\n"
        "from aicalib_tf.geometry.pattern import board_points\n"
        "import cv2\n"
        "ids = np.stack(np.meshgrid(np.arange(9), np.arange(6)), -1).reshape(-1, 2)\n"
        "K = np.array([[500., 0, 320], [0, 500, 240], [0, 0, 1]])\n"
        "views = []\n"
        "for k, (rx, ry) in enumerate([(0.3, 0.1), (-0.2, 0.3), (0.1, -0.4), (0.4, 0.3)]):\n"
        "    uv, _ = cv2.projectPoints(board_points(ids, 30.).astype(float), np.array([rx, ry, 0.]),\n"
        "                              np.array([-120., -80., 500.]), K, np.zeros(5))\n"
        "    views.append(View(f'v{k}', uv.reshape(-1, 2), ids))\n"
        "calibrate_camera(views, (9, 6), 30., (640, 480))\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('tensorflow', 'keras')))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip() == "[]"


def test_detection_calibration_and_the_guided_loop_never_import_the_benchmark():
    for name in MODULES:
        if any(_in(name, room) for room in ("aicalib_tf.detect", "aicalib_tf.calib", "aicalib_tf.guided")):
            bench = {m for m in _reach(name) if _in(m, "aicalib_tf.bench")}
            assert not bench, f"{name} reaches {bench}"


def test_sources_take_only_the_image_gate_and_guided_sits_above_calib():
    assert {m for m in _reach("aicalib_tf.sources") if _in(m, "aicalib_tf")} <= {"aicalib_tf", "aicalib_tf.io"}
    for name in MODULES:
        if _in(name, "aicalib_tf.calib") or _in(name, "aicalib_tf.detect") or _in(name, "aicalib_tf.geometry"):
            assert not {m for m in GRAPH[name] if _in(m, "aicalib_tf.guided")}, name


def _detect_stage(name: str) -> int | None:
    """The stage of a detect module: its index in DETECT_STAGES, len(DETECT_STAGES) for the top; None outside detect."""
    if not _in(name, "aicalib_tf.detect"):
        return None
    parts = name.split(".")
    return DETECT_STAGES.index(parts[2]) if len(parts) > 2 and parts[2] in DETECT_STAGES else len(DETECT_STAGES)


def _stage_violations() -> list[tuple[str, str]]:
    """Imports from a detect stage up to a later one, and between rig, hand-eye and the one-camera fit."""
    out = []
    for name, targets in GRAPH.items():
        for m in targets:
            s, t = _detect_stage(name), _detect_stage(m)
            if s is not None and t is not None and t > s and (name, m) not in DETECT_STAGE_EXCEPTIONS:
                out.append((name, m))
            if _in(name, "aicalib_tf.calib") and _in(m, "aicalib_tf.calib"):
                here = [r for r in ("aicalib_tf.calib.rig", "aicalib_tf.calib.handeye") if _in(name, r)]
                there = [r for r in ("aicalib_tf.calib.rig", "aicalib_tf.calib.handeye") if _in(m, r)]
                if there and here != there:
                    out.append((name, m))
    return sorted(out)


def test_detect_stages_and_calib_subpackages_import_only_below_them():
    assert _stage_violations() == []


def test_the_stage_check_finds_an_arrow_up(monkeypatch):
    monkeypatch.setitem(GRAPH, "aicalib_tf.detect.corners.refine",
                        GRAPH["aicalib_tf.detect.corners.refine"] | {"aicalib_tf.detect.chessboard.grid"})
    monkeypatch.setitem(GRAPH, "aicalib_tf.calib.fit", GRAPH["aicalib_tf.calib.fit"] | {"aicalib_tf.calib.rig.result"})
    assert {("aicalib_tf.detect.corners.refine", "aicalib_tf.detect.chessboard.grid"),
            ("aicalib_tf.calib.fit", "aicalib_tf.calib.rig.result")} <= set(_stage_violations())


def test_the_shared_helpers_are_leaves():
    # the place data_gen and the library both may use: nothing of the package beyond each other
    for name in SHARED_LEAVES:
        assert {m for m in _reach(name) if _in(m, "aicalib_tf")} <= set(SHARED_LEAVES), name


def test_data_gen_takes_only_geometry_and_the_image_gate():
    # and the leaf helpers every command line shares: strict JSON and the one error path
    allowed = ("aicalib_tf", "aicalib_tf.geometry", *SHARED_LEAVES)
    for name in MODULES:
        if _in(name, "data_gen"):
            lib = {m for m in GRAPH[name] if _in(m, "aicalib_tf")}
            assert all(any(m == a or (a != "aicalib_tf" and _in(m, a)) for a in allowed) for m in lib), (name, lib)
            assert not {m for m in _reach(name) if _in(m, "aicalib_tf") and not any(
                m == a or (a != "aicalib_tf" and _in(m, a)) for a in allowed)}, name


def _too_long() -> list[str]:
    out = []
    for name, path in MODULES.items():
        src = path.read_text()
        lines = src.splitlines()
        if len(lines) > MAX_MODULE_LINES:
            out.append(f"{name}: {len(lines)} lines")
        for node in ast.walk(ast.parse(src)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                body = lines[node.lineno - 1: node.end_lineno]
                if len(body) > MAX_FUNCTION_LINES and SIZE_NOTE not in "\n".join(body):
                    out.append(f"{name}.{node.name}: {len(body)} lines")
    return out


def test_modules_and_functions_stay_short_or_say_why():
    assert _too_long() == []
