"""Guidance: what is missing, and where the next view should go."""

import numpy as np

from aicalib_tf.calib.fit import fit_views
from aicalib_tf.calib.coverage import coverage_counts
from aicalib_tf.calib.quality import sigma_from_basis, uncertainty_basis
from aicalib_tf.geometry.lens import Lens
from aicalib_tf.guided.guidance import missing, next_views

from ..calib.synthetic import PATTERN, SQUARE, synthetic_views

LENS = Lens("plumb_bob", [[600, 0, 319.5], [0, 600, 239.5], [0, 0, 1]], [-0.2, 0.05, 0, 0, 0], (640, 480))


def test_missing_names_regions_and_tilts():
    views = synthetic_views(LENS, 4, seed=1, avoid=(320, 0, 640, 480))
    text = missing(views, [(2.0, 1.0)] * 4, (640, 480))
    assert "top-right corner not covered" in text and "right of the image not covered" in text
    assert any("vertical axis" in t for t in text) and any("horizontal axis" in t for t in text)
    assert not any("tilt" in t for t in missing(views, [(30.0, 0.0), (0.0, -25.0)], (640, 480)))


def test_next_view_goes_where_no_board_was():
    views = synthetic_views(LENS, 8, noise=0.1, seed=2, avoid=(320, 0, 640, 480))
    cal = fit_views(views, PATTERN, SQUARE, (640, 480), "plumb_bob")
    covered = coverage_counts(views, (640, 480), (32, 24)).ravel() > 0
    _, G, ok = uncertainty_basis(cal, fit_mask=covered)
    ranked = next_views(cal.lens, np.linalg.pinv(cal.covariance), (G, ok), float(np.median(cal.tvecs[:, 2])),
                        PATTERN, SQUARE, cal.rms ** 2)
    assert [r.sigma_px for r in ranked] == sorted(r.sigma_px for r in ranked)
    assert ranked[0].text.startswith("next: hold the board at the")
    now = float(np.nanmean(sigma_from_basis(G, ok, cal.covariance)))
    by = {(r.region, r.tilt): r.sigma_px for r in ranked}
    facing = "facing the camera"
    assert ranked[0].sigma_px < 0.9 * now
    assert by[("top-right", facing)] < by[("top-left", facing)] and by[("bottom-right", facing)] < by[("bottom-left", facing)]


def test_missing_does_not_ask_for_corners_outside_the_image_circle():
    from aicalib_tf.calib.fit import View
    from aicalib_tf.geometry.image_circle import ImageCircle

    xs, ys = np.meshgrid(np.linspace(200, 440, 9), np.linspace(140, 340, 6))
    central = [View("v", np.stack([xs.ravel(), ys.ravel()], 1), np.zeros((54, 2)))]
    tilts = [(40.0, 40.0)]
    assert any("top-left corner" in m for m in missing(central, tilts, (640, 480)))
    inside = missing(central, tilts, (640, 480), ImageCircle(319.5, 239.5, 150.0))
    assert not any("corner" in m for m in inside)


def test_next_view_never_points_outside_the_image_circle():
    from aicalib_tf.calib.fit import View
    from aicalib_tf.calib.coverage import in_circle
    from aicalib_tf.geometry.image_circle import ImageCircle
    from aicalib_tf.guided.guidance import REGIONS, TILTS, candidate_points

    fish = Lens("equidistant", [[140, 0, 319.5], [0, 140, 239.5], [0, 0, 1]], [0.0, 0.0, 0.0, 0.0], (640, 480))
    circle = ImageCircle(319.5, 239.5, 140 * np.radians(80.0))  # a 160° circular lens: the frame's corners black
    views = []
    for v in synthetic_views(fish, 12, noise=0.02, seed=3, distance=(0.25, 0.4)):
        keep = circle.contains(v.corners)
        if keep.sum() >= 20:
            views.append(View(v.name, v.corners[keep], v.ids[keep]))
    cal = fit_views(views, PATTERN, SQUARE, (640, 480), "equidistant")
    covered = coverage_counts(views, (640, 480), (32, 24)).ravel() > 0
    _, G, ok = uncertainty_basis(cal, fit_mask=covered)
    distance = float(np.median(np.linalg.norm(cal.tvecs, axis=1)))
    for lens in (fish, cal.lens):
        beyond = [(r, t) for r in REGIONS for t in TILTS
                  if (P := candidate_points(lens, r, t, distance, PATTERN, SQUARE)) is not None
                  and not circle.contains(lens.project(P)).all()]
        assert beyond  # without the circle, boards at the left and right edges reach into the black
        for r in REGIONS:
            for t in TILTS:
                P = candidate_points(lens, r, t, distance, PATTERN, SQUARE, circle)
                assert P is not None and circle.contains(lens.project(P), margin=-2.0).all(), (r, t)
    ranked = next_views(cal.lens, np.linalg.pinv(cal.covariance), (G, ok & in_circle((640, 480), (32, 24), circle)),
                        distance, PATTERN, SQUARE, cal.rms ** 2, circle)
    assert {r.region for r in ranked} == set(REGIONS)  # every region still gets a board, inside the circle
    for r in ranked:
        uv = cal.lens.project(candidate_points(cal.lens, r.region, r.tilt, distance, PATTERN, SQUARE, circle))
        assert circle.contains(uv).all(), (r.region, r.tilt)
        assert "image circle" in r.text and "corner of the image" not in r.text and np.isfinite(r.sigma_px)
