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

Starts: :mod:`aicalib_tf.calib.starts` gives the intrinsics; :func:`poses_from_rays` gives every view's pose from a lens guess (rays from
:func:`~aicalib_tf.geometry.lens.unproject`, turned so that the board lies ahead, then
``cv2.solvePnP`` on normalized coordinates with K = I), which works for boards past 90° off-axis.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from aicalib_tf.geometry.lens import COEFF_NAMES, N_COEFFS, Lens, check_model, get_model, projection_jacobian

__all__ = ["CalibrationError", "BundleResult", "bundle_adjust", "levenberg_marquardt", "schur_complement", "reduce_blocks",
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
    pseudo-inverse (rank-deficient fit), else "".
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

    @property
    def lens(self) -> Lens:
        """The fitted intrinsics as a :class:`~aicalib_tf.geometry.lens.Lens` (image size (1, 1): unknown here)."""
        return Lens.from_intrinsics(self.model, self.intrinsics, (1, 1))


class SchurProblem:
    """What :func:`levenberg_marquardt` needs of a problem whose parameters are ``nf`` global ones then 6 per
    pose: a subclass sets ``splits`` (corner groups by pose) and ``_evaluate(x)`` -> (residuals (2N,),
    global Jacobian (N, 2, nf), pose Jacobian (N, 2, 6), number of unprojectable corners)."""

    def fun(self, x):
        """Residuals (2N,), px."""
        return self._evaluate(x)[0]

    def normal_blocks(self, x):
        """Blocks of JᵀJ and Jᵀr without forming J: U (nf, nf), W (V, nf, 6), Vb (V, 6, 6), gu (nf,), gv (V, 6)."""
        r, Ji, Jp, _ = self._evaluate(x)
        return reduce_blocks(r, Ji, Jp, self.splits)


class _Problem(SchurProblem):
    """Residuals and the Jacobian's blocks of one bundle problem (cached per parameter vector)."""

    def __init__(self, model, obj, px, intr0, free):
        self.model, self.ni = model, 4 + N_COEFFS[model]
        self.X = np.concatenate([np.asarray(o, np.float64).reshape(-1, 3) for o in obj])
        self.uv = np.concatenate([np.asarray(p, np.float64).reshape(-1, 2) for p in px])
        counts = [len(np.asarray(p).reshape(-1, 2)) for p in px]
        self.view_of = np.repeat(np.arange(len(px)), counts)
        self.splits = np.cumsum(counts)[:-1]
        self.V, self.N = len(px), len(self.uv)
        self.base = np.asarray(intr0, np.float64).copy()
        self.free = np.asarray(free, bool)
        self.nf = int(self.free.sum())
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
            val = (found[0], J[:, self.free])
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
        intr[self.free] = x[: self.nf]
        poses = x[self.nf:].reshape(self.V, 6)
        return intr, poses[:, :3], poses[:, 3:]

    def _evaluate(self, x):
        if self._key is not None and np.array_equal(x, self._key):
            return self._val
        intr, rv, tv = self.unpack(x)
        R, dR = np.empty((self.V, 3, 3)), np.empty((self.V, 3, 3, 3))
        for v in range(self.V):
            Rv, jac = cv2.Rodrigues(rv[v])
            R[v], dR[v] = Rv, jac.reshape(3, 3, 3)  # dR[v][k] = dR / d rvec_k
        Xc = np.einsum("nij,nj->ni", R[self.view_of], self.X) + tv[self.view_of]
        try:
            K = np.array([[intr[0], 0, intr[2]], [0, intr[1], intr[3]], [0, 0, 1.0]])
            uv, Jp, Ji = projection_jacobian(Xc, self.model, K, intr[4:])
        except ValueError:  # e.g. a focal length <= 0 or a non-finite value mid-search
            uv = np.full((self.N, 2), np.nan)
            Jp, Ji = np.zeros((self.N, 2, 3)), np.zeros((self.N, 2, self.ni))
        bad = ~np.isfinite(uv).all(axis=1)
        res = np.where(bad[:, None], _PENALTY, uv - self.uv)
        dP_dr = np.einsum("nkij,nj->nik", dR[self.view_of], self.X)  # (N, 3, 3): d Xc / d rvec
        J_pose = np.concatenate([Jp @ dP_dr, Jp], axis=2)  # (N, 2, 6)
        J_intr = Ji[:, :, self.free]
        J_pose[bad], J_intr[bad] = 0.0, 0.0
        self._key, self._val = x.copy(), (res.ravel(), J_intr, J_pose, int(bad.sum()))
        return self._val


def reduce_blocks(r, Ji, Jp, splits):
    """JᵀJ and Jᵀr in blocks from residuals r (2N,), global columns Ji (N, 2, nf) and pose columns
    Jp (N, 2, 6), the corners grouped by pose (``splits``: np.split indices, every group non-empty):
    (U (nf, nf), W (V, nf, 6), Vb (V, 6, 6), gu (nf,), gv (V, 6))."""
    r = r.reshape(-1, 2)
    starts = np.concatenate([[0], splits]).astype(np.int64)
    # batched matmul rather than einsum: the same sums, 3–6× faster here (einsum does not use BLAS)
    flat = Ji.reshape(Ji.shape[0] * Ji.shape[1], Ji.shape[2])
    U = flat.T @ flat
    JiT, JpT = Ji.transpose(0, 2, 1), Jp.transpose(0, 2, 1)
    W = np.add.reduceat(JiT @ Jp, starts, axis=0)
    Vb = np.add.reduceat(JpT @ Jp, starts, axis=0)
    gu = flat.T @ r.ravel()
    gv = np.add.reduceat(np.einsum("nri,nr->ni", Jp, r), starts, axis=0)
    return U, W, Vb, gu, gv


def schur_complement(U, W, Vb):
    """(S = U − W·Vb⁻¹·Wᵀ (nf, nf), Vb⁻¹ (V, 6, 6)): the intrinsics block of JᵀJ with the poses eliminated."""
    Vinv = np.linalg.inv(Vb)
    WV = np.einsum("vij,vjk->vik", W, Vinv)
    nf = W.shape[1]  # Σ_v WV_v·W_vᵀ as one matrix product (einsum does not use BLAS)
    if nf == 0:
        return U, Vinv
    return U - WV.transpose(1, 0, 2).reshape(nf, -1) @ W.transpose(1, 0, 2).reshape(nf, -1).T, Vinv


def _covariance(prob: _Problem, x, cost: float, model: str, strict: bool):
    """(intrinsics covariance (ni, ni), JᵀJ (P, P), σ², note).

    [(JᵀJ)⁻¹] restricted to the intrinsics is the inverse of the Schur complement S. A rank-deficient
    fit (column-normalised S or a pose block with eigenvalue ratio <= _RANK_TOL) raises
    CalibrationError when ``strict``, else the covariance uses the pseudo-inverse and ``note`` says so.
    """
    U, W, Vb, _, _ = prob.normal_blocks(x)
    dof = 2 * prob.N - prob.shape[1]
    if dof <= 0:
        raise CalibrationError(f"{model}: {prob.N} corners give {2 * prob.N} residuals for {prob.shape[1]} parameters")
    names = [n for n, f in zip(param_names(model), prob.free) if f]
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
    cov = np.zeros((prob.ni, prob.ni))
    idx = np.flatnonzero(prob.free)
    cov[np.ix_(idx, idx)] = sigma2 * inv / np.outer(d, d)
    nf, jtj = prob.nf, np.zeros((prob.shape[1], prob.shape[1]))
    jtj[:nf, :nf] = U
    for v in range(prob.V):
        sl = slice(nf + 6 * v, nf + 6 * v + 6)
        jtj[:nf, sl], jtj[sl, :nf], jtj[sl, sl] = W[v], W[v].T, Vb[v]
    return cov, jtj, sigma2, note


def levenberg_marquardt(prob, x0, max_nfev: int):
    """Minimise ½|r(x)|² by Levenberg–Marquardt on the Schur-reduced normal equations; returns (x,
    cost, evaluations, converged), converged False when ``max_nfev`` ran out first.

    prob : any problem whose parameters are ``prob.nf`` global ones followed by 6 per pose, with
    ``prob.fun(x)`` -> residuals and ``prob.normal_blocks(x)`` -> :func:`reduce_blocks`' tuple
    (this module's bundle, and the rig fit of :mod:`aicalib_tf.calib.rig_bundle`)."""
    x = x0.copy()
    r = prob.fun(x)
    cost, nfev, lam, nf, improved, done = 0.5 * float(r @ r), 1, 1e-3, prob.nf, False, False
    while nfev < max_nfev:
        U, W, Vb, gu, gv = prob.normal_blocks(x)
        dU = np.maximum(np.diag(U), 1e-12 * max(float(np.max(np.diag(U), initial=0.0)), 1e-300))
        dV = np.maximum(np.einsum("vii->vi", Vb), 1e-12)
        improved = done = False
        while nfev < max_nfev and lam < 1e16:
            try:
                S, Vinv = schur_complement(U + lam * np.diag(dU), W, Vb + lam * dV[:, :, None] * np.eye(6))
                du = -np.linalg.solve(S, gu - np.einsum("vij,vjk,vk->i", W, Vinv, gv)) if nf else np.zeros(0)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            dv = -np.einsum("vij,vj->vi", Vinv, gv + np.einsum("vij,i->vj", W, du))
            dx = np.concatenate([du, dv.ravel()])
            r_new = prob.fun(x + dx)
            nfev += 1
            c_new = 0.5 * float(r_new @ r_new)
            if np.isfinite(c_new) and c_new < cost:
                done = cost - c_new <= 1e-10 * cost or np.all(np.abs(dx) <= 1e-9 * (np.abs(x) + 1e-9))
                x, r, cost, lam, improved = x + dx, r_new, c_new, max(lam / 3.0, 1e-12), True
                break
            lam *= 10.0
        if not improved or done:
            break
    return x, cost, nfev, done or (not improved and nfev < max_nfev)


def bundle_adjust(model: str, obj, px, intrinsics, rvecs, tvecs, *, free=None, max_nfev: int | None = None,
                  covariance: bool = True, strict: bool = True, rank_strict: bool = True) -> BundleResult:
    """Fit a lens model and every view's pose to detected corners.

    model : a :data:`~aicalib_tf.geometry.lens.MODELS` name. obj : list of V (N_v, 3) board points
    (board frame, any unit). px : list of V (N_v, 2) detected corners, px. intrinsics : (4 + n,)
    start [fx, fy, cx, cy, *dist]; rvecs, tvecs : (V, 3) start poses. free : (4 + n,) bool, the
    intrinsics to fit (default all; False holds the start value). max_nfev : evaluation cap (None:
    to convergence). covariance : also return the covariance and JᵀJ. strict : raise
    :class:`CalibrationError` when the fit ends with non-finite values or unprojectable corners.
    rank_strict : raise on a rank-deficient fit (else the covariance is a pseudo-inverse and ``note`` says so).
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
    prob = _Problem(model, obj, px, intrinsics, free)
    x0 = np.concatenate([np.asarray(intrinsics, np.float64)[free],
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
    sq = np.sum(res2 * res2, axis=1)
    per_view = np.array([np.sqrt(np.mean(s)) for s in np.split(sq, prob.splits)])
    cov = jtj = None
    sigma2, note = float(np.sum(sq) / max(2 * prob.N - prob.shape[1], 1)), ""
    if covariance:
        cov, jtj, sigma2, note = _covariance(prob, x, cost, model, rank_strict)
    return BundleResult(model, intr, rv.copy(), tv.copy(), np.split(res2, prob.splits), float(np.sqrt(np.mean(sq))),
                        per_view, cov, jtj, sigma2, cost, nfev, note, converged)


def poses_from_rays(lens: Lens, obj, px, min_z: float = 0.2):
    """Every view's pose from a lens guess: (rvecs (V, 3), tvecs (V, 3)), or None if a view fails.

    Each corner is unprojected with ``lens``; the view's rays are turned so that their mean points
    along +z (a board seen 90° or more off-axis then lies in front of the turned camera), the rays
    with z > ``min_z`` there (0.05 when fewer than 4 remain) go to ``cv2.solvePnP`` as normalized
    coordinates with K = I, and the pose is turned back.
    """
    rvecs, tvecs = [], []
    for o, p in zip(obj, px):
        o, p = np.asarray(o, np.float64).reshape(-1, 3), np.asarray(p, np.float64).reshape(-1, 2)
        rays = lens.unproject(p)
        fin = np.isfinite(rays).all(axis=1)
        if fin.sum() < 4:
            return None
        Q = _turn_to_z(np.mean(rays[fin] / np.linalg.norm(rays[fin], axis=1, keepdims=True), axis=0))
        turned = rays @ Q.T
        pose = None
        for z in (min_z, 0.05):
            ok = fin & (turned[:, 2] > z * np.linalg.norm(turned, axis=1))
            if ok.sum() >= 4:
                pose = _pnp(o[ok], turned[ok, :2] / turned[ok, 2:])
                break
        if pose is None:
            return None
        R, _ = cv2.Rodrigues(pose[0])
        rvecs.append(cv2.Rodrigues(Q.T @ R)[0].ravel())
        tvecs.append(Q.T @ pose[1])
    return np.array(rvecs), np.array(tvecs)


def _turn_to_z(m: np.ndarray) -> np.ndarray:
    """A rotation (3, 3) that takes the direction ``m`` (3,) to +z (the identity when m is +z)."""
    m = m / np.linalg.norm(m)
    axis = np.cross(m, [0.0, 0.0, 1.0])
    s, c = np.linalg.norm(axis), float(m[2])
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    return cv2.Rodrigues(axis / s * np.arctan2(s, c))[0]


def _pnp(o, xn):
    """Pose of planar board points o (M, 3) seen at normalized coordinates xn (M, 2), or None."""
    eye = np.eye(3)
    for flags in (cv2.SOLVEPNP_IPPE, cv2.SOLVEPNP_ITERATIVE):
        try:
            ok, r, t = cv2.solvePnP(o, xn.reshape(-1, 1, 2), eye, None, flags=flags)
        except cv2.error:
            continue
        if ok and np.all(np.isfinite(r)) and np.all(np.isfinite(t)) and t[2, 0] > 0:
            return r.ravel(), t.ravel()
    return None


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
