"""calib.flex_shift: a solved flex is kept only when it moves the projection beyond the flat fit's noise."""

from __future__ import annotations

import numpy as np

from aicalib_tf.calib.fit import _fit_model
from aicalib_tf.calib.flex_shift import FLEX_SHIFT_SIGMAS, flex_shift, shift_note
from aicalib_tf.calib.robust import SolveOptions
from aicalib_tf.geometry import lens as L
from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views

LENS = L.Lens("plumb_bob", [[620.0, 0, 322], [0, 621.0, 238], [0, 0, 1]], [-0.08, 0.01, 4e-4, -3e-4, 0.0], (640, 480))


def _fits(views):
    fit = lambda mode: _fit_model("plumb_bob", views, SQUARE, LENS.image_size, None,  # noqa: E731
                                  options=SolveOptions(PATTERN, mode, False))
    return fit("off"), fit("auto")


def test_a_bent_boards_flex_moves_the_projection_far_beyond_the_flat_fits_noise():
    views = synthetic_views(LENS, 10, 0.1, seed=3, flex=(0.03, 0.01))
    flat, flexed = _fits(views)
    assert flexed.flex is not None
    delta, sigma = flex_shift(flat, flexed, views, LENS.image_size)
    assert delta > FLEX_SHIFT_SIGMAS * sigma > 0
    assert shift_note(flat, flexed, views, LENS.image_size) == ""


def test_a_flat_boards_solved_flex_stays_within_the_noise_and_is_dropped():
    views = synthetic_views(LENS, 10, 0.1, seed=3)
    flat, flexed = _fits(views)
    delta, sigma = flex_shift(flat, flexed, views, LENS.image_size)
    assert np.isfinite(sigma) and delta < FLEX_SHIFT_SIGMAS * sigma
    assert flexed.flex is not None  # solved and determined (its σ rule), yet no more than noise
    note = shift_note(flat, flexed, views, LENS.image_size)
    assert note.startswith("not used: it moves the projection by") and "the board is taken as flat" in note
