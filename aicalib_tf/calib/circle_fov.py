"""A circular fisheye's field of view past the boards' reach: the polynomial's order by held-out views.

Where the image circle's rim lies beyond the widest ray the boards reached, the circle's diameter in
degrees (:func:`~aicalib_tf.geometry.image_circle.circle_fov_deg`) is the lens model's extrapolation.
For the equidistant model (Kannala–Brandt, θ_d = θ(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸)) the terms the
boards' rays hardly constrain decide it: on a real 185° lens reaching 84° off-axis, k1..k4 put the
rim at 206°, k1..k3 at 200°, k1..k2 at 197°, Double Sphere and EUCM at 198°, all within one standard
error of each other held out. The figure is therefore read through the fewest terms the views
support: k1..k2, k1..k3 and k1..k4 are each fitted (the higher terms held at 0) and cross-validated
on the same folds as the model choice (:func:`aicalib_tf.calib.select.fold_scores`), and the
smallest order within one standard error of the best (:mod:`aicalib_tf.calib.select`'s rule) gives
the figure. The calibration itself keeps its model and terms (the held-out views cannot tell them apart).

On corner-level synthetic truth (``benchmarks/circle_fov.py``: equidistant lenses with zero,
equisolid-like, stereographic-like and steepening coefficients, Double Sphere and EUCM lenses, 150°
to 210°, boards reaching 70–85° off-axis; 192 runs) this rule's |error| was 1.4° on average (90th
percentile 3.1°) against 3.2° (8.9°) for the model's own k1..k4 extrapolation, smaller on 7 of the 8
lenses; it is worse on a lens whose r(θ) steepens sharply past the reach (data_gen's rig lens with
k1..k4 > 0: 3.8° against 3.0°, up to 25° at a 210° lens seen to 85°), which no fit of the seen rays
can know.
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.calib.bundle import CalibrationError, poses_from_rays
from aicalib_tf.calib.robust import SolveOptions, solve
from aicalib_tf.calib.select import fold_scores, near_best
from aicalib_tf.geometry.image_circle import boards_reach_deg, circle_fov_deg
from aicalib_tf.geometry.lens import N_COEFFS, Lens
from aicalib_tf.geometry.pattern import board_points

__all__ = ["TERMS", "MIN_VIEWS", "BEYOND_DEG", "order_fit", "order_rows", "fewest_terms", "extrapolated_fov"]

MODEL = "equidistant"
TERMS = (2, 3, 4)  # the orders tried: k1..k2, k1..k3, k1..k4
MIN_VIEWS = 4  # fewer views: no folds (the model's own figure)
BEYOND_DEG = 1.0  # the rim counts as beyond the boards' reach when it is this many degrees past it


def order_fit(terms: int, image_size, options: SolveOptions):
    """fit(views, model, start) -> BundleResult for :func:`~aicalib_tf.calib.select.fold_scores`: the
    equidistant model with k_(terms+1)..k4 held at 0, from ``start`` (an equidistant Lens), poses from
    its rays; board points for a unit square. Raises CalibrationError when the start sees no board."""
    free = np.ones(4 + N_COEFFS[MODEL], bool)
    free[4 + terms:] = False

    def fit(views, model, start):
        obj = [board_points(v.ids, 1.0) for v in views]
        px = [v.corners for v in views]
        poses = poses_from_rays(start, obj, px)
        if poses is None:
            raise CalibrationError(f"{MODEL} k1..k{terms}: the start lens sees no board in front of it in some view")
        intr = np.where(free, start.intrinsics(), 0.0)
        return solve(model, views, obj, px, intr, poses, free=free, rank_strict=True, options=options, unit=1.0)

    return fit


def order_rows(views, lens: Lens, circle, pattern_size, terms=TERMS) -> list[dict]:
    """One row per order: {"terms", "n_params", "rms", "cv_rms", "cv_se", "cv_folds" (px), "corners",
    "fov_deg" (the ``circle``'s diameter through the all-views fit)}; an order that cannot be fitted or
    cross-validated is left out. lens : the calibration's equidistant lens (the fits' start);
    pattern_size : (cols, rows). Flat board, single corners rejected, the views' σ as weights."""
    options = SolveOptions(tuple(pattern_size), "off", True)
    rows = []
    for t in terms:
        fit = order_fit(t, lens.image_size, options)
        try:
            full = fit(views, MODEL, lens)
            folds = fold_scores(views, 1.0, fit, MODEL, full, pattern_size)
        except CalibrationError:
            continue
        fov = circle_fov_deg(Lens.from_intrinsics(MODEL, full.intrinsics, lens.image_size), circle)
        rows.append({"terms": t, "n_params": 4 + t, "rms": float(full.rms), "cv_rms": float(folds.mean()),
                     "cv_se": float(folds.std(ddof=1) / np.sqrt(len(folds))), "cv_folds": folds.tolist(),
                     "corners": int(sum(len(v.ids) for v in views)), "fov_deg": float(fov)})
    return rows


def fewest_terms(rows: list[dict]) -> dict | None:
    """The row with the fewest terms whose held-out RMS is within the noise of the best's
    (:mod:`aicalib_tf.calib.select`'s one-standard-error rule); None without rows."""
    if not rows:
        return None
    return min(near_best(rows), key=lambda r: r["terms"])


def extrapolated_fov(cal, views, lens: Lens) -> dict | None:
    """The image circle's diameter past the boards' reach by the order rule (module docstring), or None
    when it does not apply: no image circle or pattern size, a model other than equidistant, fewer than
    :data:`MIN_VIEWS` views, a rim within :data:`BEYOND_DEG` of the boards' reach, or no order fitted.

    cal : a Calibration (its image_circle and pattern_size: without one, None) and ``lens`` its lens;
    views : its used views.
    Returns {"circle_fov_deg": the chosen order's figure, "circle_fov_terms": its number of terms,
    "circle_fov_model_deg": the calibration's own figure, "circle_fov_orders": [{"terms", "cv_rms",
    "cv_se", "fov_deg"}]}."""
    circle, pattern_size = getattr(cal, "image_circle", None), getattr(cal, "pattern_size", None)
    if circle is None or pattern_size is None or lens.model != MODEL or len(views) < MIN_VIEWS:
        return None
    own = circle_fov_deg(lens, circle)
    reach = boards_reach_deg(lens, np.concatenate([v.corners for v in views]))
    if not own > 2.0 * (reach + BEYOND_DEG):
        return None
    rows = order_rows(views, lens, circle, pattern_size)
    chosen = fewest_terms(rows)
    if chosen is None:
        return None
    return {"circle_fov_deg": chosen["fov_deg"], "circle_fov_terms": chosen["terms"], "circle_fov_model_deg": own,
            "circle_fov_orders": [{k: r[k] for k in ("terms", "cv_rms", "cv_se", "fov_deg")} for r in rows]}
