"""The compiled kernels: signatures checked, the ahead-of-time extension gives the JIT's results
bit for bit on real photos and loads no numba, and a stale extension is not used."""

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from aicalib_tf import kernels
from aicalib_tf.detect.chessboard.lattice_kernels import nearest_steps
from aicalib_tf.detect.corners.saddle_kernels import saddle_refine
from aicalib_tf.detect.corners.saddle import saddle_fit_matrix

ROOT = Path(__file__).resolve().parents[1]
LEFT = ROOT / "tests" / "data" / "opencv_left"
BUILT = pytest.mark.skipif(kernels.MODE != "aot", reason="extension not built here: python -m aicalib_tf.kernels")


def test_signatures_parse_and_reject_what_the_extension_cannot_take():
    assert kernels.parse_signature("f4[:, :, ::1], f8[::1], i8, b1") == (("f4", 3), ("f8", 1), ("i8", 0), ("b1", 0))
    with pytest.raises(ValueError, match="C-ordered"):
        kernels.parse_signature("f8[:, :]")
    with pytest.raises(ValueError, match="cannot read 'u2'"):
        kernels.parse_signature("f8[::1], u2")


def test_a_call_of_the_wrong_dtype_is_refused_with_the_kernel_named():
    _, fit = saddle_fit_matrix(3)
    img = np.zeros((20, 20), np.float64)  # the kernel takes float32 images
    with pytest.raises(TypeError, match=r"kernel saddle_refine: arguments \(float64\[20, 20\]"):
        saddle_refine(img, np.zeros((1, 2)), fit, 3, 6, 3.0)


def test_an_array_not_c_ordered_is_copied_and_gives_the_same_result():
    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 100, (30, 4))
    want = rng.uniform(0, 100, (7, 2))
    strided = pts[:, ::2]
    assert not strided.flags.c_contiguous
    np.testing.assert_array_equal(nearest_steps(strided, want), nearest_steps(np.ascontiguousarray(strided), want))


def _declaring_modules() -> set[str]:
    found = set()
    for path in (ROOT / "aicalib_tf").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef):
                names = {d.func.id if isinstance(d, ast.Call) and isinstance(d.func, ast.Name) else getattr(d, "id", None)
                         for d in node.decorator_list}
                if names & {"kernel", "helper"}:
                    found.add(path.relative_to(ROOT / "aicalib_tf").as_posix())
    return found


def test_the_stamp_covers_every_module_that_declares_kernels():
    assert _declaring_modules() == set(kernels.KERNEL_SOURCES)


_DETECT = (
    "import json, sys, glob\n"
    "from aicalib_tf import kernels\n"
    "from aicalib_tf.detect.pipeline import detect_corners\n"
    "from aicalib_tf.io import load_image\n"
    "out = {'mode': kernels.MODE, 'corners': []}\n"
    "for p in sorted(glob.glob(sys.argv[1] + '/*.jpg')):\n"
    "    d = detect_corners(load_image(p), (9, 6))\n"
    "    out['corners'].append(d.corners.astype(float).tolist())\n"
    "out['numba'] = 'numba' in sys.modules\n"
    "print(json.dumps(out))\n"
)


def _detect_in_child(mode: str | None) -> dict:
    env = {k: v for k, v in os.environ.items() if k != kernels.MODE_ENV}
    if mode:
        env[kernels.MODE_ENV] = mode
    out = subprocess.run([sys.executable, "-c", _DETECT, str(LEFT)], capture_output=True, text=True,
                         timeout=600, cwd=ROOT, env=env)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


@BUILT
def test_the_extension_gives_the_jit_corners_bit_for_bit_and_loads_no_numba():
    aot, jit = _detect_in_child(None), _detect_in_child("jit")
    assert (aot["mode"], jit["mode"]) == ("aot", "jit")
    assert aot["numba"] is False and jit["numba"] is True
    assert len(aot["corners"]) == 13 and sum(len(c) == 54 for c in aot["corners"]) >= 12
    assert aot["corners"] == jit["corners"]


@BUILT
def test_an_extension_built_from_other_sources_is_not_used(monkeypatch, tmp_path):
    stamp = tmp_path / "stamp.json"
    stamp.write_text(json.dumps({"sources_sha256": "0" * 64, "cpu": kernels.cpu_name()}))
    monkeypatch.setattr(kernels, "STAMP_FILE", stamp)
    with pytest.warns(RuntimeWarning, match="built from other sources or on another CPU"):
        assert kernels._load_extension() is None
    stamp.write_text(json.dumps(kernels._stamp()))
    assert kernels._load_extension() is not None
    monkeypatch.setenv(kernels.MODE_ENV, "jit")
    assert kernels._load_extension() is None
