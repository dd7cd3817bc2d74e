"""The board's shape in a calibration (``flex="auto"``): solved with the camera, each term shrunk by its noise.

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

Measured (random half-splits of each real set, ``benchmarks/real_split_noise.py``; geometric mean of
the halves' projection difference, 90% interval over the splits): against the sag alone
(``flex="sag"``) 1.04 (0.97-1.12) on OpenCV's left photos (150 splits), 0.80 (0.69-0.92) on the bent
udacity board (48) and, held out while the rule was chosen, 0.85 (0.83-0.88) on the 185° fisheye (96);
against a flat board 1.43 (1.25-1.63), 0.32 (0.25-0.40) and 1.00 (0.92-1.07, 96 splits). So
``flex="auto"`` solves the shape, and a flat board stays the default: halves of 6-8 views of a nearly
flat board cannot tell its shape from noise. Tried on the first two sets (48 splits) and not kept: three
terms (the sags and the twist) 1.25 × flat on OpenCV's photos against 1.19 for seven; terms kept only
beyond 1 SE 1.16; a gate that takes the board flat unless the shape predicts views left out better 1.28.
Synthetic views (``benchmarks/board_shape.py``): a twisted, S-bent board's terms within 1.3 SE of the
truth, fx bias below 0.3 σ_fx.
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.geometry.board_shape import SHAPE_TERMS, out_of_plane_rms

__all__ = ["SHAPE_MODE", "SHAPE_MODES", "N_SHAPE_TERMS", "SHAPE_PLAUSIBLE", "SHAPE_SHRINK_FROM", "shape_problem",
           "leave_one_out_shapes", "shape_fields", "shape_text"]

SHAPE_MODE = "shape"  # the flex mode that solves the shape; "auto" is the same
SHAPE_MODES = ("auto", SHAPE_MODE)
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


def leave_one_out_shapes(views, refit) -> np.ndarray:
    """(V, K) squares: the shape of refit(views less view i, "shape") for each view i (0 where that refit
    keeps none). refit(views, mode) -> BundleResult with a unit square; CalibrationError propagates."""
    fits = [refit(views[:i] + views[i + 1:], SHAPE_MODE) for i in range(len(views))]
    out = [None if f.flex is None else np.asarray(f.flex, np.float64) for f in fits]
    k = max((len(s) for s in out if s is not None), default=0)
    return np.array([np.zeros(k) if s is None else s for s in out]).reshape(len(views), k)



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
