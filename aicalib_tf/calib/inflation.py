"""How much larger the intrinsics' uncertainty is than the fit's formal covariance says: the views as clusters.

A calibration's covariance σ̂²·(JᵀWJ)⁻¹ (``cal.covariance``) counts every corner as an independent
measurement. Real corners carry errors shared within a view (blur, lighting, the board's shape, the
lens model's misfit): such a view holds fewer independent measurements than corners, and the formal
covariance is too small. The views are the independent units, so the covariance of the intrinsics
is estimated from the scatter of the views' own contributions (the cluster-robust "sandwich"):

    Σ_views = S⁻¹ · (Σ_v g̃_v g̃_vᵀ) · S⁻¹,

with each view's pose eliminated (its 6 columns projected out of the view's intrinsics Jacobian J_v),
S = Σ_v J_vᵀJ_v and g̃_v = J_vᵀ(I − P_vv)^(−1/2) r_v, r_v the view's residuals and P_vv = J_v S⁻¹ J_vᵀ
its leverage: the fit has pulled the intrinsics towards each view, so its residuals are smaller than
its errors, and the leverage correction (Bell and McCaffrey's CR2) makes Σ_views unbiased when the
corners' errors are independent after all. :func:`view_inflation` is κ, the ratio of the two
covariances' projection variance summed over the covered grid cells (rotation-compensated, as
:func:`aicalib_tf.calib.quality.projection_uncertainty` projects them), never below 1: the formal
covariance is the floor (the corners' own noise), and κ scales it.

Unweighted in both covariances (a ratio: the corners' weights cancel to first order). Pure numpy/OpenCV.
"""

from __future__ import annotations

import cv2
import numpy as np

from aicalib_tf.geometry import lens as L
from aicalib_tf.geometry.board_shape import shaped_points
from aicalib_tf.geometry.pattern import board_points

__all__ = ["view_terms", "view_inflation", "MIN_VIEWS", "MAX_LEVERAGE"]

MIN_VIEWS = 4  # fewer views: no scatter between them to speak of (κ = 1)
MAX_LEVERAGE = 0.95  # a view's leverage eigenvalues are capped here (a view that alone fixes a direction)


def _kept_points(cal, view) -> tuple[np.ndarray, np.ndarray]:
    """(board points (K, 3) in the unit of ``cal.tvecs``, corners (K, 2) px) of ``view``'s corners the solve
    kept (``cal.rejected_corners`` left out), on the board as the fit solved it (``cal.flex``)."""
    keep = np.ones(len(view.ids), bool)
    rejected = (getattr(cal, "rejected_corners", None) or {}).get(view.name)
    if rejected is not None and len(rejected):
        keep &= ~np.any(np.all(view.ids[:, None, :] == np.asarray(rejected)[None], axis=2), axis=1)
    obj = board_points(view.ids[keep], cal.square_size)
    flex = getattr(cal, "flex", None)
    if flex is not None:
        obj = shaped_points(obj, cal.pattern_size, np.asarray(flex, np.float64), cal.square_size)
    return obj, np.asarray(view.corners, np.float64)[keep]


def view_terms(cal, views, lens: L.Lens, frame_basis) -> tuple[list[np.ndarray], list[np.ndarray], float]:
    """(J_v list of (2K_v, n), r_v list of (2K_v,), σ̂² px²): each used view's intrinsics Jacobian and
    residuals with its pose's 6 directions projected out, and the residual variance over the
    degrees of freedom (2N − n − 6V).

    views : View objects holding the used ones (matched by name to ``cal.views``; a used view not among
    them is left out); frame_basis : :func:`aicalib_tf.calib.quality._frame_basis` (points, distance 1:
    the pose's rotation and translation)."""
    by_name = {v.name: v for v in views}
    n = 4 + lens.dist.size
    Js, rs, sq, rows = [], [], 0.0, 0
    for name, rvec, tvec in zip(cal.views, cal.rvecs, cal.tvecs):
        if name not in by_name:
            continue
        obj, px = _kept_points(cal, by_name[name])
        P = obj @ cv2.Rodrigues(np.asarray(rvec, np.float64))[0].T + np.asarray(tvec, np.float64).ravel()
        uv = lens.project(P)
        ok = np.all(np.isfinite(uv), axis=1)
        if ok.sum() < 4:
            continue
        Ji, A = frame_basis(lens, P[ok], 1.0)
        q = np.linalg.qr(A.reshape(-1, 6))[0]
        J, r = Ji.reshape(-1, n), (px[ok] - uv[ok]).ravel()
        Js.append(J - q @ (q.T @ J))
        rs.append(r - q @ (q.T @ r))
        sq, rows = sq + float(rs[-1] @ rs[-1]), rows + len(r)
    return Js, rs, sq / max(rows - n - 6 * len(Js), 1)


def _sandwich(Js, rs) -> tuple[np.ndarray, np.ndarray]:
    """(S⁻¹ (n, n), the views' CR2 covariance (n, n), module docstring)."""
    Sinv = np.linalg.pinv(sum(J.T @ J for J in Js))
    meat = np.zeros_like(Sinv)
    for J, r in zip(Js, rs):
        Q, R = np.linalg.qr(J)
        lam, W = np.linalg.eigh(R @ Sinv @ R.T)  # the leverage P_vv = Q·(R S⁻¹ Rᵀ)·Qᵀ in its own basis
        U = Q @ W
        shrink = 1.0 / np.sqrt(1.0 - np.clip(lam, 0.0, MAX_LEVERAGE)) - 1.0
        g = J.T @ (r + U @ (shrink * (U.T @ r)))
        meat += np.outer(g, g)
    return Sinv, Sinv @ meat @ Sinv


def view_inflation(cal, views, lens: L.Lens, G: np.ndarray, frame_basis) -> float:
    """κ >= 1: the views-as-clusters covariance of the intrinsics over the formal one, as the ratio of
    the projection variance they give summed over the pixels of ``G`` (M, 2, n) (the rotation-compensated
    Jacobian of the covered cells); 1 with fewer than :data:`MIN_VIEWS` views or when it cannot be had.
    cal : a Calibration (its views' poses, square size, flex, rejected corners) and ``lens`` its lens;
    views : holding its used views; frame_basis : as in :func:`view_terms`."""
    if len(cal.views) < MIN_VIEWS or not len(G):
        return 1.0
    try:
        Js, rs, s2 = view_terms(cal, views, lens, frame_basis)
        if len(Js) < MIN_VIEWS or not s2 > 0:
            return 1.0
        Sinv, robust = _sandwich(Js, rs)
        Gz = np.nan_to_num(G)
        ratio = float(np.einsum("mij,jk,mik->", Gz, robust, Gz) / (s2 * np.einsum("mij,jk,mik->", Gz, Sinv, Gz)))
    except np.linalg.LinAlgError:
        return 1.0
    return max(1.0, ratio) if np.isfinite(ratio) else 1.0
