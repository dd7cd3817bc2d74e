"""calib.diff: the rotation-fitted projection difference of two calibrations (synthetic lenses and views)."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from aicalib_tf.calib import diff as D
from aicalib_tf.calib import quality as Q
from aicalib_tf.calib.coverage import coverage_counts
from aicalib_tf.calib.fit import fit_views
from aicalib_tf.geometry import lens as L
from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views

SIZE = (640, 480)
LENS = L.Lens("plumb_bob", [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]], [-0.25, 0.08, 0.001, -0.0005, 0.0], SIZE)


class _Rotated:
    """``lens`` seen from a camera frame turned by R0: project(P) = lens.project(R0·P) (a pure rotation)."""

    def __init__(self, lens, R0):
        self.lens, self.R0 = lens, R0
        self.image_size, self.K = lens.image_size, lens.K

    def project(self, P):
        return self.lens.project(np.asarray(P) @ self.R0.T)

    def unproject(self, q):
        return self.lens.unproject(q) @ self.R0

    def projection_jacobian(self, P):
        uv, Jp, Ji = self.lens.projection_jacobian(np.asarray(P) @ self.R0.T)
        return uv, Jp @ self.R0, Ji


def test_a_pure_rotation_is_fitted_out():
    R0 = cv2.Rodrigues(np.radians([0.4, -0.3, 0.2]))[0]
    turned = _Rotated(LENS, R0)
    fitted = D.projection_diff(LENS, turned)
    raw = D.projection_diff(LENS, turned, rotation=False)
    assert fitted["covered_stats"]["p95"] < 1e-6 and fitted["rotation_deg"] == pytest.approx(np.degrees(np.linalg.norm(
        cv2.Rodrigues(R0)[0])), rel=1e-4)
    assert raw["covered_stats"]["median"] > 2.0 and raw["rotation_deg"] == 0.0


def test_statistics_and_region():
    d = np.array([1.0, 2.0, 3.0, np.nan, 100.0])
    s = D.diff_stats(d, [True, True, True, True, False])
    assert (s["median"], s["cells"], s["max"]) == (2.0, 3, 3.0)
    assert np.isnan(D.diff_stats(d, np.zeros(5, bool))["median"])
    pts = D.grid_points(SIZE, (4, 3))
    assert pts.shape == (12, 2) and pts[0].tolist() == [79.5, 79.5]


@pytest.fixture(scope="module")
def two_fits():
    views = synthetic_views(LENS, 16, 0.2, seed=11)
    return views, [fit_views(v, PATTERN, SQUARE, SIZE, "plumb_bob") for v in (views[0::2], views[1::2])]


def test_two_calibrations_of_one_camera_differ_little(two_fits):
    views, (a, b) = two_fits
    r = D.compare_calibrations(a, b)
    assert r["coverage"] == "both" and 0 < r["covered_stats"]["median"] < 1.0
    assert r["covered_stats"]["p95"] >= r["covered_stats"]["median"]
    assert r["all_stats"]["cells"] == 32 * 24 and r["covered_stats"]["cells"] < r["all_stats"]["cells"]
    # the boards' stored poses cover about the cells the detected corners do
    from_corners = D.view_coverage([v.corners for v in views], SIZE)
    from_poses = D.board_coverage(a.lens, PATTERN, SQUARE, a.rvecs, a.tvecs) | D.board_coverage(
        b.lens, PATTERN, SQUARE, b.rvecs, b.tvecs)
    assert np.mean(from_corners == from_poses) > 0.95
    empty = dataclasses.replace(a, rvecs=np.zeros((0, 3)), tvecs=np.zeros((0, 3)))
    assert D.compare_calibrations(empty, b)["coverage"] == "whole image"


def test_half_difference_is_projection_diff_of_its_halves(two_fits):
    views, _ = two_fits
    h = Q.half_difference(views, fit_views, PATTERN, SQUARE, SIZE, "plumb_bob", "evenodd")
    covered = coverage_counts(views, SIZE, D.GRID).ravel() > 0
    r = D.projection_diff(h["cal_a"].lens, h["cal_b"].lens, covered=covered)
    assert h["median_covered"] == pytest.approx(r["covered_stats"]["median"], rel=1e-9)
    assert h["p95_covered"] == pytest.approx(r["covered_stats"]["p95"], rel=1e-9)


def test_different_sizes_or_cameras_are_refused(two_fits):
    _, (a, b) = two_fits
    with pytest.raises(ValueError, match="image sizes differ: 640x480 and 1280x960"):
        D.compare_calibrations(a, dataclasses.replace(b, image_size=(1280, 960)))
    K2 = b.K.copy()
    K2[:2, :2] *= 1.6
    with pytest.raises(ValueError, match="not one camera"):
        D.compare_calibrations(a, dataclasses.replace(b, K=K2))
    with pytest.raises(ValueError, match="split must be"):
        D.split_views([1, 2, 3], "thirds")


def test_view_coverage_fills_each_views_hull():
    square = [[100.0, 100.0], [500.0, 100.0], [500.0, 380.0], [100.0, 380.0]]
    m = D.view_coverage([square], SIZE).reshape(24, 32)
    assert m[12, 15] and m[5, 5] and not m[2, 2] and not m[20, 28]
    assert 280 <= m.sum() <= 315  # centres inside: 20 x 14; the cells the edges touch: 21 x 15
    assert D.view_coverage([[[10.0, 10.0]]], SIZE).sum() == 1


def test_boards_with_no_common_area_fall_back_to_the_whole_image(two_fits):
    _, (a, b) = two_fits
    at = lambda cal, x: dataclasses.replace(cal, rvecs=np.zeros((1, 3)), tvecs=np.array([[x, -0.1, 1.0]]))  # noqa: E731
    left, right = at(a, -0.6), at(b, 0.3)  # 0.32 m boards 1 m away: x 20-180 px and 470-630 px
    assert D.compare_calibrations(left, at(b, -0.6))["coverage"] == "both"
    r = D.compare_calibrations(left, right)
    assert r["coverage"] == "no common area" and r["covered_stats"]["cells"] == 32 * 24
