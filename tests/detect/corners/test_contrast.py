"""Each board corner's contrast against the noise about it (aicalib_tf.detect.corners.contrast)."""

import cv2
import numpy as np
import pytest

from aicalib_tf.detect.corners import contrast as cc


def _board(contrast: float, noise: float, angle: float = 20.0, square: float = 24.0, seed: int = 0, blur: float = 0.8):
    """A 240×240 checkerboard (mid-grey 100, black/white ± contrast/2) turned by ``angle``°, blurred, with Gaussian
    noise, as float64 grey levels (unrounded); its 5×5 inner corners about the image centre (N, 2) and their ids."""
    n, c = 240, 119.5
    t = np.radians(angle)
    y, x = np.mgrid[0:n, 0:n].astype(np.float64) - c
    u, v = np.cos(t) * x + np.sin(t) * y, -np.sin(t) * x + np.cos(t) * y
    img = 100.0 + 0.5 * contrast * np.sign(np.sin(np.pi * u / square) * np.sin(np.pi * v / square))
    img = cv2.GaussianBlur(img, (0, 0), blur) + np.random.default_rng(seed).normal(0.0, noise, img.shape)
    ids = np.array([(i, j) for j in range(5) for i in range(5)])
    uv = (ids - 2) * square
    pts = np.stack([np.cos(t) * uv[:, 0] - np.sin(t) * uv[:, 1], np.sin(t) * uv[:, 0] + np.cos(t) * uv[:, 1]], 1) + c
    return img, pts, ids


@pytest.mark.parametrize("noise", [2.0, 5.0])
def test_local_noise_reads_white_noise_beside_edges_and_ramps(noise):
    img, pts, ids = _board(60.0, noise)
    img = img + 0.3 * np.arange(img.shape[1])[None, :]  # a light ramp: no second difference
    got = cc.local_noise(img, pts, np.full(len(pts), 5))
    assert np.median(got) == pytest.approx(noise, rel=0.15)
    clean = cc.local_noise(np.round(_board(60.0, 0.0)[0]), pts, np.full(len(pts), 5))
    assert np.median(clean) < 0.6  # grey levels: the junction's own edges and the rounding leave little of it


def test_contrast_to_noise_follows_the_board_and_the_bound_its_inverse():
    for contrast, noise in ((60.0, 3.0), (12.0, 4.0)):
        img, pts, ids = _board(contrast, noise)
        m = cc.corner_contrast(img, pts, ids, step=1.0)
        assert np.all(m["contrast"] > 0)  # every corner in the board's colour order
        assert np.median(m["cnr"]) == pytest.approx(contrast / noise, rel=0.25)  # the sectors' means lose a little to blur
        assert np.all(m["z"] > m["cnr"])  # tens of pixels a sector
    strong = cc.corner_contrast(*_board(60.0, 3.0)[0:3], step=1.0)["bound"]
    faint = cc.corner_contrast(*_board(12.0, 4.0)[0:3], step=1.0)["bound"]
    assert np.median(faint) > 5 * np.median(strong)


def test_a_point_of_the_other_parity_has_negative_contrast_and_a_flat_one_none():
    img, pts, ids = _board(40.0, 2.0)
    swapped = ids.copy()
    swapped[12] = (7, 2)  # the centre corner named as one of the other colour order (odd id sum)
    m = cc.corner_contrast(img, pts, swapped, step=1.0)
    assert m["contrast"][12] < 0 and np.all(np.delete(m["contrast"], 12) > 0)
    flat = np.full_like(img, 100.0) + np.random.default_rng(1).normal(0.0, 3.0, img.shape)
    assert np.all(np.abs(cc.corner_contrast(flat, pts, ids, step=1.0)["z"]) < 4.5)


def test_lattice_directions_follow_the_ids_and_are_one_sided_at_the_board_edge():
    _, pts, ids = _board(40.0, 0.0, angle=30.0)
    dirs = cc.lattice_directions(pts, ids)
    t = np.radians(30.0)
    np.testing.assert_allclose(dirs[:, 0], np.tile([np.cos(t), np.sin(t)], (len(pts), 1)), atol=1e-9)
    np.testing.assert_allclose(dirs[:, 1], np.tile([-np.sin(t), np.cos(t)], (len(pts), 1)), atol=1e-9)
    assert cc.lattice_directions(np.zeros((0, 2)), np.zeros((0, 2), int)).shape == (0, 2, 2)


def test_sharply_meeting_lines_leave_the_contrast_unmeasured_not_refused():
    img, pts, ids = _board(40.0, 1.0)
    squeezed = pts.copy()
    squeezed[ids[:, 1] == 3] = pts[ids[:, 1] == 2] + 0.05 * (pts[ids[:, 1] == 3] - pts[ids[:, 1] == 2]) + [[3.0, 0.0]]
    contrast, counts = cc.sector_contrast(img, squeezed, ids, np.full(len(pts), 2))
    thin = counts.min(axis=1) < cc.MIN_SECTOR
    assert thin.any() and not thin.all()
    assert np.all(np.isnan(contrast[thin])) and np.all(np.isfinite(contrast[~thin]))


def test_a_full_board_loses_only_its_corners_of_the_other_colour_order():
    from aicalib_tf.detect.detection import Detection

    img, pts, ids = _board(40.0, 3.0)
    gray = (np.clip(np.round(img), 0, 255) / 255.0).astype(np.float32)

    def region(x0, y0, x1, y1):
        return gray[y0:y1, x0:x1]

    det = Detection(pts.astype(np.float32), ids.astype(np.int32), np.ones(len(pts), np.float32), (5, 5), True, (240, 240),
                    sigmas=np.full(len(pts), 0.1, np.float32))
    assert cc.without_reversed(det, region) is det  # every corner a junction of the board's order
    moved = pts.copy()
    moved[12] += 0.5 * ((pts[13] - pts[12]) + (pts[17] - pts[12]))  # a square's middle: no junction there
    moved[0] = pts[0] - (pts[1] - pts[0])  # a square beyond the board: the next junction, of the other colour order
    kept = cc.without_reversed(Detection(moved.astype(np.float32), ids.astype(np.int32), det.scores, (5, 5), True,
                                         (240, 240), sigmas=det.sigmas), region)
    assert not kept.complete and len(kept.corners) == len(pts) - 1
    np.testing.assert_array_equal(kept.ids, ids[1:])  # the one in a square's middle is faint, not reversed
    assert len(kept.sigmas) == len(kept.corners)


def test_a_frames_board_is_measured_once_and_another_frame_afresh():
    from aicalib_tf.detect.pyramid import Frame

    img, pts, ids = _board(40.0, 3.0)
    gray = np.clip(np.round(img), 0, 255).astype(np.uint8)
    frame, other = Frame(gray), Frame(gray.copy())
    first = cc.board_contrast(frame, pts, ids, (240, 240))
    assert cc.board_contrast(frame, pts, ids, (240, 240)) is first  # the detector's second question: the memo
    again = cc.board_contrast(other, pts, ids, (240, 240))
    assert again is not first and np.array_equal(again["z"], first["z"], equal_nan=True)
    moved = cc.board_contrast(frame, pts + 0.5, ids, (240, 240))  # other corners: measured again
    assert moved is not first and not np.array_equal(moved["contrast"], first["contrast"])
