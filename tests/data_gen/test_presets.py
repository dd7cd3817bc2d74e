import numpy as np
import pytest

from data_gen import PRESETS, get_preset, make_sample

REQUIRED = ("clean", "noisy", "blur", "distorted", "occluded", "hard", "train")


def test_required_presets_exist():
    assert set(REQUIRED) <= set(PRESETS)
    with pytest.raises(ValueError, match="unknown preset"):
        get_preset("nope")


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_every_preset_renders_with_consistent_labels(name):
    s = make_sample(name, seed=7, index=1, size=(320, 240))
    assert s.image.shape == (240, 320) and s.image.dtype == np.uint8
    lab = s.label
    assert lab["condition"] == name
    if lab["has_board"]:
        n = lab["pattern_size"][0] * lab["pattern_size"][1]
        assert s.corners.shape == (n, 2) and s.visible.shape == (n,)
        assert s.visible.any()
    else:
        assert lab["corners"] == [] and name == "clutter"


def test_samples_are_deterministic_and_differ_by_index():
    a = make_sample("hard", 3, 5, size=(320, 240))
    b = make_sample("hard", 3, 5, size=(320, 240))
    c = make_sample("hard", 3, 6, size=(320, 240))
    assert np.array_equal(a.image, b.image) and a.label == b.label
    assert not np.array_equal(a.image, c.image)


def test_train_preset_mixes_conditions():
    labels = [make_sample("train", 0, i, size=(320, 240)).label for i in range(24)]
    names = {d["name"] for lab in labels for d in lab["degradations"]}
    assert {"gaussian_noise", "gaussian_blur"} <= names and len(names) >= 6
    assert len({tuple(lab["pattern_size"]) for lab in labels}) > 10
    assert any(lab["framing"] == "partial" for lab in labels)


def test_steep_tilts_are_reached():
    import cv2

    tilts = []
    for i in range(20):
        lab = make_sample("distorted", 0, i, size=(320, 240)).label
        R = cv2.Rodrigues(np.array(lab["rvec"]))[0]
        tilts.append(np.degrees(np.arccos(R[2, 2])))
    assert max(tilts) > 45 and max(tilts) <= 60.01


def test_occluded_boards_keep_some_corners_and_narrow_images_work():
    for i in range(12):
        s = make_sample("hard", 1, i, size=(32, 32))
        if s.label["has_board"]:
            assert s.visible.any()
    for size in [(32, 400), (2000, 200), (300, 32)]:
        for i in range(3):
            s = make_sample("occluded", 0, i, size=size)
            assert s.visible.any()


@pytest.mark.parametrize("pattern, size", [((3, 3), (64, 48)), ((20, 15), (640, 480)), ((15, 20), (1920, 1080))])
def test_extreme_patterns_and_sizes(pattern, size):
    s = make_sample("clean", 0, 0, size=size, pattern=pattern)
    assert s.image.shape == (size[1], size[0])
    assert s.corners.shape == (pattern[0] * pattern[1], 2) and s.visible.all()
