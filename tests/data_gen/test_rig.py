"""data_gen rigs: the truth is consistent (poses compose, labels project), every camera sees the board."""

import cv2
import numpy as np
import pytest

from aicalib_tf.geometry.rectify import compose, rotation_angle_deg
from data_gen.rig import make_rig_sequence, sample_rig


def test_rig_frames_are_consistent_with_the_rig():
    truth, frames = make_rig_sequence(5, pairs=4, lenses=("pinhole", "fisheye", "pinhole"), size=(640, 480))
    assert [c.model for c in truth.cameras] == ["plumb_bob", "equidistant", "plumb_bob"]
    for fr in frames:
        R0 = cv2.Rodrigues(np.asarray(fr[0].label["rvec"]).reshape(3, 1))[0]
        t0 = np.asarray(fr[0].label["tvec"])
        for k, s in enumerate(fr):
            assert s.image.shape == (480, 640) and s.image.dtype == np.uint8
            assert s.label["camera_index"] == k and s.label["rig_id"] == 5
            Rk, tk = compose(truth.R[k], truth.T[k], R0, t0)
            np.testing.assert_allclose(cv2.Rodrigues(Rk)[0].ravel(), s.label["rvec"], atol=1e-12)
            np.testing.assert_allclose(tk, s.label["tvec"], atol=1e-9)
            assert s.visible.mean() >= 0.3
            # the board is really drawn where the label says: dark/light alternate around a visible corner
            c = s.corners[s.visible][len(s.corners[s.visible]) // 2]
            x, y = int(round(c[0])), int(round(c[1]))
            patch = s.image[max(y - 6, 0):y + 7, max(x - 6, 0):x + 7].astype(float)
            assert patch.max() - patch.min() > 60


@pytest.mark.parametrize("seed", range(5))
def test_rig_geometry_is_in_the_asked_range(seed):
    truth = sample_rig(np.random.default_rng(seed), ("pinhole", "pinhole"), (640, 480), baseline=(50, 500),
                       vergence_deg=(0, 10))
    assert 50 * 0.99 <= truth.baseline() <= 500 * 1.01
    assert rotation_angle_deg(truth.R[1]) <= 10.5
    assert 15 <= truth.board.square_size <= 60


def test_rig_sequences_are_deterministic():
    a = make_rig_sequence(2, pairs=2, lenses=("pinhole", "pinhole"), size=(320, 240))
    b = make_rig_sequence(2, pairs=2, lenses=("pinhole", "pinhole"), size=(320, 240))
    assert all(np.array_equal(x.image, y.image) for fa, fb in zip(a[1], b[1]) for x, y in zip(fa, fb))
    with pytest.raises(ValueError, match="at least 2 cameras"):
        sample_rig(np.random.default_rng(0), ("pinhole",))


def test_a_circular_rig_lens_images_a_whole_circle_inside_the_frame_and_black_outside():
    truth = sample_rig(np.random.default_rng(1), ("circular", "circular"), (640, 480))
    for cam in truth.cameras:
        assert cam.model == "equidistant" and 180.0 <= 2 * np.degrees(cam.max_theta) <= 195.0
        r = cam.circle_radius() * cam.K[0, 0]
        assert cam.K[0, 2] - r > 0 and cam.K[0, 2] + r < 639 and cam.K[1, 2] - r > 0 and cam.K[1, 2] + r < 479
    _, frames = make_rig_sequence(1, pairs=1, lenses=("circular", "pinhole"), size=(320, 240))
    img = frames[0][0].image.astype(float)
    assert img[:8, :8].mean() < 20 and img[100:140, 140:180].mean() > 40  # the corners are outside the circle


@pytest.mark.parametrize("spec", ["aprilgrid:3x2,tag=60mm,spacing=0.3",
                                  "charuco:5x4,square=40mm,marker=30mm,dict=DICT_4X4_50"])
def test_a_rig_renders_any_marker_board_with_its_truth(spec):
    """Rigs draw the marker boards the single-camera renders draw (data_gen.targets), labels included."""
    from data_gen.targets import parse_marker_board

    truth, frames = make_rig_sequence(6, pairs=1, lenses=("pinhole", "pinhole"), size=(320, 240),
                                      board=parse_marker_board(spec))
    assert truth.marker_board and 100 <= truth.baseline() <= 500
    for s in frames[0]:
        extra = s.label["tags"] if spec.startswith("aprilgrid") else s.label["markers"]
        assert len(extra["visible"]) == len(extra["ids"]) and any(extra["visible"])
        if spec.startswith("aprilgrid"):
            assert np.array_equal(s.label["ids"], truth.board.corner_ids())
        c = s.corners[s.visible][0]  # a tag corner (an X-junction) or an inner corner: dark and light meet there
        x, y = int(round(c[0])), int(round(c[1]))
        patch = s.image[max(y - 3, 0):y + 4, max(x - 3, 0):x + 4].astype(float)
        assert patch.max() - patch.min() > 60
