import json
import os
import signal
import subprocess
import sys
import time

import pytest

pytest.importorskip("keras")

from aicalib_tf.train import main  # noqa: E402

TINY = ["--steps", "3", "--batch-size", "4", "--pool-images", "4", "--val-images", "2", "--workers", "1", "--quiet"]


def _cli(*args, timeout=240):
    env = {**os.environ, "TF_CPP_MIN_LOG_LEVEL": "3"}
    return subprocess.Popen([sys.executable, "-m", "aicalib_tf.train", *args], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _tiny(run, arch: str) -> None:
    assert main(["--arch", arch, "--out", str(run), "--epochs", "2", "--seed", "4", *TINY]) == 0


@pytest.fixture(scope="module")
def default_run(tmp_path_factory):
    """A tiny default-architecture run (2 epochs, seed 4): its files are checked, and a second run must repeat it."""
    run = tmp_path_factory.mktemp("train") / "run"
    _tiny(run, "default")
    return run


@pytest.mark.slow
@pytest.mark.parametrize("arch", ["default", "report"])
def test_tiny_run_writes_every_file(tmp_path, arch, request):
    if arch == "default":
        run = request.getfixturevalue("default_run")
    else:
        run = tmp_path / "run"
        _tiny(run, arch)
    for name in ["config.json", "checkpoint-0002.keras", "state.json", "log.csv", "model.keras", "metrics.json"]:
        assert (run / name).is_file(), name
    assert len(list(run.glob("checkpoint-*.keras"))) == 1  # older checkpoints are removed
    assert (run / "tensorboard").is_dir()
    assert not list(run.glob("*partial*"))
    lines = (run / "log.csv").read_text().splitlines()
    assert lines[0].split(",")[0] == "epoch" and "val_recall" in lines[0] and len(lines) == 3
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["arch"] == arch and metrics["params"] > 0 and len(metrics["sha256"]) == 64
    assert json.loads((run / "config.json").read_text())["arch"] == arch


@pytest.mark.slow
def test_killed_run_resumes_from_its_last_checkpoint_and_ends_like_an_uninterrupted_run(tmp_path):
    import numpy as np

    from aicalib_tf.cnn.model import load_model

    epochs = 6
    run = tmp_path / "run"
    proc = _cli("--out", str(run), "--epochs", str(epochs), "--seed", "3", *TINY)
    state = run / "state.json"
    deadline = time.time() + 180
    while time.time() < deadline and proc.poll() is None:
        if state.is_file() and json.loads(state.read_text())["epochs_done"] >= 2:
            break
        time.sleep(0.05)
    assert proc.poll() is None, proc.stdout.read()
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done = json.loads(state.read_text())["epochs_done"]
    assert 2 <= done < epochs and not (run / "model.keras").exists()
    # resumed in this process (no third TensorFlow start): all it can take from the killed run is on disk
    assert main(["--out", str(run), "--resume", "--quiet"]) == 0  # the run's own --epochs is kept
    assert json.loads(state.read_text())["epochs_done"] == epochs
    logged = [int(line.split(",")[0]) for line in (run / "log.csv").read_text().splitlines()[1:]]
    assert logged[-1] == epochs - 1 and set(range(epochs)) <= set(logged)
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["resumed_at_epoch"] == done
    # the same seed without a kill gives the same weights: resuming replays the data exactly
    assert main(["--out", str(tmp_path / "straight"), "--epochs", str(epochs), "--seed", "3", *TINY]) == 0
    a = load_model(run / "model.keras").get_weights()
    b = load_model(tmp_path / "straight" / "model.keras").get_weights()
    for wa, wb in zip(a, b):
        np.testing.assert_allclose(wa, wb, rtol=0, atol=1e-6)


def test_same_seed_gives_the_same_weights(tmp_path, default_run):
    import numpy as np

    from aicalib_tf.cnn.model import load_model

    _tiny(tmp_path / "again", "default")
    weights = [load_model(run / "model.keras").get_weights() for run in (default_run, tmp_path / "again")]
    for wa, wb in zip(*weights):
        np.testing.assert_array_equal(wa, wb)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--arch", "resnet"], "unknown architecture"),
        (["--preset", "nope"], "unknown preset"),
        (["--epochs", "0"], "--epochs must be >= 1"),
        (["--squeeze", "1.5"], "--squeeze must be in [0, 1]"),
        (["--shrink", "-0.1"], "--shrink must be in [0, 1]"),
        (["--resume"], "holds no checkpoint"),
    ],
)
def test_bad_options_exit_2_with_a_clear_message(tmp_path, capsys, args, message):
    assert main(["--out", str(tmp_path / "run"), *args]) == 2
    assert message in capsys.readouterr().err


def test_refuses_to_overwrite_a_run(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.keras").write_bytes(b"x")
    assert main(["--out", str(run), *TINY]) == 2
    assert "already holds a run" in capsys.readouterr().err


def test_validation_without_tensorflow_decodes_the_same_points():
    # the path other Keras backends take (no aicalib_tf.cnn.inference): the same float32 map and decoding
    import numpy as np

    from aicalib_tf.cnn.inference import corner_points
    from aicalib_tf.cnn.model import load_model
    from aicalib_tf.cnn.train import _backend_corner_points
    from data_gen import make_sample

    model = load_model("default", backend="keras")
    for i in range(2):
        img = make_sample("distorted", 3, i, size=(322, 241)).image  # not a multiple of 4: padded
        want = corner_points(model, img, 0.5, precision="float32")[0]
        got = _backend_corner_points(model, img, 0.5)
        assert len(want) > 0
        np.testing.assert_allclose(got, want, atol=1e-4)


def test_a_pool_cache_renders_a_pool_once(tmp_path, monkeypatch):
    import numpy as np

    from aicalib_tf.cnn import train

    monkeypatch.setenv(train.POOL_CACHE_ENV, str(tmp_path))
    first = train.cached_pool(3, 5, preset="train", progress=False)
    files = list(tmp_path.glob("pool-*.npz"))
    assert len(files) == 1
    second = train.cached_pool(3, 5, preset="train", progress=False)
    assert np.array_equal(first.images, second.images)
    assert np.array_equal(first.mean, second.mean) and np.array_equal(first.std, second.std)
    assert all(np.array_equal(a, b) for a, b in zip(first.corners, second.corners, strict=True))
    files[0].write_bytes(b"not an npz")
    with pytest.raises(ValueError, match="pool-.*not a readable pool cache"):
        train.cached_pool(3, 5, preset="train", progress=False)


def test_init_starts_from_the_given_models_weights_and_records_it(tmp_path):
    import numpy as np

    from aicalib_tf.cnn.model import build_model, file_sha256, load_model
    from aicalib_tf.cnn.spec import MODELS_DIR
    from aicalib_tf.cnn.train import init_weights

    shipped = load_model("default", backend="keras").get_weights()
    fresh = build_model("default")
    assert any(not np.array_equal(a, b) for a, b in zip(fresh.get_weights(), shipped))
    init_weights(fresh, "default")
    for a, b in zip(fresh.get_weights(), shipped):
        np.testing.assert_array_equal(a, b)
    # a run at a vanishing learning rate ends where it started: the shipped weights, not a fresh start
    run = tmp_path / "run"
    assert main(["--out", str(run), "--epochs", "1", "--init", "default", "--learning-rate", "1e-9", *TINY]) == 0
    for a, b in zip(load_model(run / "model.keras").get_weights(), shipped):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-6)
    sha = file_sha256(MODELS_DIR / "default.keras")
    assert json.loads((run / "config.json").read_text())["init_model"]["sha256"] == sha
    assert json.loads((run / "metrics.json").read_text())["init"]["sha256"] == sha


def test_init_with_a_bad_or_mismatched_file_exits_2_naming_it(tmp_path, capsys):
    from aicalib_tf.cnn.model import build_model, save_model

    other = save_model(build_model("default_v1"), tmp_path / "v1.keras")
    broken = tmp_path / "broken.keras"
    broken.write_bytes(b"not a zip")
    cases = [(other, "does not match --arch"), (broken, "not a Keras 3 .keras archive"),
             (tmp_path / "missing.keras", "not found")]
    for i, (path, message) in enumerate(cases):
        assert main(["--out", str(tmp_path / f"run{i}"), "--init", str(path), *TINY]) == 2
        err = capsys.readouterr().err
        assert message in err and str(path) in err, err
    assert main(["--out", str(tmp_path / "run9"), "--init", "weights.h5", *TINY]) == 2
    assert "--init" in capsys.readouterr().err
