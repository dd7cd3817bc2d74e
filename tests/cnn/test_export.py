import numpy as np
import pytest

import data_gen
from aicalib_tf.cnn import export


class _Sample:
    def __init__(self, index):
        self.image = np.full((8, 8), index, np.uint8)


def test_int8_calibration_replaces_a_scene_data_gen_cannot_pose(monkeypatch):
    asked = []

    def fake(name, seed, index):
        asked.append((name, index))
        if index == 1:
            raise RuntimeError("no acceptable pose")
        return _Sample(index)

    monkeypatch.setattr(data_gen, "make_sample", fake)
    monkeypatch.setattr(export, "CALIBRATION_PRESETS", ("a", "b"))
    images = list(export.calibration_images(3))
    assert len(images) == 3 and all(x.shape[0] == 1 and x.shape[-1] == 1 for x in images)
    assert asked == [("a", 0), ("b", 1), ("b", 4), ("a", 2)]  # scene 1 of b replaced by scene 1 + n


def test_int8_calibration_names_a_preset_it_cannot_draw(monkeypatch):
    def fake(name, seed, index):
        raise RuntimeError("no acceptable pose")

    monkeypatch.setattr(data_gen, "make_sample", fake)
    monkeypatch.setattr(export, "CALIBRATION_PRESETS", ("a",))
    with pytest.raises(RuntimeError, match="no 'a' scene"):
        list(export.calibration_images(2))


def test_int8_calibration_presets_exist_and_stay_fixed():
    """A preset added to data_gen later does not change what a re-export of the int8 models calibrates on."""
    assert set(export.CALIBRATION_PRESETS) <= set(data_gen.PRESETS)
    assert set(data_gen.PRESETS) - set(export.CALIBRATION_PRESETS) >= {"train_fisheye", "tilt_steep"}
