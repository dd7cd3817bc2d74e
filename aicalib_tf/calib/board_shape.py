"""The board's shape in a calibration (``flex="shape"``, and ``"auto"`` where the views afford it).

A printed sheet on a backing is rarely flat in the parabolic way of the flex alone: it twists, bends in
an S, or sags more at one edge. The shape is the polynomial z(u, v) of
:mod:`aicalib_tf.geometry.board_shape` (:data:`~aicalib_tf.geometry.board_shape.SHAPE_TERMS`: the
flex's two sags, the twist uv, the cubics P₃(u) and P₃(v), and the sags that grow across the board),
one shape shared by every view, its :data:`N_SHAPE_TERMS` coefficients solved with the camera by the
bundle (:mod:`aicalib_tf.calib.bundle`, beside the intrinsics, as the flex is).

Rule. The solve keeps the shape when every coefficient is finite and within
:data:`SHAPE_PLAUSIBLE` squares (else the board is flat and the note says why).
Then each coefficient w_k is shrunk towards 0 (:func:`aicalib_tf.calib.flex_check.confirm_shape`) by the rule
the flex's sag follows: its standard error SE_k = max(σ_k, σ_J,k) (the fit's own σ, and the jackknife's from
refitting the shape with each view left out), nothing of it kept up to t = |w_k| / SE_k =
:data:`SHAPE_SHRINK_FROM`, all from t = 4,
linear in between. A term the views cannot determine is 0; with every term 0 the board is taken as
flat and the note says so; otherwise the camera is refitted with the board held at the shrunk shape
(the intrinsics' covariance is the solved fit's, the shape's uncertainty included), and the shape's
covariance is the fit's scaled to the SE's. Reported: the coefficients with their SE, the sag
(w_x + w_y, as for the flex) and the RMS out of the board's best plane over the corners, with σ.

Whether the views afford a shape (``flex="auto"``, the calibrate command's default). A shape can be real and
still cost: halves of 6-7 of OpenCV's left photos find its sag along y at t ≈ 4 (the board does sag), yet
agree 1.26 times worse than flat with only the terms beyond a Bonferroni Student-t cut kept, 1.42 with all,
because the terms trade against the lens's own parameters while the flat board's error, shared by the two
halves of one board, does not show. What matters is how far the shape moves the lens against the noise it
brings: :func:`~aicalib_tf.calib.flex_check.lens_shift` measures the move of the projection over the boards
(shaped fit against flat, rotation fitted) and the jackknife SE of the shaped lens from the
leave-one-view-out fits the terms' SE already need. With z = shift / SE and c = t₀.₉₀(V − 1)
(:func:`~aicalib_tf.calib.flex_check.afford_cut`: Student's t, one-sided 90%, with the jackknife's V − 1
degrees of freedom: 1.48 for 6 views, 1.33 for 20) none of the shape is used up to z = c, all of it from
2c, linearly between (:func:`~aicalib_tf.calib.flex_check.afford_part`); the note gives the shift, z and
the two bounds. Chosen on synthetic views and OpenCV's left photos, with udacity's bent board and the 185°
fisheye held out: over 81 random half-splits of OpenCV's photos z has median 0.40 (90th percentile
1.02); all of the shape from z > 1 costs 1.09 × flat, from z > c 1.02, the ramp from c to 2c 0.99
(0.96-1.01); synthetic flat boards (6-20 views, 0.2 px) stay below z = 0.9 and never keep a shape, while
boards bent by 0.006-0.015 squares keep it in 25-100% of the sequences, their lens error to the truth
0.2-0.5 × flat's. The step at c alone (no ramp) cost the held-out fisheye 1.03 (1.01-1.06) × flat over
51 splits, every bit of it in the 4 splits where one half kept a shape and the other did not: the
ramp, the firm shrinkage each term already follows, keeps two halves either side of c close. Each view's
refit costs what ``"shape"``'s do, plus one flat refit. Measured on the real sets: docs/benchmark.md.
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.geometry.board_shape import SHAPE_TERMS, out_of_plane_rms

__all__ = ["AUTO_MODE", "SHAPE_MODE", "SHAPE_MODES", "N_SHAPE_TERMS", "SHAPE_PLAUSIBLE", "SHAPE_SHRINK_FROM",
           "shape_problem", "leave_one_out_fits", "loo_shapes", "leave_one_out_shapes", "shape_fields", "shape_text"]

SHAPE_MODE = "shape"  # the flex mode that solves the shape and keeps each term shrunk by its noise
AUTO_MODE = "auto"  # the same, kept only when it moves the lens by more than its noise (flex_check.afford_shape)
SHAPE_MODES = (AUTO_MODE, SHAPE_MODE)
N_SHAPE_TERMS = len(SHAPE_TERMS)
SHAPE_PLAUSIBLE = 0.25  # squares: a term beyond this is the lens model's misfit, not the board's (the flex's too)
SHAPE_SHRINK_FROM = 0.5  # t = |w_k| / SE_k up to which a term is 0 (the sag's too: flex_check.SHRINK_FROM)


def shape_problem(shape, covariance, unit: float = 1.0) -> str:
    """Why a solved shape is not kept ("" when it is): (K,) shape and (K, K) covariance in board units of
    ``unit`` per square."""
    if shape is None or covariance is None:
        return "not determined by these views"
    w = np.asarray(shape, np.float64) / unit
    if not np.all(np.isfinite(w)) or not np.all(np.isfinite(covariance)):
        return "not determined by these views"
    if np.abs(w).max() > SHAPE_PLAUSIBLE:
        k = int(np.argmax(np.abs(w)))
        return (f"not used: the fit asks {w[k]:+.3f} squares of {SHAPE_TERMS[k]}, beyond a board's plausible "
                f"{SHAPE_PLAUSIBLE} (the lens model's misfit, not the board's)")
    return ""


def leave_one_out_fits(views, refit) -> list:
    """The V fits refit(views less view i, "shape"), one for each view i. refit(views, mode) -> BundleResult
    with a unit square; CalibrationError propagates."""
    return [refit(views[:i] + views[i + 1:], SHAPE_MODE) for i in range(len(views))]


def loo_shapes(fits) -> np.ndarray:
    """(V, K) squares: the shapes of V leave-one-out fits (0 where a fit keeps none)."""
    out = [None if f.flex is None else np.asarray(f.flex, np.float64) for f in fits]
    k = max((len(s) for s in out if s is not None), default=0)
    return np.array([np.zeros(k) if s is None else s for s in out]).reshape(len(fits), k)


def leave_one_out_shapes(views, refit) -> np.ndarray:
    """(V, K) squares: the shape of refit(views less view i, "shape") for each view i (0 where that refit
    keeps none). refit(views, mode) -> BundleResult with a unit square; CalibrationError propagates."""
    return loo_shapes(leave_one_out_fits(views, refit))


def shape_fields(shape, covariance, pattern_size, square_size: float) -> dict:
    """camera.json's shape fields of ``board_flex`` (:func:`~aicalib_tf.calib.flex.flex_dict`): {"shape_terms",
    "shape" (K,) squares, "shape_covariance" (K, K) squares², "out_of_plane_rms", "out_of_plane_rms_std" (squares)
    and the same two in the board's unit ("…_unit")}."""
    w = np.asarray(shape, np.float64)
    c = np.asarray(covariance, np.float64)
    rms, sd = out_of_plane_rms(w, c, pattern_size)
    s = float(square_size)
    return {"shape_terms": list(SHAPE_TERMS[:len(w)]), "shape": w.tolist(), "shape_covariance": c.tolist(),
            "out_of_plane_rms": rms, "out_of_plane_rms_std": sd, "out_of_plane_rms_unit": rms * s,
            "out_of_plane_rms_std_unit": sd * s}


def shape_text(shape, covariance, pattern_size, square_size: float, unit: str) -> str:
    """The report's words on a shape: its RMS out of plane ± σ (squares, and the board's unit when known) and
    each nonzero term ± its σ."""
    w = np.asarray(shape, np.float64)
    sd = np.sqrt(np.maximum(np.diag(np.asarray(covariance, np.float64)), 0.0))
    rms, rsd = out_of_plane_rms(w, covariance, pattern_size)
    in_unit = f"{rms * square_size:.3g} ± {rsd * square_size:.2g} {unit}, " if unit else ""
    terms = ", ".join(f"{SHAPE_TERMS[k]} {w[k]:+.4f} ± {sd[k]:.4f}" for k in range(len(w)) if w[k] != 0.0)
    return f"out of plane RMS {in_unit}{rms:.4f} ± {rsd:.4f} squares; terms (squares) {terms}"
