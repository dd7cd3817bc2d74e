"""Hand-eye calibration: a robot's poses and the camera's board views -> where the camera sits (numpy/OpenCV).

Two setups (frames as ROS names them; ``T_a_b`` maps b's coordinates into a; metres, radians):

* ``eye-in-hand``: the camera rides on the flange and looks at a board fixed in the cell.
  Unknowns: ``T_flange_camera`` (the hand-eye transform) and ``T_base_board``.
* ``eye-to-hand``: the camera is fixed in the cell and the flange holds the board.
  Unknowns: ``T_base_camera`` and ``T_flange_board``.

:func:`calibrate_handeye` runs, in order:

1. each view's board pose by PnP with the camera's intrinsics (:func:`aicalib_tf.calib.bundle.solve_pose`);
2. the rotations' spread (:func:`~aicalib_tf.calib.handeye.solve.rotation_spread`): rotations all
   about one axis leave the transform unfixed and are refused;
3. a robust closed-form start (:func:`~aicalib_tf.calib.handeye.solve.robust_start`): views whose
   robot pose disagrees with their image by more than 1° or 2 cm are left out, with the reason;
4. the joint fit (:func:`~aicalib_tf.calib.handeye.fit.joint_fit`) of the corners over the
   transform, the board's pose, the robot poses (with their σ) and, when asked, the intrinsics;
5. a finer outlier test: the robot pose each image implies (through the fitted chain) against
   the reported one; a view more than max(5 × the median, 4√3 σ) off, in rotation or in
   translation, is left out and the fit rerun (worst first, at most a third of the views);
6. the verdict (:mod:`aicalib_tf.calib.handeye.quality`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from aicalib_tf.calib.bundle import CalibrationError, solve_pose
from aicalib_tf.calib.handeye.fit import SETUPS, JointFit, chain_G, joint_fit
from aicalib_tf.calib.handeye.solve import board_flips, chain_discrepancy, inv, robust_start, rotation_angle, to_T
from aicalib_tf.geometry.lens import Lens, project
from aicalib_tf.geometry.pattern import board_points

__all__ = ["SETUPS", "FRAMES", "HandEyeResult", "calibrate_handeye", "DEFAULT_SIGMA_ROT_DEG", "DEFAULT_SIGMA_T_MM"]

DEFAULT_SIGMA_ROT_DEG = 0.01  # a robot's reported orientation, per axis (repeatability class of industrial arms)
DEFAULT_SIGMA_T_MM = 0.05  # its reported position, per axis
FRAMES = {"eye-in-hand": (("flange", "camera"), ("base", "board")),
          "eye-to-hand": (("base", "camera"), ("flange", "board"))}


@dataclass(frozen=True)
class HandEyeResult:
    """A hand-eye calibration.

    setup : "eye-in-hand" or "eye-to-hand". X : (4, 4) the hand-eye transform (T_flange_camera or
    T_base_camera), Y : (4, 4) the board's pose (T_base_board or T_flange_board), metres.
    cov_X, cov_Y : (6, 6) covariance of [tx, ty, tz (m), rx, ry, rz (rad, a small rotation in the
    parent frame)]. lens : the camera; intrinsics_fitted : whether they were part of the fit.
    views : names of the used views; per_view_rms (V,) px; robot_deg, robot_mm (V,): how far the
    robot pose each image implies is from the reported one; correction_deg, correction_mm (V,):
    how far the fit moved the reported poses. A : (V, 4, 4) reported T_base_flange; C : (V, 4, 4)
    fitted T_camera_board per view. rejected : {view name: reason}. sigma_px : the corners' noise per
    coordinate; sigma_rot_deg, sigma_t_mm : the robot's stated σ. rms : px. chi2 : reduced χ².
    quality : the verdict (:mod:`aicalib_tf.calib.handeye.quality`).
    """

    setup: str
    X: np.ndarray
    Y: np.ndarray
    cov_X: np.ndarray
    cov_Y: np.ndarray
    lens: Lens
    intrinsics_fitted: bool
    views: tuple[str, ...]
    per_view_rms: np.ndarray
    robot_deg: np.ndarray
    robot_mm: np.ndarray
    correction_deg: np.ndarray
    correction_mm: np.ndarray
    A: np.ndarray
    C: np.ndarray
    rejected: dict
    sigma_px: float
    sigma_rot_deg: float
    sigma_t_mm: float
    rms: float
    chi2: float
    quality: dict = field(default_factory=dict)

    @property
    def names(self) -> tuple[tuple[str, str], tuple[str, str]]:
        """((parent, child) of X, (parent, child) of Y)."""
        return FRAMES[self.setup]

    @property
    def std_X(self) -> tuple[np.ndarray, np.ndarray]:
        """(σ of X's translation (3,) mm, σ of its rotation (3,) degrees)."""
        s = np.sqrt(np.maximum(np.diag(self.cov_X), 0.0))
        return 1e3 * s[:3], np.degrees(s[3:])


@dataclass
class _Views:
    names: list
    obj: list  # (N, 3) metres, in the board frame as the detection reads it
    px: list
    A: np.ndarray
    Cs: np.ndarray  # (V, F, 4, 4) PnP pose in each of the board's orders
    sigmas: list  # per view the detector's (N,) σ px or None
    scale: list | None = None  # per view (N,) each corner's σ over the corners' noise (_corner_scale), None: all 1


def _pnp_views(views, poses, lens: Lens, square: float, flips, rejected) -> _Views:
    names, obj, px, A, Cs, sigmas = [], [], [], [], [], []
    for v in views:
        o = board_points(v.ids, square)
        found = solve_pose(lens, o, v.corners)
        if found is None:
            rejected[v.name] = "no board pose (PnP failed)"
            continue
        C = to_T(found[0], found[1])
        names.append(v.name)
        obj.append(o)
        px.append(np.asarray(v.corners, np.float64))
        A.append(np.asarray(poses[v.name], np.float64))
        Cs.append([C @ F for F in flips])
        sigmas.append(getattr(v, "sigmas", None))
    return _Views(names, obj, px, np.array(A).reshape(-1, 4, 4), np.array(Cs).reshape(-1, len(flips), 4, 4), sigmas)


def _keep(d: _Views, mask) -> _Views:
    idx = np.flatnonzero(mask)
    return _Views([d.names[k] for k in idx], [d.obj[k] for k in idx], [d.px[k] for k in idx], d.A[idx], d.Cs[idx],
                  [d.sigmas[k] for k in idx], None if d.scale is None else [d.scale[k] for k in idx])


def _apply_order(d: _Views, order, flips) -> None:
    """Map each view's board points into the first view's reading of the board (module solve's board_flips)."""
    for k, f in enumerate(order):
        if f:
            Fi = inv(flips[f])
            d.obj[k] = d.obj[k] @ Fi[:3, :3].T + Fi[:3, 3]
            d.Cs[k] = d.Cs[k][[f]].repeat(d.Cs.shape[1], axis=0)
    d.Cs = d.Cs[:, :1]


def _pnp_residuals(d: _Views, lens: Lens) -> list:
    """Per view (N, 2) px: projected − detected at each view's PnP pose."""
    return [project(o @ C[:3, :3].T + C[:3, 3], lens.model, lens.K, lens.dist) - q
            for o, q, C in zip(d.obj, d.px, d.Cs[:, 0])]


def _corner_scale(d: _Views, lens: Lens) -> list | None:
    """Per view (N,) each corner's σ over their median, by the rule every fit shares (the views' σ,
    :func:`~aicalib_tf.calib.weights.fit_sigmas`, with the error they leave unexplained in the PnP
    residuals added, :func:`~aicalib_tf.calib.robust.with_floor`); None when no view has σ."""
    from aicalib_tf.calib.robust import with_floor
    from aicalib_tf.calib.weights import fit_sigmas

    sig = fit_sigmas(d.sigmas, [len(q) for q in d.px])
    if sig is None:
        return None
    sig = with_floor(sig, _Fit(_pnp_residuals(d, lens)))
    ref = float(np.median(np.concatenate(sig)))
    return [s / ref for s in sig]


@dataclass
class _Fit:
    residuals: list  # per view (N, 2) px, as with_floor reads a fit


def _sigma_px(d: _Views, lens: Lens) -> float:
    """The corners' noise per coordinate from each view's PnP residuals (6 pose parameters a view), each
    corner's over its ``scale``."""
    e2, n = 0.0, 0
    scale = d.scale or [np.ones(len(q)) for q in d.px]
    for r, q, s in zip(_pnp_residuals(d, lens), d.px, scale):
        e2 += float(np.nansum((r / s[:, None]) ** 2))
        n += q.size
    dof = n - 6 * len(d.obj)
    return max(math.sqrt(e2 / max(dof, 1)), 0.01)


def _implied(setup, A, X, Y, C) -> tuple[np.ndarray, np.ndarray]:
    """(degrees (V,), mm (V,)) between the reported T_base_flange and the one each view's image implies."""
    G = Y[None] @ inv(C) @ inv(X)[None]
    A_img = G if setup == "eye-in-hand" else inv(G)
    D = inv(A) @ A_img
    return np.degrees(rotation_angle(D[:, :3, :3])), 1e3 * np.linalg.norm(A_img[:, :3, 3] - A[:, :3, 3], axis=1)


def _repnp(d: _Views, lens: Lens) -> np.ndarray:
    out = []
    for o, q, C in zip(d.obj, d.px, d.Cs[:, 0]):
        found = solve_pose(lens, o, q)
        out.append(to_T(*found[:2]) if found is not None else C)
    return np.array(out)


def _fit(setup, d: _Views, lens, X0, Y0, sig, free) -> JointFit:
    return joint_fit(setup, lens, d.obj, d.px, d.A, X0, Y0, sigma_px=sig[0], sigma_rot=sig[1], sigma_t=sig[2],
                     free_intrinsics=free, corner_scale=d.scale)


def _outlier_loop(setup, d: _Views, lens, fit: JointFit, sig, free, rejected) -> tuple[_Views, JointFit]:
    """Step 5 of the module docstring; returns the views kept and their fit."""
    floor_deg, floor_mm = 4 * math.sqrt(3) * math.degrees(sig[1]), 4 * math.sqrt(3) * sig[2] * 1e3
    budget = len(d.names) // 3
    while budget > 0 and len(d.names) > 3:
        deg, mm = _implied(setup, d.A, fit.X, fit.Y, _repnp(d, fit.lens))
        scale = np.ones(len(deg)) if d.scale is None else np.array([float(np.median(c)) for c in d.scale])
        thr_deg = np.maximum(5 * np.median(deg / scale) * scale, floor_deg)  # a view's image noise: its own σ
        thr_mm = np.maximum(5 * np.median(mm / scale) * scale, floor_mm)
        ratio = np.maximum(deg / thr_deg, mm / thr_mm)
        k = int(np.argmax(ratio))
        if ratio[k] <= 1.0:
            break
        rejected[d.names[k]] = (f"robot pose disagrees with the image: {deg[k]:.3f}° and {mm[k]:.2f} mm from the pose "
                                f"the fitted chain implies (limit {thr_deg[k]:.3f}°, {thr_mm[k]:.2f} mm)")
        d = _keep(d, np.arange(len(d.names)) != k)
        fit = _fit(setup, d, fit.lens if free else lens, fit.X, fit.Y, sig, free)
        budget -= 1
    return d, fit


def _reorder(cov6: np.ndarray) -> np.ndarray:
    """[ω, τ] -> [τ, ω]."""
    p = [3, 4, 5, 0, 1, 2]
    return cov6[np.ix_(p, p)]


def _check_inputs(setup, views, poses, square):
    if setup not in SETUPS:
        raise ValueError(f"setup must be one of {', '.join(SETUPS)}, got {setup!r}")
    if not square > 0:
        raise ValueError(f"square must be a positive size in metres, got {square}")
    missing = [v.name for v in views if v.name not in poses]
    if missing:
        raise ValueError(f"no robot pose for {', '.join(missing[:5])}")


def calibrate_handeye(views, poses: dict, setup: str, lens: Lens, square: float, *, pattern_size=None,
                      free_intrinsics: bool = False, sigma_rot_deg: float = DEFAULT_SIGMA_ROT_DEG,
                      sigma_t_mm: float = DEFAULT_SIGMA_T_MM, rng: np.random.Generator | None = None,
                      rejected: dict | None = None, halves: bool = True) -> HandEyeResult:
    """Hand-eye calibration from board views and the robot's poses (module docstring).

    views : sequence of :class:`~aicalib_tf.calib.fit.View` (corners (N, 2) px, ids (N, 2) (col, row)).
    poses : {view name: (4, 4) T_base_flange, metres}. lens : the camera (the start when
    ``free_intrinsics``). square : the board's square, metres. pattern_size : (cols, rows) of a
    chessboard, whose 180° (and, square, 90°) turns a detector may read either way; None for a
    board without symmetry (ChArUco). sigma_rot_deg, sigma_t_mm : the robot's σ per axis.
    rejected : views already left out {name: reason}, extended here.
    Raises :class:`CalibrationError` with fewer than 3 usable views or rotations about one axis.
    """
    from aicalib_tf.calib.handeye.quality import assess, check_spread

    _check_inputs(setup, views, poses, square)
    rng = rng if rng is not None else np.random.default_rng(0)
    rejected = {} if rejected is None else rejected
    flips = board_flips(pattern_size, square) if pattern_size is not None else [np.eye(4)]
    d = _pnp_views(views, poses, lens, square, flips, rejected)
    if len(d.names) < 3:
        raise CalibrationError(f"fewer than 3 usable views ({len(d.names)}); hand-eye needs at least 3 with robot poses")
    check_spread(chain_G(setup, d.A), setup, strict=True)
    try:
        X0, Y0, inl, order = robust_start(chain_G(setup, d.A), d.Cs, rng)
    except ValueError as exc:
        raise CalibrationError(str(exc)) from None
    for k in np.flatnonzero(~inl):
        deg, m = chain_discrepancy(chain_G(setup, d.A[[k]]), X0, d.Cs[[k], order[k]], Y0)
        rejected[d.names[k]] = (f"robot pose disagrees with the image: the chain is {math.degrees(deg[0]):.2f}° and "
                                f"{1e3 * m[0]:.1f} mm off the consensus of {int(inl.sum())} views")
    order = order[inl]
    d = _keep(d, inl)
    _apply_order(d, order, flips)
    d.scale = _corner_scale(d, lens)
    sig = (_sigma_px(d, lens), math.radians(sigma_rot_deg), sigma_t_mm * 1e-3)
    fit = _fit(setup, d, lens, X0, Y0, sig, free_intrinsics)
    d, fit = _outlier_loop(setup, d, lens, fit, sig, free_intrinsics, rejected)
    deg, mm = _implied(setup, d.A, fit.X, fit.Y, _repnp(d, fit.lens))
    C = inv(fit.X)[None] @ inv(chain_G(setup, fit.A)) @ fit.Y[None]
    result = HandEyeResult(setup, fit.X, fit.Y, _reorder(fit.cov[:6, :6]), _reorder(fit.cov[6:12, 6:12]), fit.lens,
                           bool(free_intrinsics), tuple(d.names), fit.per_view_rms, deg, mm, fit.correction_deg,
                           fit.correction_mm, d.A, C, dict(rejected), sig[0], sigma_rot_deg, sigma_t_mm, fit.rms,
                           fit.chi2)
    half_fit = (lambda mask: _fit(setup, _keep(d, mask), fit.lens, fit.X, fit.Y, sig, False)) if halves else None
    from dataclasses import replace

    return replace(result, quality=assess(result, half_fit))
