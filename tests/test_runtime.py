"""The shipped LiteRT models: detection without TensorFlow, same corners as Keras, clear errors."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
LEFT = ROOT / "tests" / "data" / "opencv_left"


def test_detection_leaves_tensorflow_and_keras_unloaded():
    code = (
        "import json, sys\n"
        "import aicalib_tf\n"
        "from aicalib_tf import detect_corners, load_image\n"
        f"d = detect_corners(load_image({str(LEFT / 'left01.jpg')!r}), (9, 6))\n"
        "print(json.dumps({'complete': bool(d.complete), 'n': len(d.corners),\n"
        "    'tf': 'tensorflow' in sys.modules, 'keras': 'keras' in sys.modules}))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    res = json.loads(out.stdout.strip().splitlines()[-1])
    assert res == {"complete": True, "n": 54, "tf": False, "keras": False}


@pytest.mark.parametrize("name", ["left01.jpg", "left07.jpg", "left12.jpg"])
def test_runtime_and_keras_give_the_same_corners(name):
    from aicalib_tf.cnn.model import load_model
    from aicalib_tf.detect.pipeline import detect_corners
    from aicalib_tf.io import load_image

    gray = load_image(LEFT / name)
    rt = detect_corners(gray, (9, 6), model=load_model("default"))
    ks = detect_corners(gray, (9, 6), model=load_model("default", backend="keras"))
    assert rt.complete and ks.complete
    np.testing.assert_array_equal(rt.ids, ks.ids)
    assert np.abs(rt.corners - ks.corners).max() <= 1e-3


def test_runtime_map_matches_keras_float32():
    from aicalib_tf.cnn.inference import corner_map, patch_weights
    from aicalib_tf.cnn.model import load_model
    from aicalib_tf.io import load_image

    gray = load_image(LEFT / "left01.jpg")[:301, :403]  # an odd size: padded to multiples of 4
    a = corner_map(load_model("default"), gray)
    b = corner_map(load_model("default", backend="keras"), gray, precision="float32")
    assert a.shape == b.shape and np.abs(a - b).max() < 1e-4
    pts = np.array([[100, 100], [200, 150], [5, 5]])
    wa = patch_weights(load_model("report"), gray, pts)
    wb = patch_weights(load_model("report", backend="keras"), gray, pts)
    assert np.abs(wa - wb).max() < 1e-4


@pytest.mark.parametrize("name, remedy", [("default.tflite", "re-create it with `python -m aicalib_tf.export`"),
                                          ("default.keras", "restore it \\(git checkout\\)")])
def test_missing_or_corrupt_model_names_the_file_and_the_sha256(tmp_path, name, remedy):
    from aicalib_tf.cnn.model import MODELS_DIR, load_model
    from aicalib_tf.cnn.spec import expected_sha256

    want = expected_sha256(MODELS_DIR / name)
    assert want and len(want) == 64
    bad = tmp_path / name
    bad.write_bytes((MODELS_DIR / name).read_bytes()[:-10] + b"0123456789")
    (tmp_path / f"{name}.sha256").write_text(f"{want}  {name}\n")
    with pytest.raises(ValueError, match=f"corrupt model file {bad}: sha256 [0-9a-f]{{64}}, expected {want}; {remedy}"):
        load_model(bad)
    bad.unlink()
    with pytest.raises(FileNotFoundError, match=f"model file not found: {bad} \\(expected sha256 {want}\\); {remedy}"):
        load_model(bad)


def test_shipped_tflite_matches_its_recorded_sha256():
    from aicalib_tf.cnn.model import MODELS_DIR, file_sha256
    from aicalib_tf.cnn.runtime import expected_sha256
    from aicalib_tf.cnn.spec import RUNTIME_FILES

    assert set(RUNTIME_FILES) == {"default", "report", "default_int8", "quick", "quick_int8"}
    paths = [MODELS_DIR / f"{n}.tflite" for n in RUNTIME_FILES] + [MODELS_DIR / f"{n}.keras" for n in ("default", "report", "quick")]
    for path in paths:
        assert file_sha256(path) == expected_sha256(path)


@pytest.mark.parametrize("name", ["left01.jpg", "left12.jpg"])
def test_int8_model_gives_float32_boards(name):
    """default_int8 (weights and activations int8) finds the same full board, corners within 0.05 px."""
    from aicalib_tf.cnn.model import load_model
    from aicalib_tf.detect.pipeline import detect_corners
    from aicalib_tf.io import load_image

    q = load_model("default_int8")
    assert q.kind == "map" and q.aicalib_path.endswith("default_int8.tflite")
    gray = load_image(LEFT / name)
    a, b = detect_corners(gray, (9, 6), model=load_model("default")), detect_corners(gray, (9, 6), model=q)
    assert a.complete and b.complete
    np.testing.assert_array_equal(a.ids, b.ids)
    assert np.abs(a.corners - b.corners).max() < 0.05


def test_a_keras_model_without_tensorflow_says_what_to_install(tmp_path):
    """TensorFlow and Keras blocked from importing: loading a .keras model, and the CLI, say what to install."""
    block = "import sys; sys.modules['tensorflow'] = None; sys.modules['keras'] = None\n"
    code = block + (
        "from aicalib_tf.cnn.model import load_model\n"
        "try:\n"
        "    load_model('default', backend='keras')\n"
        "except ImportError as exc:\n"
        "    print(exc)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert "default.keras" in out.stdout and "pip install 'tensorflow-cpu" in out.stdout
    cli = block + ("import sys; from aicalib_tf.detect.__main__ import main\n"
                   f"sys.exit(main([{str(LEFT / 'left01.jpg')!r}, '--pattern', '9x6', '--out', {str(tmp_path)!r}, "
                   "'--model', 'models/default.keras']))\n")
    out = subprocess.run([sys.executable, "-c", cli], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 2 and out.stderr.count("\n") == 1 and "pip install 'tensorflow-cpu" in out.stderr
