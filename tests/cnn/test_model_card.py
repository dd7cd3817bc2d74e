import hashlib
import json

from aicalib_tf.cnn.model import file_sha256
from aicalib_tf.cnn.model_card import main, train_command


def _run(tmp_path, arch="default", body=b"model bytes"):
    run = tmp_path / f"runs-{arch}"
    run.mkdir()
    config = {"arch": arch, "epochs": 2, "steps": 3, "batch_size": 4, "seed": 5, "preset": "train",
              "pool_images": 6, "val_images": 2, "learning_rate": 0.002, "focal_gamma": 2.0, "threshold": 0.5}
    (run / "config.json").write_text(json.dumps(config))
    (run / "model.keras").write_bytes(body)
    (run / "log.csv").write_text("epoch,loss\n0,1.0\n")
    metrics = {"precision": 0.9, "recall": 0.8, "f1": 0.847, "loc_median_px": 0.2, "loc_p95_px": 0.7,
               "params": 24483, "wall_s_total": 900.0, "wall_s_this_process": 900.0, "sha256": hashlib.sha256(body).hexdigest(),
               "size_bytes": len(body), "validation": {"preset": "train", "seed": 900001, "images": 2, "match_px": 1.0}}
    (run / "metrics.json").write_text(json.dumps(metrics))
    return run, config


def test_the_card_holds_each_models_command_and_the_copied_files_hash(tmp_path):
    run, config = _run(tmp_path)
    out = tmp_path / "models"
    assert main([str(run), "--out", str(out)]) == 0
    assert (out / "default.keras").read_bytes() == b"model bytes"
    assert (out / "default_log.csv").is_file()
    card = (out / "MODEL_CARD.md").read_text()
    assert "## `default.keras`" in card and train_command(config) in card
    assert "--arch default --epochs 2 --steps 3 --batch-size 4 --seed 5" in train_command(config)
    assert "15.0 min." in card and "24,483" in card and "| 0.9000 | 0.8000 |" in card
    assert f"sha256: `{file_sha256(out / 'default.keras')}`" in card


def test_an_unfinished_run_is_refused_before_anything_is_written(tmp_path, capsys):
    good, _ = _run(tmp_path)
    bad, _ = _run(tmp_path, arch="report")
    (bad / "metrics.json").unlink()  # killed before the end
    out = tmp_path / "models"
    assert main([str(good), str(bad), "--out", str(out)]) == 2
    assert "not a finished training run" in capsys.readouterr().err
    assert not out.exists()


def test_the_command_names_the_crop_options_and_older_runs_get_their_defaults():
    config = {"arch": "default", "epochs": 40, "steps": 750, "batch_size": 32, "seed": 0,
              "preset": "train:0.75,distorted:0.25", "pool_images": 4000, "val_images": 64,
              "learning_rate": 0.002, "focal_gamma": 2.0, "squeeze": 0.5, "shrink": 0.25}
    cmd = train_command(config)
    assert "--preset train:0.75,distorted:0.25" in cmd and cmd.endswith("--squeeze 0.5 --shrink 0.25")
    older = {k: v for k, v in config.items() if k not in ("squeeze", "shrink", "focal_gamma")}
    assert train_command(older).endswith("--focal-gamma 0.0 --squeeze 0.0 --shrink 0.0")
    assert "--init" not in cmd and train_command({**config, "init": "default"}).endswith("--shrink 0.25 --init default")


def test_the_card_says_how_much_of_the_wall_time_was_the_image_pool(tmp_path):
    run, _ = _run(tmp_path)
    metrics = json.loads((run / "metrics.json").read_text())
    (run / "metrics.json").write_text(json.dumps({**metrics, "data_prep_s": 6.0}))
    assert main([str(run), "--out", str(tmp_path / "models")]) == 0
    assert "15.0 min (of which 0.1 min rendering or loading the image pools)." in (tmp_path / "models" / "MODEL_CARD.md").read_text()


def test_runtime_section_replaces_its_own_part_of_the_card_only():
    from aicalib_tf.cnn.model_card import RUNTIME_HEADING, with_runtime_section

    card = "# Model card\n\n## `default.keras`\n\nweights\n"
    once = with_runtime_section(card, f"{RUNTIME_HEADING}\n\nold\n")
    assert once.startswith(card.rstrip("\n")) and once.endswith("old\n")
    middle = once + "\n## later\n\nkept\n"
    again = with_runtime_section(middle, f"{RUNTIME_HEADING}\n\nnew\n")
    assert "old" not in again and "new" in again and again.endswith("## later\n\nkept\n")
    assert again.count(RUNTIME_HEADING) == 1 and "## `default.keras`\n\nweights" in again
