"""The second look at thin boards (aicalib_tf.detect.chessboard.zoom and its use in detect_corners)."""

import numpy as np
import pytest

from aicalib_tf.detect.chessboard.zoom import FACTOR, from_zoom, zoom_box, zoom_in


def _lattice(step_x: float, step_y: float, shape=(4, 3), origin=(300.0, 200.0)):
    """A sheared lattice: ij (K, 2) and points (K, 2) px, corner (i, j) at origin + i·a + j·b."""
    i, j = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij")
    ij = np.stack([i.ravel(), j.ravel()], 1)
    a, b = np.array([step_x, 0.3 * step_x]), np.array([0.5 * step_y, step_y])
    return ij, np.asarray(origin) + ij[:, :1] * a + ij[:, 1:] * b


def test_from_zoom_maps_enlarged_pixel_centres_back_to_the_image():
    # on a linear ramp bilinear enlargement is exact, so each enlarged pixel's value is the image x
    # (or y) of its centre
    h, w = 40, 60
    ramp_x = np.tile(np.arange(w, dtype=np.float32), (h, 1))
    ramp_y = np.tile(np.arange(h, dtype=np.float32)[:, None], (1, w))
    box = (10, 5, 40, 30)
    big_x, big_y = zoom_in(ramp_x, box), zoom_in(ramp_y, box)
    assert big_x.shape == ((30 - 5) * FACTOR, (40 - 10) * FACTOR)
    ys, xs = np.mgrid[3:big_x.shape[0] - 3, 3:big_x.shape[1] - 3]  # away from the replicated border
    back = from_zoom(np.stack([xs.ravel(), ys.ravel()], 1), box)
    assert np.abs(back[:, 0] - big_x[ys, xs].ravel()).max() < 1e-3
    assert np.abs(back[:, 1] - big_y[ys, xs].ravel()).max() < 1e-3


def test_a_grid_with_wide_squares_or_few_corners_gets_no_second_look():
    ij, pts = _lattice(12.0, 10.0)
    assert zoom_box(ij, pts, (9, 6), (640, 480)) is None  # nearest corners 10+ px apart
    ij, pts = _lattice(4.0, 3.0, shape=(2, 4))
    assert zoom_box(ij, pts, (9, 6), (640, 480)) is None  # 8 corners: too few


def test_the_box_covers_every_place_the_board_could_be_and_stays_inside_the_image():
    ij, pts = _lattice(4.0, 3.0)  # 4 × 3 corners: the 9 × 6 board may reach 5 steps past each side
    x0, y0, x1, y1 = zoom_box(ij, pts, (9, 6), (640, 480))
    reach = 9 - np.array([4, 3])
    far = np.array([[-reach[0], -reach[1]], [3 + reach[0], 2 + reach[1]], [-reach[0], 2 + reach[1]],
                    [3 + reach[0], -reach[1]]])
    corners = pts[0] + far[:, :1] * np.array([4.0, 1.2]) + far[:, 1:] * np.array([1.5, 3.0])
    assert (corners[:, 0] >= x0).all() and (corners[:, 0] < x1).all()
    assert (corners[:, 1] >= y0).all() and (corners[:, 1] < y1).all()
    # near the frame: clipped to the image
    ij, pts = _lattice(4.0, 3.0, origin=(5.0, 3.0))
    x0, y0, x1, y1 = zoom_box(ij, pts, (9, 6), (60, 50))
    assert (x0, y0) == (0, 0) and x1 <= 60 and y1 <= 50


def test_a_region_too_large_to_enlarge_gets_no_second_look():
    ij, pts = _lattice(5.5, 5.0, shape=(3, 3), origin=(600.0, 500.0))
    assert zoom_box(ij, pts, (9, 6), (1920, 1080)) is not None
    # a 20 × 15 board could reach 17 steps (about 100 px) past each side of the grid: enlarged,
    # that region would pass MAX_PIXELS
    assert zoom_box(ij, pts, (20, 15), (1920, 1080)) is None


def test_candidates_near_the_grid_narrow_the_box_to_the_board():
    ij, pts = _lattice(4.0, 3.0)
    wide = zoom_box(ij, pts, (9, 6), (640, 480))
    # candidates 3 steps past one side of the grid, and one far outside where the board could be
    near = pts[0] + np.array([[-12.0, -3.6], [-12.0, 3.0]])
    box = zoom_box(ij, pts, (9, 6), (640, 480), others=np.concatenate([near, [[5.0, 5.0]]]))
    x0, y0, x1, y1 = box
    assert (x1 - x0) * (y1 - y0) < (wide[2] - wide[0]) * (wide[3] - wide[1])
    for p in np.concatenate([pts, near]):
        assert x0 <= p[0] < x1 and y0 <= p[1] < y1
    assert x0 > 5.0  # the far candidate is not the board's
    assert all(a >= b for a, b in zip(box[:2], wide[:2])) and all(a <= b for a, b in zip(box[2:], wide[2:]))


@pytest.mark.parametrize("index", [70])
def test_a_board_squeezed_at_the_edge_of_a_120_degree_lens_is_found_by_the_second_look(index, monkeypatch):
    # evaluate barrel #70: squares 1.8-14 px thick; at full size the network finds 32 of the 54
    # corners and the grid cannot be placed; enlarged 3x, the whole board is found
    import aicalib_tf.detect.pipeline as detect
    from aicalib_tf.bench.conditions import PATTERN, named_conditions
    from aicalib_tf.bench.metrics import board_detection_outcome
    from data_gen import make_sample

    cond = next(c for c in named_conditions() if c.name == "barrel")
    assert cond.min_tilt_deg == 0  # no filter: the condition's image `index` is rendered alone, not after 70 others
    s = make_sample(cond.preset, cond.seed, index, size=cond.size, pattern=PATTERN)
    looked = []
    real = detect._zoomed
    monkeypatch.setattr(detect, "_zoomed", lambda *a: looked.append(1) or real(*a))
    det = detect.detect_corners(s.image, (9, 6))
    assert looked and det.complete and det.image_size == (640, 480)
    outcome, err = board_detection_outcome(det.corners, s.corners, (9, 6))
    assert outcome == "hit" and np.median(err) < 0.1
    monkeypatch.setattr(detect, "_zoomed", lambda *a: None)
    monkeypatch.setattr(detect, "_unsheared", lambda *a: a[-1])  # nor the steep-tilt look (its squares are sheared too)
    assert not detect.detect_corners(s.image, (9, 6)).found  # without it: no board


def test_no_second_look_without_a_pattern_or_once_a_board_is_found(monkeypatch):
    import aicalib_tf.detect.pipeline as detect
    from data_gen import make_sample

    looked = []
    monkeypatch.setattr(detect, "_zoomed", lambda *a: looked.append(1))
    s = make_sample("clean", 0, 0, size=(640, 480), pattern=(9, 6))
    assert detect.detect_corners(s.image, (9, 6)).complete
    assert detect.detect_corners(s.image, None).complete
    assert not looked
