"""A calibrated rig (:class:`RigCalibration`) and how a joint fit becomes one: per-camera calibrations and poses."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import cv2
import numpy as np

from aicalib_tf.calib.bundle import param_names
from aicalib_tf.calib.fit import Calibration
from aicalib_tf.calib.rig.bundle import Observation, RigFit, global_layout
from aicalib_tf.geometry.lens import Lens
from aicalib_tf.geometry.rectify import compose, invert

__all__ = ["RigCalibration", "rig_result", "camera_calibration", "relative_flags"]


@dataclass(frozen=True)
class RigCalibration:
    """A calibrated rig.

    names : camera names (camera 0 first: the reference). cameras : one :class:`Calibration` per
    camera (its lens from the joint fit, its views' poses, per-view RMS, the intrinsics covariance).
    R : (C, 3, 3), T : (C, 3): X_k = R_k·X_0 + T_k (camera 0: identity, 0); T in ``square_unit``.
    pose_covariance : (C, 6, 6) covariance of each camera's (rvec, tvec) from camera 0 (rad, unit).
    frames : names of the frames seen by two or more cameras and kept; frame_rms : (F,) px, RMS
    over all their corners; frame_cameras : per frame, the indices of the cameras that saw it.
    rejected : {"camera/frame" or "frame": reason}. rms : px over every corner of the joint fit.
    quality : filled by :func:`aicalib_tf.calib.rig.quality.assess_rig`. meta : provenance.
    single : each camera's own calibration (alone, before the joint fit), for the sanity checks
    of :mod:`aicalib_tf.calib.rig.sanity`; not written to the files.
    """

    names: tuple[str, ...]
    cameras: tuple[Calibration, ...]
    R: np.ndarray
    T: np.ndarray
    pose_covariance: np.ndarray
    frames: tuple[str, ...]
    frame_rms: np.ndarray
    frame_cameras: tuple[tuple[int, ...], ...]
    rms: float
    pattern_size: tuple[int, int]
    square_size: float
    square_unit: str = ""
    rejected: dict = field(default_factory=dict)
    quality: dict = field(default_factory=dict)
    meta: dict = field(default_factory=dict)
    single: tuple = ()

    @property
    def lenses(self) -> tuple[Lens, ...]:
        """Each camera's :class:`~aicalib_tf.geometry.lens.Lens`."""
        return tuple(c.lens for c in self.cameras)

    def baseline(self, k: int = 1) -> float:
        """|T_k|: the distance from camera 0 to camera k, in ``square_unit``."""
        return float(np.linalg.norm(self.T[k]))

    def pair(self, i: int, j: int) -> tuple[np.ndarray, np.ndarray]:
        """(R, T) of camera j from camera i: X_j = R·X_i + T."""
        return compose(self.R[j], self.T[j], *invert(self.R[i], self.T[i]))


def relative_flags(cal: Calibration) -> tuple[bool, ...]:
    """Per used view of a camera's calibration in a rig: are its ids relative to the visible grid?
    (``meta["relative_views"]``; all False when absent)."""
    return tuple(cal.meta.get("relative_views") or (False,) * len(cal.views))


def _R(rvec) -> np.ndarray:
    return cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))[0]


def camera_calibration(fit: RigFit, obs: list[Observation], k: int, own: Calibration) -> Calibration:
    """Camera k's :class:`Calibration` from the joint fit: its lens, its views' poses (board to camera k)
    and RMS, its block of the covariance; model table and rejected views from its own calibration ``own``."""
    sl = global_layout(fit.models)[0][k]
    cov = None if fit.covariance is None else fit.covariance[sl, sl].copy()
    lens = Lens.from_intrinsics(fit.models[k], fit.intrinsics[k], own.image_size)
    Rk, tk = _R(fit.extrinsics[k, :3]), fit.extrinsics[k, 3:]
    mine = [(o, r) for o, r in zip(obs, fit.residuals) if o.camera == k]
    rvecs, tvecs = [], []
    for o, _ in mine:
        R, t = compose(Rk, tk, _R(fit.poses[o.group, :3]), fit.poses[o.group, 3:])
        rvecs.append(cv2.Rodrigues(R)[0].ravel())
        tvecs.append(t)
    sq = np.concatenate([np.sum(r * r, axis=1) for _, r in mine])
    std = {} if cov is None else dict(zip(param_names(lens.model), np.sqrt(np.maximum(np.diag(cov), 0.0)).tolist()))
    rel = dict(zip(own.views, relative_flags(own)))
    return dataclasses.replace(
        own, K=lens.K, dist=lens.dist, rms=float(np.sqrt(np.mean(sq))), views=tuple(o.name for o, _ in mine),
        rvecs=np.array(rvecs), tvecs=np.array(tvecs),
        per_view_rms=np.array([np.sqrt(np.mean(np.sum(r * r, axis=1))) for _, r in mine]),
        corner_counts=np.array([len(o.px) for o, _ in mine]), std=std, covariance=cov, quality={},
        meta=dict(own.meta, relative_views=tuple(rel.get(o.name, False) for o, _ in mine), fit="joint rig fit"))


def _pose_covariance(fit: RigFit) -> np.ndarray:
    """(C, 6, 6) covariance of each camera's (rvec, tvec) from camera 0 (zeros for camera 0)."""
    out = np.zeros((len(fit.models), 6, 6))
    if fit.covariance is None:
        return out
    for k, sl in enumerate(global_layout(fit.models)[1]):
        if sl is not None:
            out[k] = fit.covariance[sl, sl]
    return out


def rig_result(fit: RigFit, obs, groups, g_rms, cals, names, pattern_size, square_size, square_unit,
               rejected, meta) -> RigCalibration:
    """The :class:`RigCalibration` of a joint fit: groups are the board poses' names, g_rms their RMS (px),
    cals each camera's own calibration."""
    # each camera's file names the marker board, as a single camera's does (check and handeye read it there)
    board = {"board": meta["board"]} if meta.get("board") else {}
    cams = [camera_calibration(fit, obs, k, dataclasses.replace(c, meta=dict(c.meta, **board)))
            for k, c in enumerate(cals)]
    seen = [sorted({o.camera for o in obs if o.group == g}) for g in range(len(groups))]
    shared = [g for g in range(len(groups)) if len(seen[g]) > 1]
    R = np.stack([_R(e[:3]) for e in fit.extrinsics])
    return RigCalibration(
        names=tuple(names), cameras=tuple(cams), R=R, T=fit.extrinsics[:, 3:].copy(),
        pose_covariance=_pose_covariance(fit), frames=tuple(groups[g] for g in shared),
        frame_rms=np.asarray(g_rms)[shared], frame_cameras=tuple(tuple(seen[g]) for g in shared), rms=fit.rms,
        pattern_size=tuple(pattern_size), square_size=float(square_size), square_unit=square_unit,
        rejected=dict(rejected), meta=dict(meta, fit_note=fit.note) if fit.note else dict(meta))
