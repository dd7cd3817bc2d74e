"""The models in models/ load safely, match their card, and score above a floor."""

import re

import numpy as np
import pytest

pytest.importorskip("keras")

from aicalib_tf.cnn.training_data import render_pool  # noqa: E402
from aicalib_tf.cnn.inference import corner_points  # noqa: E402
from aicalib_tf.cnn.point_metrics import point_detection_stats  # noqa: E402
from aicalib_tf.cnn.model import MODELS_DIR, file_sha256, load_model, model_kind  # noqa: E402
from aicalib_tf.cnn.train import VALIDATION_SEED  # noqa: E402

# Floors well below the card's figures and far above an untrained or broken model (which finds
# no corners: recall 0), on a fixed slice of the validation images.
FLOORS = {"default": {"precision": 0.6, "recall": 0.45}, "report": {"precision": 0.3, "recall": 0.3},
          "quick": {"precision": 0.6, "recall": 0.45}}


@pytest.fixture(scope="module")
def images():
    pool = render_pool(12, VALIDATION_SEED, workers=1, progress=False)
    return pool.images, pool.corners


@pytest.mark.parametrize("name, kind", [("default", "map"), ("report", "patch"), ("quick", "map")])
def test_shipped_model_loads_matches_its_card_and_scores_above_the_floor(images, name, kind):
    path = MODELS_DIR / f"{name}.keras"
    assert path.is_file(), f"{path} is missing"
    assert path.stat().st_size <= 20e6
    card = (MODELS_DIR / "MODEL_CARD.md").read_text()
    section = card.split(f"## `{name}.keras`")[1].split("\n## ")[0]
    assert re.search(r"sha256: `([0-9a-f]{64})`", section).group(1) == file_sha256(path)
    model = load_model(name)
    assert model_kind(model) == kind
    stats = point_detection_stats([(corner_points(model, img)[0], gt) for img, gt in zip(*images)])
    for key, floor in FLOORS[name].items():
        assert stats[key] >= floor, (name, stats)


def test_untrained_model_fails_the_floor(images):
    from aicalib_tf.cnn.model import build_model

    stats = point_detection_stats([(corner_points(build_model("default"), img)[0], gt) for img, gt in zip(*images)])
    assert not (stats["precision"] >= 0.6 and stats["recall"] >= 0.45)
    assert np.isfinite(stats["recall"])
