"""Does a solved board flex earn its two parameters on held-out views?

A flex whose σ is small (:func:`~aicalib_tf.calib.flex.flex_problem`) can still be the lens model's
misfit: on OpenCV's 13 left-camera photos the two first/second halves each found a flex within
σ = 0.001 squares of its own, 8σ apart from the other's, and their projections drifted 1.1 px apart
where the flat fits agree to 0.27 px. So the flex is kept only when it predicts views it was not
fitted to: k = min(5, V) folds as in :mod:`aicalib_tf.calib.select` (view i in fold i mod k); each
fold's other views are fitted with the flex and with a flat board, each held-out view's pose is solved
with those intrinsics (and that flex applied to its board points), and the fold's score is the RMS
over its held-out corners. The flex stays when the mean gain (flat − flexed) exceeds its standard
error over the folds (the one-SE rule of the model choice); with fewer than
:data:`~aicalib_tf.calib.select.MIN_CV_VIEWS` views the σ rule alone decides. A flex that passes must
also move the projection beyond the flat fit's own noise (:mod:`aicalib_tf.calib.flex_shift`), when the
image size is given.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from aicalib_tf.calib.bundle import CalibrationError
from aicalib_tf.calib.flex_shift import shift_note
from aicalib_tf.calib.select import MAX_FOLDS, MIN_CV_VIEWS, held_out_rms

__all__ = ["held_out_gain", "flex_earned", "confirm_flex", "solve_fields"]


def held_out_gain(views, fit, pattern_size, square_size: float = 1.0) -> np.ndarray:
    """(k,) px: each fold's held-out RMS with a flat board minus with the flex (positive: the flex helps).

    views : list of View; fit(views, flex) -> BundleResult with flex "auto" or "off" (its board points
    in ``square_size`` per square). Raises CalibrationError when a fold cannot be fitted or posed.
    """
    k = min(MAX_FOLDS, len(views))
    gains = []
    for f in range(k):
        train = [v for i, v in enumerate(views) if i % k != f]
        held = [v for i, v in enumerate(views) if i % k == f]
        flexed, flat = fit(train, "auto"), fit(train, "off")
        score = [held_out_rms(r, held, square_size, pattern_size) for r in (flat, flexed)]
        gains.append(score[0] - score[1])
    return np.array(gains)


def flex_earned(views, fit, pattern_size, square_size: float = 1.0) -> tuple[bool, str]:
    """(keep the flex, why not when not): the held-out rule of the module docstring."""
    if len(views) < MIN_CV_VIEWS:
        return True, ""
    try:
        g = held_out_gain(views, fit, pattern_size, square_size)
    except CalibrationError as exc:
        return False, f"not used: the held-out check failed ({exc})"
    se = float(g.std(ddof=1) / np.sqrt(len(g)))
    if g.mean() > se:
        return True, ""
    return False, (f"not used: no gain on held-out views ({1000 * g.mean():+.1f} ± {1000 * se:.1f} mpx over "
                   f"{len(g)} folds; the board is taken as flat)")


def confirm_flex(fit, views, refit, pattern_size, image_size=None):
    """``fit`` when it has no flex or held-out views confirm its flex (:func:`flex_earned`) and, given the
    image size (w, h) px and enough views for the held-out check, its flex moves the projection beyond the
    flat fit's noise (:func:`aicalib_tf.calib.flex_shift.shift_note`); else the views refitted flat, its
    ``flex_note`` saying why. refit(views, "auto" | "off") -> BundleResult (unit square)."""
    if getattr(fit, "flex", None) is None:
        return fit
    keep, why = flex_earned(views, refit, pattern_size)
    if keep and (image_size is None or len(views) < MIN_CV_VIEWS):
        return fit
    flat = refit(views, "off")
    if keep:
        why = shift_note(flat, fit, views, image_size)
        if not why:
            return fit
    return dataclasses.replace(flat, flex_note=why)


def solve_fields(fit, views) -> dict:
    """The Calibration fields of a solve's flex (fit with a unit square) and rejected corners:
    {"flex_note", "rejected_corners" ({view name: (K, 2) ids}), and "flex", "flex_covariance" when solved}."""
    flex, inliers = getattr(fit, "flex", None), getattr(fit, "inliers", None)
    out = {"flex_note": getattr(fit, "flex_note", ""), "rejected_corners": {}}
    if flex is not None:
        out.update(flex=np.asarray(flex, np.float64).copy(), flex_covariance=np.asarray(fit.flex_covariance, np.float64))
    if inliers is not None:
        for v, keep in zip(views, np.split(np.asarray(inliers, bool), np.cumsum([len(v.ids) for v in views])[:-1])):
            if not keep.all():
                out["rejected_corners"][v.name] = v.ids[~keep].copy()
    return out
