"""The last corners of a steeply tilted board placed on its unsheared view (aicalib_tf.detect.chessboard.unshear_fill)."""

from dataclasses import dataclass

import cv2
import numpy as np
import pytest

from aicalib_tf.detect.chessboard import unshear_fill
from aicalib_tf.detect.chessboard.board_order import full_board_ids
from aicalib_tf.detect.chessboard.unshear_fill import MAX_FILL, filled_board, junction_contrast, pattern_indices
from aicalib_tf.detect.pyramid import refine_full

PATTERN = (9, 6)


@dataclass(frozen=True)
class _Det:  # the fields of a pipeline Detection that filled_board reads and replaces
    corners: np.ndarray
    ids: np.ndarray
    scores: np.ndarray
    complete: bool = False
    reason: str = ""
    relative: bool = False


def _view(step=12.0, origin=(60.3, 50.6), size=(240, 200), blur=1.5):
    """A blurred 9×6 chessboard (outer squares too) on white paper, squares of ``step`` px: (view (H, W) float32,
    its corners (54, 2) px row-major). The square beyond corner 0 is black."""
    s = 4  # supersampling
    ys, xs = np.mgrid[0:size[1] * s, 0:size[0] * s]
    u = ((xs + 0.5) / s - 0.5 - origin[0]) / step + 1  # board square column (corner 0 at 1, 1)
    v = ((ys + 0.5) / s - 0.5 - origin[1]) / step + 1
    inside = (u >= 0) & (u < PATTERN[0] + 1) & (v >= 0) & (v < PATTERN[1] + 1)
    black = inside & ((np.floor(u) + np.floor(v)) % 2 == 0)
    img = np.where(black, 0.1, 0.9).astype(np.float32)
    img = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
    img = cv2.GaussianBlur(img, (0, 0), blur)
    corners = np.asarray(origin) + full_board_ids(PATTERN) * step
    return img, corners.astype(np.float64)


def _partial(corners, missing, relative=False):
    keep = np.setdiff1d(np.arange(len(corners)), missing)
    ids = full_board_ids(PATTERN)[keep] + [3, -2]  # ids relative to some origin: only their span matters
    return _Det(corners[keep].astype(np.float32), ids.astype(np.int32), np.full(len(keep), 0.9, np.float32),
                relative=relative)


def test_pattern_indices_read_a_grid_spanning_the_pattern_either_way_round_with_its_handedness():
    ids = full_board_ids(PATTERN)
    pts = ids * [20.0, 5.0]
    np.testing.assert_array_equal(pattern_indices(ids + 7, pts, PATTERN), np.arange(54))
    turned = np.stack([5 - ids[:, 1], ids[:, 0]], 1)  # the same board, its grid's axes a quarter turned
    np.testing.assert_array_equal(pattern_indices(turned, pts, PATTERN), np.arange(54))
    assert pattern_indices(ids[ids[:, 0] < 8], pts[ids[:, 0] < 8], PATTERN) is None  # spans 8 columns
    assert pattern_indices(np.r_[ids, [[9, 0]]], np.r_[pts, [[180.0, 0.0]]], PATTERN) is None  # 10 columns
    mirrored = pattern_indices(ids, pts * [1, -1], PATTERN)  # rows running up: read with rows down
    np.testing.assert_array_equal(mirrored, (5 - ids[:, 1]) * 9 + ids[:, 0])


def test_junction_contrast_has_one_sign_on_every_corner_and_none_on_blank_paper():
    view, corners = _view()
    lat, _ = cv2.findHomography(full_board_ids(PATTERN).astype(np.float64), corners, 0)
    got = junction_contrast(view, lat, full_board_ids(PATTERN))
    assert np.all(got < -1.2)  # the diagonal pairs differ by 2 × (0.9 − 0.1), a little less blurred
    blank = np.full_like(view, 0.5)
    assert np.abs(junction_contrast(blank, lat, full_board_ids(PATTERN))).max() < 1e-5


@pytest.mark.parametrize("missing", [[52], [0, 8, 45, 53], [20, 21, 29, 30, 31]])
def test_a_board_missing_a_few_corners_is_completed_on_its_view(missing):
    view, corners = _view()
    got = filled_board(_partial(corners, missing), PATTERN, view, refine_full)
    assert got is not None and got.complete and not got.relative
    np.testing.assert_array_equal(got.ids, full_board_ids(PATTERN))
    err = np.linalg.norm(got.corners - corners, axis=1)  # the rule's order: corner 0 beside the black outer square
    assert err.max() < 0.2 and np.delete(err, missing).max() < 1e-4  # the found corners kept as they were
    np.testing.assert_array_equal(np.nonzero(got.scores == 0)[0], missing)


def test_no_board_without_a_junction_where_one_is_missing_nor_from_too_few_or_relative_corners():
    view, corners = _view()
    hidden = view.copy()
    x, y = corners[30].round().astype(int)
    hidden[y - 8:y + 9, x - 8:x + 9] = 0.5  # an object in front of corner 30: no junction there
    assert filled_board(_partial(corners, [30]), PATTERN, hidden, refine_full) is None
    assert filled_board(_partial(corners, [30]), PATTERN, view, refine_full) is not None
    assert filled_board(_partial(corners, list(range(MAX_FILL + 1))), PATTERN, view, refine_full) is None
    assert filled_board(_partial(corners, [30], relative=True), PATTERN, view, refine_full) is None
    assert filled_board(_partial(corners, list(range(9))), PATTERN, view, refine_full) is None  # spans 5 rows


def test_a_steep_board_the_search_leaves_a_corner_short_of_is_found_complete(monkeypatch):
    from aicalib_tf.bench.conditions import PATTERN as P, generalize_conditions
    from aicalib_tf.bench.metrics import board_detection_outcome
    from aicalib_tf.detect import pipeline
    from data_gen import make_sample

    cond = {c.name: c for c in generalize_conditions()}["tilt-steep"]
    s = make_sample(cond.preset, 97, 95, size=cond.size, pattern=P)  # 77°, its far corner's squares 1.8 px thick
    det = pipeline.detect_corners(s.image, P)
    assert det.complete and board_detection_outcome(det.corners, s.corners, P)[0] == "hit"
    monkeypatch.setattr(unshear_fill, "MAX_FILL", 0)  # no position filled: the search's 50 corners stay a partial board
    assert not pipeline.detect_corners(s.image, P).complete


def test_empty_positions_are_predicted_by_their_neighbours_lattice_and_refused_where_the_lens_bends_it():
    from aicalib_tf.detect.chessboard.unshear_fill import local_guesses

    ij = full_board_ids(PATTERN).astype(np.float64)
    lat = np.array([[14.0, 3.0, 40.0], [1.0, 12.0, 30.0], [0.004, 0.03, 1.0]])  # a board in perspective
    pts = cv2.perspectiveTransform(ij.reshape(-1, 1, 2), lat).reshape(-1, 2)
    empty = np.array([7, 8, 17, 26])  # a far corner's cluster, as a steep board's search leaves it
    kept = np.setdiff1d(np.arange(len(ij)), empty)
    got = local_guesses(ij[kept], pts[kept], ij[empty])
    assert got is not None and np.abs(got - pts[empty]).max() < 1e-3
    def bent(k):  # barrel distortion k about the board's near corner, r in units of 100 px
        r2 = ((pts - pts[45]) ** 2).sum(axis=1) / 100.0**2
        return pts[45] + (pts - pts[45]) * (1.0 - k * r2)[:, None]

    mild = bent(0.05)
    got = local_guesses(ij[kept], mild[kept], ij[empty])
    whole, _ = cv2.findHomography(ij[kept], mild[kept], 0)  # the whole board's homography: 3 times further off
    off = np.linalg.norm(cv2.perspectiveTransform(ij[empty].reshape(-1, 1, 2), whole).reshape(-1, 2) - mild[empty], axis=1)
    assert got is not None and np.linalg.norm(got - mild[empty], axis=1).max() < off.max() / 2
    assert local_guesses(ij[kept], bent(0.3)[kept], ij[empty]) is None  # its far squares 3 times thinner: refused
    assert local_guesses(ij[kept][:5], pts[kept][:5], ij[empty]) is None  # too few corners to span a lattice
