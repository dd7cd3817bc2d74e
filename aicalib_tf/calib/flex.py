"""The board's flex in a calibration: when it is solved, when it is kept, and how it is reported.

The flex is the two-parameter parabolic sag of :mod:`aicalib_tf.geometry.board_flex` (mrcal's
``calobject_warp``): a board point (c, r) moves along the board's z axis by
w_x·(1 − u²) + w_y·(1 − v²), u and v its place across the inner-corner grid scaled to [−1, 1].
One flex is shared by every view (one physical board); the bundle solves (w_x, w_y) with the camera
(:mod:`aicalib_tf.calib.bundle`). Here w is in squares; ``sag`` is the centre's offset against the
corners of the grid, w_x + w_y, reported in squares and in the board's unit.

Modes (:data:`FLEX_MODES`): ``flex="sag"`` solves this flex; ``"shape"`` the board's shape of
:mod:`aicalib_tf.calib.board_shape`, whose first two terms are this flex; ``"auto"`` (the calibrate
command's default, :data:`FLEX_DEFAULT`) the shape when the views afford it, else a flat board (the rule
and its measurements there); ``"off"`` takes the board as flat.

Rule (``flex="sag"``): the flex is solved, and used when the views determine it: both standard
deviations at most :data:`FLEX_SIGMA_MAX` squares (a quarter of :data:`FLEX_TYPICAL`, the sag of a
printed board on a rigid backing that a flex must resolve: mrcal measures about 0.014 squares on a
GoPro set) and |w| within :data:`FLEX_PLAUSIBLE`; then its sag is moved towards 0 by part of the noise
of its own estimate, measured by leaving each view out, and the camera refitted with the board held
there (:mod:`aicalib_tf.calib.flex_check`). Otherwise, or when nothing of the sag is left, the board is
taken as flat and refitted, and the note says why. Views whose ids are relative (a board larger than the frame) do not know where
their corners lie on the board, so a set holding one is fitted flat.
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.calib import board_shape
from aicalib_tf.calib.board_shape import (AUTO_MODE, N_SHAPE_TERMS, SHAPE_MODE, SHAPE_MODES, SHAPE_PLAUSIBLE,
                                         shape_fields, shape_text)
from aicalib_tf.geometry.board_shape import shape_basis

__all__ = ["FLEX_SIGMA_MAX", "FLEX_TYPICAL", "FLEX_PLAUSIBLE", "FLEX_MODES", "FLEX_DEFAULT", "SAG_MODE", "basis_of_views",
           "mode_terms", "flex_problem", "flex_line", "flex_dict"]

FLEX_TYPICAL = 0.02  # squares: the sag a flex must resolve (the benchmark's largest)
FLEX_SIGMA_MAX = FLEX_TYPICAL / 4  # squares: the largest σ of a kept flex
FLEX_PLAUSIBLE = SHAPE_PLAUSIBLE  # squares: beyond this a "flex" is the lens model's misfit, not the board's
SAG_MODE = "sag"  # the two-term flex alone
FLEX_MODES = (AUTO_MODE, "off", SAG_MODE, SHAPE_MODE)  # the board's shape (calib.board_shape): auto tests it first
FLEX_DEFAULT = AUTO_MODE  # the calibrate command's (photos of one camera; videos and rigs take the board flat)


def basis_of_views(views, pattern_size, n_terms: int = 2) -> tuple[list | None, str]:
    """(list of V (N_v, n_terms) :func:`~aicalib_tf.geometry.board_shape.shape_basis` rows (2: the flex's
    :func:`~aicalib_tf.geometry.board_flex.flex_basis`), "") for views with absolute ids, or (None, why) when
    the flex cannot be solved for these views."""
    relative = sum(1 for v in views if getattr(v, "relative", False))
    if relative:
        return None, f"not solved: {relative} view{'s' if relative != 1 else ''} with ids relative to what is seen"
    if pattern_size is None:
        return None, "not solved: no pattern size"
    return [shape_basis(v.ids[:, 0], v.ids[:, 1], pattern_size, n_terms) for v in views], ""


def mode_terms(mode: str) -> int:
    """How many shape terms a flex mode solves: 2 (the sag) for "sag",
    :data:`~aicalib_tf.calib.board_shape.N_SHAPE_TERMS` for "auto" and "shape"."""
    return board_shape.N_SHAPE_TERMS if mode in SHAPE_MODES else 2


def flex_problem(flex, covariance, unit: float = 1.0) -> str:
    """Why a solved flex is not kept ("" when it is): (2,) flex and (2, 2) covariance in board units of
    ``unit`` per square (the unit the bundle's board points were in)."""
    if flex is None or covariance is None:
        return "not determined by these views"
    w = np.asarray(flex, np.float64) / unit
    sd = np.sqrt(np.maximum(np.diag(np.asarray(covariance, np.float64)), 0.0)) / unit
    if not np.all(np.isfinite(w)) or not np.all(np.isfinite(sd)):
        return "not determined by these views"
    if sd.max() > FLEX_SIGMA_MAX:
        return f"not determined by these views (σ {sd.max():.3f} squares > {FLEX_SIGMA_MAX:.3f})"
    if np.abs(w).max() > FLEX_PLAUSIBLE:
        return (f"not used: the fit asks {np.abs(w).max():.3f} squares, beyond a board's plausible "
                f"{FLEX_PLAUSIBLE} (the lens model's misfit, not the board's)")
    return ""


def _sag(flex, std) -> tuple[float, float]:
    """(sag, σ) squares of the centre against the grid's corners: w_x + w_y (σ from the diagonal and
    the covariance's off-diagonal term when ``std`` is a (2, 2) covariance)."""
    w = np.asarray(flex, np.float64)
    c = np.asarray(std, np.float64)
    var = float(c[0, 0] + c[1, 1] + 2 * c[0, 1]) if c.ndim == 2 else float(np.sum(c * c))
    return float(w.sum()), float(np.sqrt(max(var, 0.0)))


def flex_line(cal) -> str | None:
    """The report's line on the board flex, or None when the calibration did not consider one."""
    flex = getattr(cal, "flex", None)
    note = getattr(cal, "flex_note", "")
    if flex is None:
        return f"board flex: {note}" if note else None
    if len(flex) > 2:
        text = shape_text(flex, cal.flex_covariance, cal.pattern_size, float(cal.square_size), cal.square_unit)
        return f"board flex: shape {text}" + (f"; {note}" if note else "")
    sag, sd = _sag(flex, cal.flex_covariance)
    s, unit = float(cal.square_size), cal.square_unit
    wx, wy = (float(v) for v in flex)
    in_unit = f"{sag * s:.3g} ± {sd * s:.2g} {unit} (" if unit else ""
    return (f"board flex: sag {in_unit}{sag:.4f} ± {sd:.4f} squares{')' if unit else ''}, "
            f"along x {wx:+.4f}, along y {wy:+.4f} squares")


def flex_dict(cal) -> dict | None:
    """camera.json's ``board_flex``: {"wx", "wy" (squares), "covariance" (2×2 squares²), "sag", "sag_std"
    (squares), "sag_unit" (the board's unit: square size × squares), "note"}, or None when not considered; a
    board shape (``flex="shape"``) adds :func:`~aicalib_tf.calib.board_shape.shape_fields` (its first two terms
    are wx and wy)."""
    flex = getattr(cal, "flex", None)
    note = getattr(cal, "flex_note", "")
    if flex is None:
        return {"wx": None, "wy": None, "note": note} if note else None
    cov = np.asarray(cal.flex_covariance, np.float64)
    sag, sd = _sag(flex[:2], cov[:2, :2])
    extra = shape_fields(flex, cov, cal.pattern_size, float(cal.square_size)) if len(flex) > 2 else {}
    return {"wx": float(flex[0]), "wy": float(flex[1]),
            "covariance": cov[:2, :2].tolist(), "sag": sag, "sag_std": sd,
            "sag_unit": sag * float(cal.square_size), "sag_std_unit": sd * float(cal.square_size),
            "unit": cal.square_unit, "note": note, **extra}


def solve_fields_from_dict(d: dict) -> dict:
    """The Calibration fields :func:`flex_dict` and ``rejected_corners`` wrote into camera.json (absent in
    older files: a flat board, no corner rejected); every field checked (:mod:`aicalib_tf.calib.schema`)."""
    from aicalib_tf.calib import schema as S

    out: dict = {}
    flex = S.require_mapping(d, "board_flex", {}) if d.get("board_flex") is not None else {}
    with S.within("board_flex"):
        out["flex_note"] = S.require_str(flex, "note", "")
        if flex.get("shape") is not None:  # a board shape: its K terms
            out["flex"] = S.require_vector(flex, "shape")
            n = len(out["flex"])
            if not 2 < n <= N_SHAPE_TERMS:
                raise S.FieldError("shape", f"must hold 3 to {N_SHAPE_TERMS} numbers, got {n}")
            out["flex_covariance"] = S.require_matrix(flex, "shape_covariance", (n, n))
        elif flex.get("wx") is not None or flex.get("wy") is not None:
            out["flex"] = np.array([S.require_number(flex, "wx"), S.require_number(flex, "wy")])
            out["flex_covariance"] = S.require_matrix(flex, "covariance", (2, 2))
    corners = S.require_mapping(d, "rejected_corners", {}) if d.get("rejected_corners") is not None else {}
    with S.within("rejected_corners"):
        out["rejected_corners"] = {str(k): S.require_matrix(corners, k, (-1, 2)).astype(np.int64) for k in corners}
    return out


def rejected_corners_dict(cal) -> dict:
    """camera.json's ``rejected_corners``: {view name: [[col, row], ...]} of single corners the solve rejected."""
    return {k: np.asarray(v, np.int64).reshape(-1, 2).tolist() for k, v in getattr(cal, "rejected_corners", {}).items()}
