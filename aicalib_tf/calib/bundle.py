"""One least-squares fit over all views, for any lens model of :mod:`aicalib_tf.geometry.lens`.

Parameters: the intrinsics [fx, fy, cx, cy, *dist] (px, and the model's coefficients) followed by
6 per view (rvec, tvec: board-to-camera, tvec in the unit of the board points). Residuals are
projected − detected, px, two per corner. The Jacobian is analytic
(:func:`~aicalib_tf.geometry.lens.projection_jacobian` chained with ``cv2.Rodrigues``' Jacobian)
and block-sparse: a view's pose only touches that view's rows. Levenberg–Marquardt with Marquardt's
diagonal scaling solves the normal equations with the poses eliminated (Schur complement: 6×6
blocks per view, then a (4 + n)² system), so a step costs O(V). Measured on 40 views × 54 corners;
``scipy.optimize.least_squares`` needed 9,000 evaluations with its sparse (lsmr) trust region and
6 s per step with its dense SVD one on this CPU.

A model with a regularization (``LensModel.prior``: the spline's smoothness) adds its residuals,
which depend on the coefficients alone, to the cost and to the intrinsics' block of the normal equations.

A corner that the current parameters cannot project (behind a pinhole camera, or beyond the
model's monotonic range) gets a constant residual of ``_PENALTY`` px and a zero Jacobian row, so
the solver moves away from such parameters; a final fit with any such corner is an error. A step
that takes a coefficient outside the model's valid range (Double Sphere ξ ∈ (−1, 1], α ∈ [0, 1];
EUCM α ∈ [0, 1], β > 0) cannot be evaluated and is refused the same way, so the search never
leaves the range; a fit that ends on its edge (within ``RANGE_EDGE_REL`` of
:mod:`~aicalib_tf.geometry.lens_model`) stopped there because the views ask for a value beyond it,
and is an error naming the coefficient (``auto`` then moves on to the next model), as is a start
outside the range.

Weights (:mod:`~aicalib_tf.calib.weights`): residuals and Jacobian rows are multiplied by σ_ref/σ per
corner, 0 for rejected corners (not in the RMS or the degrees of freedom); the covariance σ̂²·(JᵀWJ)⁻¹
depends only on the σ's ratios. Board flex: with ``flex_basis`` two global parameters (w_x, w_y) of
:mod:`~aicalib_tf.geometry.board_flex` (or the K of a board shape, :mod:`~aicalib_tf.geometry.board_shape`)
follow the free intrinsics (z offset w·basis along the board's
z axis; Jacobian: the projection's along the rotated z axis times the basis), in the Schur complement.

Starts: :mod:`aicalib_tf.calib.starts` gives the intrinsics; :func:`~aicalib_tf.calib.poses.poses_from_rays`
gives every view's pose from a lens guess, which works for boards past 90° off-axis.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from aicalib_tf.calib.lm import SchurProblem, levenberg_marquardt, reduce_blocks, schur_complement
from aicalib_tf.calib.poses import poses_from_rays
from aicalib_tf.calib.weights import corner_weights
from aicalib_tf.geometry.lens import COEFF_NAMES, N_COEFFS, Lens, check_model, get_model, projection_jacobian

__all__ = ["CalibrationError", "BundleResult", "bundle_adjust", "corner_weights", "levenberg_marquardt", "schur_complement", "reduce_blocks",
           "SchurProblem", "poses_from_rays", "solve_pose", "param_names"]

_PENALTY = 1e3  # px, the residual of a corner the parameters cannot project
MAX_EVALUATIONS = 200  # a bundle fit's residual evaluations; one that needs more has not converged
_RANK_TOL = 1e-13  # smallest eigenvalue / largest of the column-normalised JᵀJ for a determined fit


class CalibrationError(ValueError):
    """The views cannot give a calibration (too few usable views, a model that cannot be fitted, ...)."""


def param_names(model: str) -> tuple[str, ...]:
    """("fx", "fy", "cx", "cy", *coefficient names) of a lens model."""
    check_model(model, None)
    return ("fx", "fy", "cx", "cy") + COEFF_NAMES[model]


@dataclass(frozen=True)
class BundleResult:
    """A least-squares fit.

    model : lens model name. intrinsics : (4 + n,) [fx, fy, cx, cy, *dist]. rvecs, tvecs : (V, 3).
    residuals : list of V arrays (N_v, 2), projected − detected, px. rms : px over all corners;
    per_view_rms : (V,) px. covariance : (4 + n, 4 + n) intrinsics covariance σ²·[(JᵀJ)⁻¹] (rows and
    columns of fixed parameters are 0), or None when not asked for. jtj : (P, P) JᵀJ of the free
    parameters (free intrinsics first, then 6 per view), or None. sigma2 : residual variance, px².
    cost : ½ sum of squared residuals. nfev : function evaluations. note : why the covariance is a
    pseudo-inverse (rank-deficient fit), else "". flex : (2,) the board flex (w_x, w_y) (or (K,) a board
    shape's terms) in the unit of the board points, or None when not solved; flex_covariance : (K, K) its
    covariance, or None. inliers :
    (N,) bool over all corners in order (False: rejected, weight 0), or None when all count. flex_note :
    why a flex was not solved or kept (:mod:`aicalib_tf.calib.robust`), else "".
    """

    model: str
    intrinsics: np.ndarray
    rvecs: np.ndarray
    tvecs: np.ndarray
    residuals: list
    rms: float
    per_view_rms: np.ndarray
    covariance: np.ndarray | None
    jtj: np.ndarray | None
    sigma2: float
    cost: float
    nfev: int
    note: str = ""
    converged: bool = True
    flex: np.ndarray | None = None
    flex_covariance: np.ndarray | None = None
    inliers: np.ndarray | None = None
    flex_note: str = ""

    @property
    def lens(self) -> Lens:
        """The fitted intrinsics as a :class:`~aicalib_tf.geometry.lens.Lens` (image size (1, 1): unknown here)."""
        return Lens.from_intrinsics(self.model, self.intrinsics, (1, 1))


class _Problem(SchurProblem):
    """Residuals and the Jacobian's blocks of one bundle problem (cached per parameter vector)."""

    def __init__(self, model, obj, px, intr0, free, weights=None, flex_basis=None, flex0=None):
        self.model, self.ni = model, 4 + N_COEFFS[model]
        self.X = np.concatenate([np.asarray(o, np.float64).reshape(-1, 3) for o in obj])
        self.uv = np.concatenate([np.asarray(p, np.float64).reshape(-1, 2) for p in px])
        counts = [len(np.asarray(p).reshape(-1, 2)) for p in px]
        self.view_of = np.repeat(np.arange(len(px)), counts)
        self.splits = np.cumsum(counts)[:-1]
        self.V, self.N = len(px), len(self.uv)
        self.base = np.asarray(intr0, np.float64).copy()
        self.free = np.asarray(free, bool)
        self.w = None if weights is None else np.asarray(weights, np.float64).reshape(self.N)
        self.basis = None if flex_basis is None else np.concatenate(  # (N, K): K = 2 the flex, more a board shape
            [np.asarray(b, np.float64).reshape(len(np.asarray(p).reshape(-1, 2)), -1) for b, p in zip(flex_basis, px)])
        self.nflex = 0 if self.basis is None else self.basis.shape[1]
        self.flex0 = np.zeros(self.nflex) if flex0 is None else np.asarray(flex0, np.float64).reshape(self.nflex)
        self.nf = int(self.free.sum()) + self.nflex
        self.n_used = self.N if self.w is None else int(np.count_nonzero(self.w > 0))
        self._key, self._val = None, None
        self.shape = (2 * self.N, self.nf + 6 * self.V)  # (residuals, parameters)
        self.spec = get_model(model)
        self._prior_key, self._prior_val = None, None

    def _prior(self, x):
        """The model's regularization (LensModel.prior) at x: (r (M,), J (M, nf) on the free intrinsics), or None."""
        if self._prior_key is not None and np.array_equal(x, self._prior_key):
            return self._prior_val
        found = self.spec.prior(self.unpack(x)[0][4:])
        val = None
        if found is not None:
            J = np.zeros((found[1].shape[0], self.ni))
            J[:, 4:] = found[1]
            val = (found[0], np.pad(J[:, self.free], ((0, 0), (0, self.nflex))))  # no prior on the flex
        self._prior_key, self._prior_val = x.copy(), val
        return val

    def fun(self, x):
        r, p = self._evaluate(x)[0], self._prior(x)
        return r if p is None else np.concatenate([r, p[0]])

    def normal_blocks(self, x):
        U, W, Vb, gu, gv = super().normal_blocks(x)
        p = self._prior(x)
        if p is not None:  # residuals on the intrinsics alone: they add to U and gu only
            U, gu = U + p[1].T @ p[1], gu + p[1].T @ p[0]
        return U, W, Vb, gu, gv

    def unpack(self, x):
        intr = self.base.copy()
        intr[self.free] = x[: self.nf - self.nflex]
        poses = x[self.nf:].reshape(self.V, 6)
        return intr, poses[:, :3], poses[:, 3:]

    def flex_of(self, x):
        """(K,) the flex (or board shape) of parameter vector x, or None when not solved."""
        return None if self.nflex == 0 else x[self.nf - self.nflex: self.nf].copy()

    def _evaluate(self, x):
        if self._key is not None and np.array_equal(x, self._key):
            return self._val
        intr, rv, tv = self.unpack(x)
        R, dR = np.empty((self.V, 3, 3)), np.empty((self.V, 3, 3, 3))
        for v in range(self.V):
            Rv, jac = cv2.Rodrigues(rv[v])
            R[v], dR[v] = Rv, jac.reshape(3, 3, 3)  # dR[v][k] = dR / d rvec_k
        X = self.X
        if self.nflex:
            X = X.copy()
            X[:, 2] += self.basis @ self.flex_of(x)
        Xc = np.einsum("nij,nj->ni", R[self.view_of], X) + tv[self.view_of]
        try:
            K = np.array([[intr[0], 0, intr[2]], [0, intr[1], intr[3]], [0, 0, 1.0]])
            uv, Jp, Ji = projection_jacobian(Xc, self.model, K, intr[4:])
        except ValueError:  # e.g. a focal length <= 0 or a non-finite value mid-search
            uv = np.full((self.N, 2), np.nan)
            Jp, Ji = np.zeros((self.N, 2, 3)), np.zeros((self.N, 2, self.ni))
        bad = ~np.isfinite(uv).all(axis=1)
        self.px_residuals = uv - self.uv  # unweighted, px (NaN where unprojectable)
        res = np.where(bad[:, None], _PENALTY, self.px_residuals)
        dP_dr = np.einsum("nkij,nj->nik", dR[self.view_of], X)  # (N, 3, 3): d Xc / d rvec
        J_pose = np.concatenate([Jp @ dP_dr, Jp], axis=2)  # (N, 2, 6)
        J_glob = Ji[:, :, self.free]
        if self.nflex:  # d Xc / d w = R[:, 2] · basis
            dz = np.einsum("nij,nj->ni", Jp, R[self.view_of][:, :, 2])
            J_glob = np.concatenate([J_glob, dz[:, :, None] * self.basis[:, None, :]], axis=2)
        J_pose[bad], J_glob[bad] = 0.0, 0.0
        if self.w is not None:
            res, J_pose, J_glob = res * self.w[:, None], J_pose * self.w[:, None, None], J_glob * self.w[:, None, None]
            bad &= self.w > 0
        self._key, self._val = x.copy(), (res.ravel(), J_glob, J_pose, int(bad.sum()))
        return self._val


def _covariance(prob: _Problem, x, cost: float, model: str, strict: bool):
    """(intrinsics covariance (ni, ni), flex covariance (2, 2) or None, JᵀJ (P, P), σ², note).

    [(JᵀJ)⁻¹] restricted to the global parameters (free intrinsics, then the flex) is the inverse of
    the Schur complement S. A rank-deficient fit (column-normalised S or a pose block with eigenvalue
    ratio <= _RANK_TOL) raises CalibrationError when ``strict``, else the covariance uses the
    pseudo-inverse and ``note`` says so.
    """
    U, W, Vb, _, _ = prob.normal_blocks(x)
    dof = 2 * prob.n_used - prob.shape[1]
    if dof <= 0:
        raise CalibrationError(f"{model}: {prob.n_used} corners give {2 * prob.n_used} residuals for "
                               f"{prob.shape[1]} parameters")
    names = [n for n, f in zip(param_names(model), prob.free) if f] + (["flex_x", "flex_y"] if prob.nflex == 2
                                                                       else [f"shape_{k}" for k in range(prob.nflex)])
    dv = np.sqrt(np.einsum("vii->vi", Vb))
    wv = np.linalg.eigvalsh(Vb / (dv[:, :, None] * dv[:, None, :]))
    if not np.all(np.isfinite(Vb)) or np.any(~(wv[:, 0] > _RANK_TOL * wv[:, -1])):
        raise CalibrationError(f"{model}: a view's pose is not determined")
    S, _ = schur_complement(U, W, Vb)
    d = np.sqrt(np.maximum(np.diag(S), 0.0))
    sigma2, note = 2.0 * cost / dof, ""
    if np.any(~(d > 0)) or not np.all(np.isfinite(S)):
        dead = [names[i] for i in np.flatnonzero(~(d > 0))]
        raise CalibrationError(f"{model}: the views do not constrain {', '.join(dead) or 'the parameters'}")
    C = S / np.outer(d, d)
    w = np.linalg.eigvalsh(C)
    if w[0] <= _RANK_TOL * w[-1]:
        note = (f"{model}: rank-deficient fit (condition {w[-1] / max(w[0], 1e-300):.1e}); the views do not "
                "determine all its parameters")
        if strict:
            raise CalibrationError(note)
        inv = np.linalg.pinv(C, rcond=_RANK_TOL, hermitian=True)
    else:
        inv = np.linalg.inv(C)
    full = sigma2 * inv / np.outer(d, d)
    nfi = prob.nf - prob.nflex
    cov = np.zeros((prob.ni, prob.ni))
    idx = np.flatnonzero(prob.free)
    cov[np.ix_(idx, idx)] = full[:nfi, :nfi]
    flex_cov = full[nfi:, nfi:].copy() if prob.nflex else None
    nf, jtj = prob.nf, np.zeros((prob.shape[1], prob.shape[1]))
    jtj[:nf, :nf] = U
    for v in range(prob.V):
        sl = slice(nf + 6 * v, nf + 6 * v + 6)
        jtj[:nf, sl], jtj[sl, :nf], jtj[sl, sl] = W[v], W[v].T, Vb[v]
    return cov, flex_cov, jtj, sigma2, note


def bundle_adjust(model: str, obj, px, intrinsics, rvecs, tvecs, *, free=None, max_nfev: int | None = None,
                  covariance: bool = True, strict: bool = True, rank_strict: bool = True, sigmas=None,
                  inliers=None, flex_basis=None, flex=None) -> BundleResult:  # size: one entry, its checks and results
    """Fit a lens model and every view's pose to detected corners.

    model : a :data:`~aicalib_tf.geometry.lens.MODELS` name. obj : list of V (N_v, 3) board points
    (board frame, any unit). px : list of V (N_v, 2) detected corners, px. intrinsics : (4 + n,)
    start [fx, fy, cx, cy, *dist]; rvecs, tvecs : (V, 3) start poses. free : (4 + n,) bool, the
    intrinsics to fit (default all; False holds the start value). max_nfev : evaluation cap (None:
    to convergence). covariance : also return the covariance and JᵀJ. strict : raise
    :class:`CalibrationError` when the fit ends with non-finite values or unprojectable corners.
    rank_strict : raise on a rank-deficient fit (else the covariance is a pseudo-inverse and ``note`` says so).
    sigmas : list of V (N_v,) per-corner σ, px (> 0), or None (all equal). inliers : (N,) bool over all
    corners in order, or None (all); rejected corners get weight 0 and their residuals are still
    returned. flex_basis : list of V (N_v, K) :func:`~aicalib_tf.geometry.board_shape.shape_basis` rows
    (K = 2: the flex) to solve the board's shape (module docstring), or None; flex : its (K,) start (default 0).
    """
    if model in N_COEFFS:  # a known model whose start lies outside its valid range: no fit to make
        try:
            check_model(model, np.asarray(intrinsics, np.float64)[4:])
        except ValueError as exc:
            raise CalibrationError(f"{model}: the start is outside the model's valid range ({exc})") from exc
    check_model(model, np.asarray(intrinsics, np.float64)[4:])
    if len(obj) != len(px) or len(px) != len(rvecs) or len(px) != len(tvecs) or not px:
        raise ValueError(f"obj, px, rvecs and tvecs must list the same V >= 1 views, got {len(obj)}, {len(px)}, "
                         f"{len(rvecs)}, {len(tvecs)}")
    ni = 4 + N_COEFFS[model]
    free = np.ones(ni, bool) if free is None else np.asarray(free, bool)
    weights = corner_weights(sigmas, inliers, sum(len(np.asarray(p).reshape(-1, 2)) for p in px))
    prob = _Problem(model, obj, px, intrinsics, free, weights, flex_basis, flex)
    x0 = np.concatenate([np.asarray(intrinsics, np.float64)[free], prob.flex0[:prob.nflex],
                         np.hstack([np.asarray(rvecs, np.float64).reshape(-1, 3),
                                    np.asarray(tvecs, np.float64).reshape(-1, 3)]).ravel()])
    if not np.all(np.isfinite(x0)):
        raise CalibrationError(f"{model}: non-finite start parameters")
    x, cost, nfev, converged = levenberg_marquardt(prob, x0, max_nfev or MAX_EVALUATIONS)
    intr, rv, tv = prob.unpack(x)
    res, _, _, n_bad = prob._evaluate(x)
    if strict and (n_bad or not np.all(np.isfinite(x))):
        raise CalibrationError(f"{model}: the fit diverged ({n_bad} of {prob.N} corners cannot be projected "
                               "with the final parameters)")
    edge = get_model(model).range_edge(intr[4:]) if strict else None
    if edge is not None:  # the search stops there: every step beyond is outside the model (module docstring)
        raise CalibrationError(f"{model}: the fit stopped at the edge of the model's valid range ({edge}): the views "
                               "ask for a value the model does not allow, so it does not describe this lens")
    res2 = res.reshape(-1, 2)
    used = np.ones(prob.N, bool) if prob.w is None else prob.w > 0
    if prob.w is not None:  # px residuals (the penalty where unprojectable), rejected corners included
        res2 = np.where(np.isfinite(prob.px_residuals).all(axis=1)[:, None], prob.px_residuals, _PENALTY)
    sq = np.sum(res2 * res2, axis=1)
    per_view = np.array([np.sqrt(np.mean(s[u])) if u.any() else np.nan
                         for s, u in zip(np.split(sq, prob.splits), np.split(used, prob.splits))])
    cov = jtj = flex_cov = None
    sigma2, note = float(np.sum(sq[used]) / max(2 * prob.n_used - prob.shape[1], 1)), ""
    if covariance:
        cov, flex_cov, jtj, sigma2, note = _covariance(prob, x, cost, model, rank_strict)
    return BundleResult(model, intr, rv.copy(), tv.copy(), np.split(res2, prob.splits), float(np.sqrt(np.mean(sq[used]))),
                        per_view, cov, jtj, sigma2, cost, nfev, note, converged, prob.flex_of(x), flex_cov,
                        None if inliers is None else np.asarray(inliers, bool).copy())


def solve_pose(lens: Lens, obj, px) -> tuple[np.ndarray, np.ndarray, float] | None:
    """One view's pose with the intrinsics held fixed: (rvec (3,), tvec (3,), RMS px), or None.

    obj : (N, 3) board points; px : (N, 2) detected corners. Start from :func:`poses_from_rays`,
    then the least-squares fit over the 6 pose parameters only.
    """
    start = poses_from_rays(lens, [obj], [px])
    if start is None:
        return None
    fit = bundle_adjust(lens.model, [obj], [px], lens.intrinsics(), start[0], start[1],
                        free=np.zeros(4 + lens.dist.size, bool), covariance=False, strict=False)
    if not np.isfinite(fit.rms):
        return None
    return fit.rvecs[0], fit.tvecs[0], float(fit.rms)
