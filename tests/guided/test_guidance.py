"""Guidance: what is missing, and where the next view should go."""

import numpy as np

from aicalib_tf.calib.fit import fit_views
from aicalib_tf.calib.quality import coverage_counts, sigma_from_basis, uncertainty_basis
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
