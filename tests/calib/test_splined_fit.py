"""The splined model's fit: layout from the views, refusal with too few views, files and remap maps."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from aicalib_tf.calib import files as F
from aicalib_tf.calib.bundle import CalibrationError
from aicalib_tf.calib.fit import View, fit_views
from aicalib_tf.calib.report import solve_lines
from aicalib_tf.calib.maps import MAP_FILES
from aicalib_tf.calib.splined_fit import MIN_VIEWS
from aicalib_tf.geometry._splined import splined_name
from aicalib_tf.geometry import lens as L
from aicalib_tf.geometry.pose import best_rotation
from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views

# a wide rational lens (no equidistant polynomial holds it exactly)
WIDE = L.Lens("rational_polynomial", [[330.0, 0, 322.0], [0, 331.0, 243.0], [0, 0, 1]],
              [0.35, 0.05, 1e-3, -8e-4, 0.0, 0.72, 0.14, 0.01], (640, 480))
# a ~190° fisheye
KB = L.Lens("equidistant", [[300.0, 0, 641.0], [0, 300.5, 479.0], [0, 0, 1]], [0.03, -0.012, 0.004, -0.0008], (1280, 960))


def displaced(views, every=3, seed=7):
    """(views with one corner of every ``every``-th view moved 3–10 px, {view name: [[col, row]]} of those)."""
    rng = np.random.default_rng(seed)
    out, moved = [], {}
    for k, v in enumerate(views):
        c = v.corners.copy()
        if k % every == 0:
            i = int(rng.integers(len(c)))
            c[i] += rng.uniform(3, 10) * np.array([np.cos(a := rng.uniform(0, 2 * np.pi)), np.sin(a)])
            moved[v.name] = [v.ids[i].tolist()]
        out.append(View(v.name, c, v.ids))
    return out, moved


@pytest.fixture(scope="module")
def spline_cal():
    views = synthetic_views(WIDE, 10, 0.005, seed=3, distance=(0.25, 0.45))
    dirty, moved = displaced(views)
    # a layout of the family's own choice takes a held-out fit per smoothness: the benchmark runs that
    return views, fit_views(dirty, PATTERN, SQUARE, WIDE.image_size, splined_name(8, 8, 140.0, 0.033)), moved


def test_displaced_corners_are_rejected_inside_the_splines_solve(spline_cal):
    _, cal, moved = spline_cal
    assert {k: v.tolist() for k, v in cal.rejected_corners.items()} == moved
    assert cal.n_rejected_corners == len(moved) and not cal.rejected
    assert solve_lines(cal)[0].startswith(f"{len(moved)} single corners rejected inside the solve")


def test_the_fit_recovers_another_models_projections(spline_cal):
    # on the views with their displaced corners: a fit that kept them is off by 1.3 px (median)
    views, cal, _ = spline_cal
    assert cal.model == splined_name(8, 8, 140.0, 0.033) and cal.rms < 0.015
    px = np.concatenate([v.corners for v in views])
    rays = WIDE.unproject(px)
    R = best_rotation(cal.lens, rays, px)
    err = np.linalg.norm(cal.lens.project(rays @ R.T) - WIDE.project(rays), axis=1)
    assert np.median(err) < 0.05 and np.percentile(err, 95) < 0.1


def test_too_few_views_are_refused_with_the_reason():
    views = synthetic_views(WIDE, MIN_VIEWS - 2, 0.005, seed=4)
    with pytest.raises(CalibrationError, match=f"needs at least {MIN_VIEWS} views covering the image, got {MIN_VIEWS - 2}"):
        fit_views(views, PATTERN, SQUARE, WIDE.image_size, "splined_equidistant")


def test_files_round_trip_and_the_maps_remap_like_the_lens(spline_cal, tmp_path):
    _, cal, moved = spline_cal
    F.save_calibration(cal, tmp_path)
    back = F.load_calibration(tmp_path / "camera.json")
    assert back.lens == cal.lens
    data = F.read_json(tmp_path / "camera.json")
    assert data["lens_layout"]["base"] == "equidistant" and data["undistort_maps"]["files"] == list(MAP_FILES)
    assert data["n_rejected_corners"] == len(moved) and data["rejected_corners"] == moved
    mx, my = (np.load(tmp_path / n, allow_pickle=False) for n in MAP_FILES)
    assert mx.dtype == np.float32 and mx.shape == (480, 640)
    new_K = np.array(data["undistort_maps"]["camera_matrix"])
    # the map sends an output pixel to where the lens images its pinhole ray
    uv = np.array([[100.0, 80.0], [320.0, 240.0], [500.0, 400.0]])
    ray = np.stack([(uv[:, 0] - new_K[0, 2]) / new_K[0, 0], (uv[:, 1] - new_K[1, 2]) / new_K[1, 1], np.ones(3)], 1)
    want = cal.lens.project(ray)
    got = np.stack([mx[uv[:, 1].astype(int), uv[:, 0].astype(int)], my[uv[:, 1].astype(int), uv[:, 0].astype(int)]], 1)
    np.testing.assert_allclose(got, want, atol=1e-3)
    img = (np.indices((480, 640)).sum(axis=0) % 256).astype(np.uint8)
    out = cv2.remap(img, mx, my, cv2.INTER_LINEAR)
    np.testing.assert_array_equal(out, F.undistort(img, cal))


def test_boards_that_leave_most_of_the_image_unseen_are_refused_with_the_reason():
    from aicalib_tf.calib.splined_fit import choose_layout

    w, h = KB.image_size
    whole = synthetic_views(KB, MIN_VIEWS, 0.0, seed=5, distance=(0.25, 0.45))
    assert choose_layout(KB, [v.corners for v in whole], KB.image_size, MIN_VIEWS)[0] >= 6
    right = synthetic_views(KB, MIN_VIEWS, 0.0, seed=5, avoid=(0, 0, 3 * w // 5, h), distance=(0.25, 0.45))
    with pytest.raises(CalibrationError, match=r"^splined_equidistant: \d+% of the \d+x\d+ knots under the image "
                       r"reach no corner \(at most 50%\): the boards leave part of the image unseen$"):
        choose_layout(KB, [v.corners for v in right], KB.image_size, MIN_VIEWS)


def test_the_model_choice_moves_on_when_the_spline_is_refused(monkeypatch):
    from aicalib_tf.calib import select
    from aicalib_tf.calib.fit import _fit_model

    monkeypatch.setattr(select, "AUTO_SPLINE_VIEWS", 0)
    monkeypatch.setattr(select, "misfit_note", lambda fit, views: None)  # as if the residuals showed a pattern
    views = synthetic_views(WIDE, MIN_VIEWS - 1, 0.05, seed=4)
    table, chosen, _ = select.select_model(views, SQUARE, lambda vs, m, start: _fit_model(m, vs, SQUARE, WIDE.image_size,
                                                                                           start),
                                           ("equidistant", "splined_equidistant"))
    assert chosen == "equidistant"
    assert table[1]["note"] == f"splined_equidistant: needs at least {MIN_VIEWS} views covering the image, got {MIN_VIEWS - 1}"


def test_the_model_choice_fits_a_spline_only_where_the_residuals_show_a_pattern():
    from types import SimpleNamespace

    from aicalib_tf.calib.splined_fit import misfit_note

    rng = np.random.default_rng(0)
    views = synthetic_views(WIDE, 12, 0.0, seed=5)
    noise = [0.1 * rng.standard_normal(v.corners.shape) for v in views]
    assert "no pattern" in misfit_note(SimpleNamespace(residuals=noise), views)
    # a 0.1 px displacement over the image's right third, below the noise of single corners
    bump = [n + 0.1 * (v.corners[:, :1] > 430) * [1.0, -0.5] for n, v in zip(noise, views)]
    assert misfit_note(SimpleNamespace(residuals=bump), views) is None


def test_a_start_that_bends_back_near_the_corners_gives_a_fitted_and_a_plain_base():
    import math

    from aicalib_tf.calib.splined_fit import RANGE_MARGIN_DEG, _bases

    bent = L.Lens("equidistant", WIDE.K, [-0.022, -0.114, 0.067, -0.033], WIDE.image_size)  # turns back at 67°
    theta = np.radians(np.linspace(5.0, 62.0, 40))
    rays = np.stack([np.sin(theta), 0.3 * np.sin(theta), np.cos(theta)], axis=1)
    px = [bent.project(rays)]
    fitted, plain = _bases(bent, px)
    assert not np.any(plain.dist) and np.count_nonzero(fitted.dist) >= 1
    widest = math.degrees(np.max(np.arctan2(np.hypot(*bent.unproject(px[0])[:, :2].T), bent.unproject(px[0])[:, 2])))
    assert math.degrees(fitted.max_angle()) >= widest + RANGE_MARGIN_DEG
    # the fitted base holds the start's radial bulk over the corners; θ_d = θ leaves it all to the knots
    err = lambda lens: np.max(np.abs(lens.project(rays) - px[0]))  # noqa: E731
    assert err(fitted) < 0.2 * err(plain)
    # a start that stays monotonic well beyond the corners is its own base
    good = L.Lens("equidistant", WIDE.K, [0.01, -0.002, 0.0, 0.0], WIDE.image_size)
    (only,) = _bases(good, [good.project(rays)])
    np.testing.assert_array_equal(only.dist, good.dist)


class _Bumped:
    """A lens plus a local 1.2 px displacement (σ 80 px at (900, 330)): no parametric model holds it."""

    def __init__(self, lens):
        self.lens, self.image_size = lens, lens.image_size

    def project(self, P):
        q = self.lens.project(P)
        g = np.exp(-np.sum((q - (900.0, 330.0)) ** 2, axis=-1) / (2 * 80.0 ** 2))
        return q + g[..., None] * np.array([1.0, -0.6])

    def unproject(self, q):
        return self.lens.unproject(q)


def test_the_folds_keep_the_smoothest_spline_unless_the_lens_asks_for_less():
    from aicalib_tf.calib.splined_fit import SMOOTH_REL
    from aicalib_tf.geometry.lens import get_model

    kb = KB
    smooth = lambda cal: get_model(cal.model).smooth / cal.lens.fx  # noqa: E731
    # 8 views of a lens equidistant holds: less smoothing only fits the noise
    plain = fit_views(synthetic_views(kb, 8, 0.05, seed=1), PATTERN, SQUARE, kb.image_size, "splined_equidistant")
    assert smooth(plain) == pytest.approx(SMOOTH_REL[0], rel=0.02)
    # with a bump the boards saw, the held-out views ask for a bendier spline
    views = synthetic_views(_Bumped(kb), 8, 0.02, seed=2)
    bumped = fit_views(views, PATTERN, SQUARE, kb.image_size, "splined_equidistant")
    assert smooth(bumped) < 0.5 * SMOOTH_REL[0]
    assert bumped.rms < fit_views(views, PATTERN, SQUARE, kb.image_size, "equidistant").rms


def test_the_spline_solves_a_bent_boards_shape_with_the_lens():
    from aicalib_tf.calib.fit import _fit_model
    from aicalib_tf.calib.robust import SolveOptions

    shape = (0.006, 0.004, 0.01, 0.004, -0.003, 0.002, 0.003)  # squares: all seven terms
    views, moved = displaced(synthetic_views(WIDE, 10, 0.005, seed=3, distance=(0.25, 0.45), flex=shape))
    fit = _fit_model(splined_name(8, 8, 140.0, 0.033), views, 1.0, WIDE.image_size, rank_strict=False,
                     options=SolveOptions(PATTERN, "shape"))
    np.testing.assert_allclose(fit.flex, shape, atol=5e-4)  # taken flat, the fit is off by 1.1 px (median)
    assert fit.rms < 0.015 and (~fit.inliers).sum() == len(moved)
    lens = L.Lens.from_intrinsics(fit.model, fit.intrinsics, WIDE.image_size)
    px = np.concatenate([v.corners for v in views])
    rays = WIDE.unproject(px)
    err = np.linalg.norm(lens.project(rays @ best_rotation(lens, rays, px).T) - WIDE.project(rays), axis=1)
    assert np.median(err) < 0.05
