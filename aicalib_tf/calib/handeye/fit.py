"""Hand-eye calibration's joint fit: board corners' reprojection over the whole chain (numpy).

One least-squares problem over

* X (the hand-eye transform) and Y (the board's pose in the base, or on the flange), see
  :mod:`aicalib_tf.calib.handeye.solve` for the chain ``C_i = X⁻¹ · G_i⁻¹ · Y``;
* each view's robot pose ``A_i = T_base_flange``, which enters as a parameter with a prior: the
  reported pose, with σ_rot (radians, about each base axis) and σ_t (metres, each axis);
* optionally the intrinsics ([fx, fy, cx, cy, *dist] of the lens model).

Residuals: each corner's reprojection error divided by σ_px, and each robot pose's correction
divided by its σ. A transform is perturbed on the left: R = exp(ω)·R₀ (ω in the parent frame,
radians), t = t₀ + τ (metres), so its covariance is that of (τ, ω) at the solution.

The Jacobian is by central differences, grouped: the global parameters one at a time, the robot
poses' six components each for all views at once (a view's residuals depend on its own pose only).
Levenberg–Marquardt on the dense normal equations (a few hundred parameters at most). The
covariance is (JᵀJ)⁻¹ at the minimum, scaled by the reduced χ² when that exceeds 1 (noise larger
than stated widens σ; smaller noise never narrows it below what was stated).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aicalib_tf.geometry.transform import exp_rotations, inv, perturb
from aicalib_tf.geometry.lens import Lens, project

__all__ = ["SETUPS", "JointFit", "joint_fit", "exp_rotations", "perturb", "chain_G"]

SETUPS = ("eye-in-hand", "eye-to-hand")


def chain_G(setup: str, A) -> np.ndarray:
    """The chain's robot transforms G (V, 4, 4) from T_base_flange A: A itself (eye-in-hand) or A⁻¹."""
    if setup not in SETUPS:
        raise ValueError(f"setup must be one of {SETUPS}, got {setup!r}")
    return np.asarray(A, np.float64) if setup == "eye-in-hand" else inv(A)


@dataclass(frozen=True)
class JointFit:
    """The joint fit's result. X, Y (4, 4); A (V, 4, 4) the fitted robot poses; lens : the camera.
    cov : (n, n) covariance of all parameters in the order [X (ω, τ), Y (ω, τ), A_i (ω, τ) ..., intrinsics].
    per_view_rms : (V,) px. correction_deg, correction_mm : (V,) how far the fit moved each robot pose.
    chi2 : reduced χ² (2·cost / (m − n)); rms : px over all corners; iterations."""

    X: np.ndarray
    Y: np.ndarray
    A: np.ndarray
    lens: Lens
    cov: np.ndarray
    per_view_rms: np.ndarray
    correction_deg: np.ndarray
    correction_mm: np.ndarray
    chi2: float
    rms: float
    iterations: int


class _Problem:
    """The stacked residuals of the module docstring and their grouped finite-difference Jacobian."""

    def __init__(self, setup, lens, obj, px, A, X0, Y0, sigma_px, sigma_rot, sigma_t, free_intrinsics, corner_scale=None):
        self.setup, self.model, self.size = setup, lens.model, lens.image_size
        self.V = len(obj)
        self.view = np.concatenate([np.full(len(o), k) for k, o in enumerate(obj)])
        self.obj = np.concatenate(obj)
        self.px = np.concatenate(px)
        self.A0, self.X0, self.Y0 = np.asarray(A, np.float64), X0, Y0
        self.intr0 = lens.intrinsics()
        self.free = bool(free_intrinsics)
        self.sigma = (float(sigma_px), float(sigma_rot), float(sigma_t))
        self.sp = float(sigma_px) * (np.ones(len(self.px)) if corner_scale is None  # each corner's σ px
                                     else np.concatenate([np.asarray(c, np.float64).ravel() for c in corner_scale]))
        self.n_global = 12 + (self.intr0.size if self.free else 0)
        self.n = self.n_global + 6 * self.V
        # rows: 2 per corner, then 6 per view's prior
        self.row_view = np.concatenate([np.repeat(self.view, 2), np.repeat(np.arange(self.V), 6)])

    def unpack(self, p):
        X, Y = perturb(self.X0, p[0:6]), perturb(self.Y0, p[6:12])
        k = 12
        intr = self.intr0
        if self.free:
            intr = self.intr0 + p[12:12 + self.intr0.size]
            k += self.intr0.size
        d = p[k:k + 6 * self.V].reshape(self.V, 6)
        return X, Y, intr, d, perturb(self.A0, d)

    def residuals(self, p) -> np.ndarray:
        X, Y, intr, d, A = self.unpack(p)
        G = chain_G(self.setup, A)
        C = inv(X)[None] @ inv(G) @ Y[None]
        R, t = C[self.view, :3, :3], C[self.view, :3, 3]
        pc = np.einsum("nij,nj->ni", R, self.obj) + t
        K = np.array([[intr[0], 0, intr[2]], [0, intr[1], intr[3]], [0, 0, 1.0]])
        uv = project(pc, self.model, K, intr[4:])
        _, sr, st = self.sigma
        rp = ((uv - self.px) / self.sp[:, None]).ravel()
        prior = np.concatenate([d[:, :3] / sr, d[:, 3:] / st], axis=1).ravel()
        return np.concatenate([rp, prior])

    def _steps(self, p) -> np.ndarray:
        h = np.full(self.n, 1e-6)
        if self.free:
            h[12:self.n_global] = 1e-6 * np.maximum(1.0, np.abs(self.intr0 + p[12:self.n_global]))
            h[12 + 4:self.n_global] = 1e-7  # distortion coefficients
        return h

    def jacobian(self, p) -> np.ndarray:
        m = self.px.size + 6 * self.V
        J = np.zeros((m, self.n))
        h = self._steps(p)
        for j in range(self.n_global):
            e = np.zeros(self.n)
            e[j] = h[j]
            J[:, j] = (self.residuals(p + e) - self.residuals(p - e)) / (2 * h[j])
        rows = np.arange(m)
        for c in range(6):  # component c of every view's robot pose at once
            e = np.zeros(self.n)
            cols = self.n_global + 6 * np.arange(self.V) + c
            e[cols] = h[cols]
            diff = (self.residuals(p + e) - self.residuals(p - e)) / (2 * h[cols[0]])
            J[rows, self.n_global + 6 * self.row_view + c] = diff
        return J


def _lm(prob: _Problem, p, max_iter: int = 60) -> tuple[np.ndarray, np.ndarray, int]:
    """Levenberg–Marquardt (Marquardt's diagonal scaling); returns (p, J at p, iterations)."""
    r = prob.residuals(p)
    cost = float(r @ r)
    if not np.isfinite(cost):
        raise ValueError("the start projects board corners outside the lens's valid range")
    lam, it = 1e-3, 0
    J = prob.jacobian(p)
    for it in range(1, max_iter + 1):
        g, N = J.T @ r, J.T @ J
        D = np.maximum(np.diag(N), 1e-12)
        improved = False
        for _ in range(12):
            try:
                step = -np.linalg.solve(N + lam * np.diag(D), g)
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            r_new = prob.residuals(p + step)
            c_new = float(r_new @ r_new)
            if np.isfinite(c_new) and c_new < cost:
                rel = (cost - c_new) / max(cost, 1e-300)
                p, r, cost, improved = p + step, r_new, c_new, True
                lam = max(lam / 10, 1e-12)
                break
            lam *= 10
        if not improved:
            break
        J = prob.jacobian(p)
        if rel < 1e-12 or np.max(np.abs(step)) < 1e-12:
            break
    return p, J, it


def joint_fit(setup: str, lens: Lens, obj, px, A, X0, Y0, *, sigma_px: float, sigma_rot: float, sigma_t: float,
              free_intrinsics: bool = False, max_iter: int = 60, corner_scale=None) -> JointFit:
    """Fit X, Y, the robot poses (and the intrinsics) to the views' corners (module docstring).

    setup : "eye-in-hand" or "eye-to-hand". lens : the camera (its intrinsics are the start when free).
    obj : V arrays (N_i, 3) board points, metres, each in the board's frame as that view's
    detection reads it (turned detections mapped back). px : V arrays (N_i, 2) detected corners, px.
    A : (V, 4, 4) reported T_base_flange, metres. X0, Y0 : (4, 4) start. sigma_px : the corners' noise
    per coordinate, px; sigma_rot (radians), sigma_t (metres): the robot's per axis. corner_scale : V
    arrays (N_i,), each corner's σ over ``sigma_px`` (the detector's σ by the rule every fit shares,
    :func:`aicalib_tf.calib.weights.fit_sigmas`), or None (all 1).
    """
    prob = _Problem(setup, lens, [np.asarray(o, np.float64) for o in obj], [np.asarray(q, np.float64) for q in px],
                    A, np.asarray(X0, np.float64), np.asarray(Y0, np.float64), sigma_px, sigma_rot, sigma_t,
                    free_intrinsics, corner_scale)
    p, _, it = _lm(prob, np.zeros(prob.n), max_iter)
    X, Y, intr, d, A_fit = prob.unpack(p)
    # re-centre at the solution so that the covariance is that of a small perturbation there
    prob2 = _Problem(setup, Lens.from_intrinsics(lens.model, intr, lens.image_size), obj, px, A_fit, X, Y,
                     sigma_px, sigma_rot, sigma_t, free_intrinsics, corner_scale)
    prob2.A0 = prob.A0  # the priors stay on the reported poses
    p2 = np.zeros(prob2.n)
    p2[prob2.n_global:] = _relative(prob.A0, A_fit).ravel()
    r = prob2.residuals(p2)
    J = prob2.jacobian(p2)
    m, n = r.size, p2.size
    chi2 = float(r @ r) / max(m - n, 1)
    cov = np.linalg.pinv(J.T @ J) * max(chi2, 1.0)
    res = r[:prob.px.size].reshape(-1, 2) * prob.sp[:, None]
    e2 = np.bincount(prob.view, weights=(res ** 2).sum(1), minlength=prob.V)
    per_view = np.sqrt(e2 / np.bincount(prob.view, minlength=prob.V))
    return JointFit(X, Y, A_fit, Lens.from_intrinsics(lens.model, intr, lens.image_size), cov, per_view,
                    np.degrees(np.linalg.norm(d[:, :3], axis=1)), 1e3 * np.linalg.norm(d[:, 3:], axis=1),
                    chi2, float(np.sqrt((res ** 2).sum(1).mean())), it)


def _relative(A0, A) -> np.ndarray:
    """(V, 6) [ω, τ] with A = perturb(A0, [ω, τ])."""
    import cv2

    D = A[:, :3, :3] @ np.swapaxes(A0[:, :3, :3], 1, 2)
    w = np.array([cv2.Rodrigues(np.ascontiguousarray(R))[0].ravel() for R in D])
    return np.concatenate([w, A[:, :3, 3] - A0[:, :3, 3]], axis=1)
