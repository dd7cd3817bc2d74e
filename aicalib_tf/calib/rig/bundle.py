"""One least-squares fit over every camera and view of a rig: intrinsics, camera poses and board poses.

Parameters, in order: each camera's intrinsics [fx, fy, cx, cy, *dist] (its own lens model), then
6 per camera after the first (rvec, tvec of X_k = R_k·X_0 + T_k: camera 0's frame to camera k's),
then 6 per board pose (rvec, tvec of the board in camera 0's frame). An observation is one camera's
corners of one board pose: camera k sees board point X at R_k·(R_g·X + t_g) + T_k. A board pose
seen by several cameras ties them together, whichever of its corners each one sees; a pose seen by
one camera only constrains that camera's lens.

The normal equations are solved as in :mod:`aicalib_tf.calib.bundle` (board poses eliminated by the
Schur complement, Levenberg–Marquardt of that module), so a step costs O(board poses).
The covariance of the global parameters is σ²·S⁻¹ with S the Schur complement at the minimum.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from aicalib_tf.calib.bundle import (_PENALTY, _RANK_TOL, CalibrationError, SchurProblem, levenberg_marquardt,
                                     schur_complement)
from aicalib_tf.calib.robust import with_floor
from aicalib_tf.calib.weights import corner_weights, fit_sigmas
from aicalib_tf.geometry.lens import N_COEFFS, check_model, projection_jacobian

__all__ = ["Observation", "RigFit", "rig_adjust", "global_layout"]


@dataclass(frozen=True)
class Observation:
    """Camera ``camera`` saw board pose ``group``: board points obj (N, 3) at pixels px (N, 2); name: its view's;
    sigmas: (N,) px, its corners' σ from the detector, or None (:mod:`aicalib_tf.calib.weights`)."""

    camera: int
    group: int
    obj: np.ndarray
    px: np.ndarray
    name: str = ""
    sigmas: np.ndarray | None = None


@dataclass(frozen=True)
class _Residuals:
    """A first fit's per-observation residuals (N_v, 2) px, as :func:`~aicalib_tf.calib.robust.with_floor` reads them."""

    residuals: list


@dataclass(frozen=True)
class RigFit:
    """The fitted rig.

    intrinsics : list of C arrays (4 + n_k,). extrinsics : (C, 6) rvec, tvec of each camera from
    camera 0 (row 0 zero). poses : (G, 6) board poses in camera 0's frame. residuals : list (one
    per observation, in the given order) of (N, 2) px, projected − detected. rms : px over all
    corners. covariance : (P, P) over the global parameters (:func:`global_layout`; fixed ones 0)
    or None. sigma2 : px². cost : ½ sum of squares. note : why the covariance is a pseudo-inverse, else "".
    """

    models: tuple[str, ...]
    intrinsics: list
    extrinsics: np.ndarray
    poses: np.ndarray
    residuals: list
    rms: float
    covariance: np.ndarray | None
    sigma2: float
    cost: float
    nfev: int
    note: str = ""


def global_layout(models) -> tuple[list[slice], list[slice]]:
    """(slices of each camera's intrinsics, slices of each camera's 6 pose parameters (None for camera 0))
    in the global parameter vector."""
    intr, k = [], 0
    for m in models:
        intr.append(slice(k, k + 4 + N_COEFFS[m]))
        k += 4 + N_COEFFS[m]
    extr = [None] + [slice(k + 6 * i, k + 6 * i + 6) for i in range(len(models) - 1)]
    return intr, extr


def _rodrigues(rvecs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R (M, 3, 3), dR (M, 3, 3, 3)) with dR[m, k] = dR / d rvec_k."""
    R, dR = np.empty((len(rvecs), 3, 3)), np.empty((len(rvecs), 3, 3, 3))
    for i, r in enumerate(rvecs):
        Ri, jac = cv2.Rodrigues(np.asarray(r, np.float64).reshape(3, 1))
        R[i], dR[i] = Ri, jac.reshape(3, 3, 3)
    return R, dR


class _RigProblem(SchurProblem):
    """Residuals and Jacobian blocks of one rig problem; corners sorted by board pose."""

    def __init__(self, models, observations, base, free, n_groups, sigmas=None):
        self.models = tuple(models)
        self.intr_sl, self.extr_sl = global_layout(models)
        order = sorted(range(len(observations)), key=lambda i: observations[i].group)
        self.order = order
        obs = [observations[i] for i in order]
        counts = np.array([len(o.px) for o in obs])
        self.X = np.concatenate([np.asarray(o.obj, np.float64).reshape(-1, 3) for o in obs])
        self.uv = np.concatenate([np.asarray(o.px, np.float64).reshape(-1, 2) for o in obs])
        self.cam = np.repeat([o.camera for o in obs], counts)
        group = np.repeat([o.group for o in obs], counts)
        if set(np.unique(group)) != set(range(n_groups)):
            raise ValueError("every board pose needs at least one observation")
        self.group = group
        self.splits = np.flatnonzero(np.diff(group)) + 1
        self.obs_splits = np.cumsum(counts)[:-1]
        self.N, self.V = len(self.uv), n_groups
        self.base = np.asarray(base, np.float64).copy()
        self.free = np.asarray(free, bool)
        self.nf = int(self.free.sum())
        self.shape = (2 * self.N, self.nf + 6 * self.V)
        self.w = None if sigmas is None else corner_weights([sigmas[i] for i in order], None, self.N)
        self._key = self._val = self.px_residuals = None

    def unpack(self, x):
        g = self.base.copy()
        g[self.free] = x[: self.nf]
        intr = [g[s] for s in self.intr_sl]
        extr = np.zeros((len(self.models), 6))
        for k, s in enumerate(self.extr_sl[1:], start=1):
            extr[k] = g[s]
        return g, intr, extr, x[self.nf:].reshape(self.V, 6)

    def _evaluate(self, x):  # size: one pass over the cameras' projections and the chain rule
        if self._key is not None and np.array_equal(x, self._key):
            return self._val
        g, intr, extr, poses = self.unpack(x)
        Rg, dRg = _rodrigues(poses[:, :3])
        Rc, dRc = _rodrigues(extr[:, :3])
        Y = np.einsum("nij,nj->ni", Rg[self.group], self.X) + poses[self.group, 3:]
        Rk = Rc[self.cam]
        Z = np.einsum("nij,nj->ni", Rk, Y) + extr[self.cam, 3:]
        uv, Jp = np.full((self.N, 2), np.nan), np.zeros((self.N, 2, 3))
        Jg = np.zeros((self.N, 2, g.size))
        for k, model in enumerate(self.models):
            m = self.cam == k
            if not m.any():
                continue
            v = intr[k]
            try:
                K = np.array([[v[0], 0, v[2]], [0, v[1], v[3]], [0, 0, 1.0]])
                uv[m], Jp[m], Jg[m, :, self.intr_sl[k]] = projection_jacobian(Z[m], model, K, v[4:])
            except ValueError:  # a focal length <= 0 or a non-finite value mid-search
                continue
            if k:
                Jg[m, :, self.extr_sl[k].start:self.extr_sl[k].start + 3] = np.einsum(
                    "nij,njk->nik", Jp[m], np.einsum("kij,nj->nik", dRc[k], Y[m]))
                Jg[m, :, self.extr_sl[k].start + 3:self.extr_sl[k].stop] = Jp[m]
        bad = ~np.isfinite(uv).all(axis=1)
        res = np.where(bad[:, None], _PENALTY, uv - self.uv)
        dY_dr = np.einsum("nkij,nj->nik", dRg[self.group], self.X)  # (N, 3, 3)
        JpR = np.einsum("nij,njk->nik", Jp, Rk)  # d uv / d Y
        J_pose = np.concatenate([np.einsum("nij,njk->nik", JpR, dY_dr), JpR], axis=2)
        J_glob = Jg[:, :, self.free]
        J_pose[bad], J_glob[bad] = 0.0, 0.0
        J_pose, J_glob = np.nan_to_num(J_pose), np.nan_to_num(J_glob)
        self.px_residuals = res  # unweighted, px
        if self.w is not None:
            res, J_pose, J_glob = res * self.w[:, None], J_pose * self.w[:, None, None], J_glob * self.w[:, None, None]
        self._key, self._val = x.copy(), (res.ravel(), J_glob, J_pose, int(bad.sum()))
        return self._val


def _covariance(prob: _RigProblem, x, cost: float, strict: bool) -> tuple[np.ndarray, float, str]:
    """(global covariance (P, P), σ², note): σ²·S⁻¹ over the free global parameters (column-normalised)."""
    U, W, Vb, _, _ = prob.normal_blocks(x)
    dof = 2 * prob.N - prob.shape[1]
    if dof <= 0:
        raise CalibrationError(f"rig: {prob.N} corners give {2 * prob.N} residuals for {prob.shape[1]} parameters")
    S, _ = schur_complement(U, W, Vb)
    d = np.sqrt(np.maximum(np.diag(S), 0.0))
    if np.any(~(d > 0)) or not np.all(np.isfinite(S)):
        raise CalibrationError("rig: the views do not constrain every camera's parameters")
    C = S / np.outer(d, d)
    w = np.linalg.eigvalsh(C)
    sigma2, note = 2.0 * cost / dof, ""
    if w[0] <= _RANK_TOL * w[-1]:
        note = f"rig: rank-deficient fit (condition {w[-1] / max(w[0], 1e-300):.1e})"
        if strict:
            raise CalibrationError(note)
        inv = np.linalg.pinv(C, rcond=_RANK_TOL, hermitian=True)
    else:
        inv = np.linalg.inv(C)
    cov = np.zeros((prob.base.size, prob.base.size))
    idx = np.flatnonzero(prob.free)
    cov[np.ix_(idx, idx)] = sigma2 * inv / np.outer(d, d)
    return cov, sigma2, note


def rig_adjust(models, observations, intrinsics, extrinsics, poses, *, free=None, max_nfev: int = 200,
               covariance: bool = True, rank_strict: bool = False) -> RigFit:
    """Fit every camera's lens, the cameras' poses and the board poses to the observations.

    models : C lens model names. observations : list of :class:`Observation` (camera in 0..C-1,
    group in 0..G-1, every group observed). intrinsics : C start vectors (4 + n_k,). extrinsics :
    (C, 6) start poses from camera 0 (row 0 ignored). poses : (G, 6) start board poses in camera 0's
    frame. free : bool over the global vector of :func:`global_layout` (default all). Raises
    :class:`CalibrationError` when the fit diverges or leaves a camera unconstrained.

    The observations' ``sigmas`` weigh their corners by the rule every fit shares
    (:func:`aicalib_tf.calib.weights.fit_sigmas`), with the error they leave unexplained added from a
    first fit (:func:`aicalib_tf.calib.robust.with_floor`), as a single camera's solve does; residuals
    and rms stay in px.
    """
    models = tuple(models)
    for m, v in zip(models, intrinsics):
        check_model(m, np.asarray(v, np.float64)[4:])
    extrinsics = np.asarray(extrinsics, np.float64).reshape(len(models), 6)
    base = np.concatenate([np.asarray(v, np.float64) for v in intrinsics] + [extrinsics[k] for k in range(1, len(models))])
    free = np.ones(base.size, bool) if free is None else np.asarray(free, bool)
    poses = np.asarray(poses, np.float64).reshape(-1, 6)
    sigmas = fit_sigmas([o.sigmas for o in observations], [len(o.px) for o in observations])
    prob = _RigProblem(models, observations, base, free, len(poses), sigmas)
    x0 = np.concatenate([base[free], poses.ravel()])
    if not np.all(np.isfinite(x0)):
        raise CalibrationError("rig: non-finite start parameters")
    x, cost, nfev, _ = levenberg_marquardt(prob, x0, max_nfev)
    if sigmas is not None and np.all(np.isfinite(x)):  # the error the σ's leave unexplained, then the weighted refit
        prob._evaluate(x)
        parts = np.split(prob.px_residuals, prob.obs_splits)
        firsts = [None] * len(observations)
        for pos, i in enumerate(prob.order):
            firsts[i] = parts[pos]
        floored = with_floor(sigmas, _Residuals(firsts))
        prob = _RigProblem(models, observations, base, free, len(poses), floored)
        x, cost, more, _ = levenberg_marquardt(prob, x, max_nfev)
        nfev += more
    res, _, _, n_bad = prob._evaluate(x)
    if n_bad or not np.all(np.isfinite(x)):
        raise CalibrationError(f"rig: the fit diverged ({n_bad} of {prob.N} corners cannot be projected); "
                               "do the images paired as one frame show the board at one moment?")
    _, intr, extr, pose_out = prob.unpack(x)
    res2, px2 = res.reshape(-1, 2), prob.px_residuals
    parts = np.split(px2, prob.obs_splits)
    residuals = [None] * len(observations)
    for pos, i in enumerate(prob.order):
        residuals[i] = parts[pos]
    cov, sigma2, note = None, float(np.sum(res2 * res2) / max(2 * prob.N - prob.shape[1], 1)), ""
    if covariance:
        cov, sigma2, note = _covariance(prob, x, cost, rank_strict)
    return RigFit(models, [v.copy() for v in intr], extr, pose_out.copy(), residuals,
                  float(np.sqrt(np.mean(np.sum(px2 * px2, axis=1)))), cov, sigma2, cost, nfev, note)
