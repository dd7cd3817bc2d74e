"""Calibrate a rig of cameras: each lens as for one camera, then one joint fit of every lens and pose.

Input: per camera, :class:`~aicalib_tf.calib.fit.View` objects named by their *frame*: views of two
cameras with one name were taken at the same instant (a pair), so they share the board's pose.

1. Each camera is calibrated alone (:func:`~aicalib_tf.calib.fit.calibrate_camera`: the lens model
   chosen on held-out views unless forced, outlier views rejected; a circular fisheye with its image
   circle, which the joint fit's calibration of that camera keeps).
2. The cameras are placed from the frames they share (:func:`place_cameras`): camera 0 is the
   reference; the others are reached through the pair with the most shared frames (so a camera
   that never shares a frame with camera 0 is placed through another one). Each shared frame gives
   one estimate of the relative pose; the medoid of the estimates starts the fit.
3. One least-squares fit over every camera and frame (:mod:`aicalib_tf.calib.rig.bundle`). A frame
   seen by two cameras ties them through the board's pose, whichever corners each sees: partial
   boards with board ids count. A view with ids relative to its visible grid (a board larger than
   the frame) keeps a pose of its own and serves its camera's lens only.
4. Outlier frames (a pair whose cameras do not agree on the board, e.g. the board moved between the
   two exposures) are rejected one at a time, worst first, by the one-camera rule
   (:func:`~aicalib_tf.calib.fit.outlier_threshold` on the frames' RMS), at most a third.

Quality (epipolar errors on held-out pairs, baseline and rotation with σ) is in
:mod:`aicalib_tf.calib.rig.quality`.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from aicalib_tf.calib.bundle import CalibrationError
from aicalib_tf.calib.fit import Calibration, calibrate_camera, outlier_threshold
from aicalib_tf.calib.rig.bundle import Observation, RigFit, rig_adjust
from aicalib_tf.calib.rig.result import RigCalibration, relative_flags, rig_result
from aicalib_tf.geometry.pattern import board_points, check_lattice
from aicalib_tf.geometry.rectify import compose, invert, relative_pose

__all__ = ["RigCalibration", "calibrate_rig", "place_cameras", "MIN_SHARED_VIEWS", "frame_groups", "fit_rig",
           "relative_flags", "pose_vector", "joint_start"]

MIN_SHARED_VIEWS = 3  # frames two cameras must share for one to be placed from the other


def _rt(p) -> tuple[np.ndarray, np.ndarray]:
    """(R (3, 3), t (3,)) of a 6-vector (rvec, tvec)."""
    return cv2.Rodrigues(np.asarray(p[:3], np.float64).reshape(3, 1))[0], np.asarray(p[3:], np.float64)


def pose_vector(R, t) -> np.ndarray:
    """(6,) rvec, tvec of the transform X -> R·X + t."""
    return np.concatenate([cv2.Rodrigues(np.asarray(R, np.float64))[0].ravel(), np.asarray(t, np.float64).ravel()])


def _medoid_pose(estimates: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """The estimate (R, t) closest to all others (angles in rad plus translations relative to their
    median length), as a 6-vector: robust to a few frames whose cameras disagree."""
    scale = max(float(np.median([np.linalg.norm(t) for _, t in estimates])), 1e-12)
    cost = [sum(np.linalg.norm(cv2.Rodrigues(Ra @ Rb.T)[0]) + np.linalg.norm(ta - tb) / scale for Rb, tb in estimates)
            for Ra, ta in estimates]
    return pose_vector(*estimates[int(np.argmin(cost))])


def place_cameras(cals: list[Calibration], names: list[str]) -> np.ndarray:
    """Start poses (C, 6) of every camera from camera 0 (row 0 zero), from the frames they share.

    cals : each camera's own calibration (its used, absolute-id views and their poses). Raises
    :class:`CalibrationError` when no two cameras share a frame, or naming a camera that shares
    fewer than :data:`MIN_SHARED_VIEWS` frames with every placed camera.
    """
    poses = [{n: (r, t) for n, r, t, rel in zip(c.views, c.rvecs, c.tvecs, relative_flags(c)) if not rel} for c in cals]
    shared = {(i, j): sorted(set(poses[i]) & set(poses[j])) for i in range(len(cals)) for j in range(len(cals)) if i != j}
    if not any(shared.values()):
        raise CalibrationError("the cameras never see the board at the same time: no frame has a board found in two "
                               "cameras, so nothing ties them together (are the images paired right?)")
    placed, out = {0: (np.eye(3), np.zeros(3))}, np.zeros((len(cals), 6))
    while len(placed) < len(cals):
        best = max(((i, j) for i in placed for j in range(len(cals)) if j not in placed), key=lambda p: len(shared[p]))
        i, j = best
        if len(shared[best]) < MIN_SHARED_VIEWS:
            left = [names[k] for k in range(len(cals)) if k not in placed]
            counts = ", ".join(f"{names[k]}: {max(len(shared[(p, k)]) for p in placed)}" for k in range(len(cals)) if k not in placed)
            raise CalibrationError(f"camera{'s' if len(left) > 1 else ''} {', '.join(left)} share{'' if len(left) > 1 else 's'} "
                                   f"too few frames with the placed cameras to be placed (need {MIN_SHARED_VIEWS}; {counts})")
        est = [relative_pose(*poses[i][f], *poses[j][f]) for f in shared[best]]
        R_ji, t_ji = _rt(_medoid_pose(est))
        placed[j] = compose(R_ji, t_ji, *placed[i])
        out[j] = pose_vector(*placed[j])
    return out


def frame_groups(cals: list[Calibration]) -> tuple[list[str], list[tuple[int, str]]]:
    """Board poses of the joint fit: (frame names with absolute ids, [(camera, view name)] of relative views).

    Each absolute-id frame is one board pose shared by the cameras that used it; each relative view
    gets a pose of its own."""
    frames, solo = [], []
    for k, c in enumerate(cals):
        for n, rel in zip(c.views, relative_flags(c)):
            if rel:
                solo.append((k, n))
            elif n not in frames:
                frames.append(n)
    return frames, solo


def _board_in_cam0(cam_pose, cal: Calibration, i: int) -> np.ndarray:
    """(6,) the board pose of ``cal``'s view i in camera 0's frame, given that camera's pose (R, t) from camera 0."""
    return pose_vector(*compose(*invert(*cam_pose), cv2.Rodrigues(cal.rvecs[i])[0], cal.tvecs[i]))


def joint_start(cals, extr, frames, solo, views_by_cam, square_size):
    """(observations, start board poses (G, 6), group names) for :func:`rig_adjust`."""
    obs, poses, names = [], [], []
    by_name = [{v.name: v for v in vs} for vs in views_by_cam]
    cam_pose = [_rt(e) for e in extr]
    absolute = [{n: i for i, (n, rel) in enumerate(zip(c.views, relative_flags(c))) if not rel} for c in cals]
    for g, f in enumerate(frames):
        seen = [k for k in range(len(cals)) if f in absolute[k]]
        for k in seen:
            v = by_name[k][f]
            obs.append(Observation(k, g, board_points(v.ids, square_size), v.corners, f, getattr(v, "sigmas", None)))
        poses.append(_board_in_cam0(cam_pose[seen[0]], cals[seen[0]], absolute[seen[0]][f]))
        names.append(f)
    for k, n in solo:
        v = by_name[k][n]
        obs.append(Observation(k, len(poses), board_points(v.ids, square_size), v.corners, n, getattr(v, "sigmas", None)))
        poses.append(_board_in_cam0(cam_pose[k], cals[k], cals[k].views.index(n)))
        names.append(f"{n} ({k})")
    return obs, np.array(poses), names


def _group_rms(fit: RigFit, obs: list[Observation], n_groups: int) -> tuple[np.ndarray, list[tuple[int, ...]]]:
    """(per board pose RMS px (G,), per board pose the cameras that saw it)."""
    sq, cnt, cams = np.zeros(n_groups), np.zeros(n_groups), [[] for _ in range(n_groups)]
    for o, r in zip(obs, fit.residuals):
        sq[o.group] += float(np.sum(r * r))
        cnt[o.group] += len(r)
        cams[o.group].append(o.camera)
    return np.sqrt(sq / np.maximum(cnt, 1)), [tuple(sorted(c)) for c in cams]


def _drop_group(obs: list[Observation], poses: np.ndarray, g: int) -> tuple[list[Observation], np.ndarray]:
    """The observations and poses without board pose g (groups renumbered)."""
    out = [dataclasses.replace(o, group=o.group - (o.group > g)) for o in obs if o.group != g]
    return out, np.delete(poses, g, axis=0)


def fit_rig(models, intr, extr, obs, poses, names, *, reject_outliers=True) -> tuple[RigFit, list, list, np.ndarray, dict]:
    """The joint fit with outlier frames rejected: (fit, observations, group names, group RMS, rejected)."""
    rejected = {}
    fit = rig_adjust(models, obs, intr, extr, poses)
    max_drop = sum(len(c) > 1 for c in _group_rms(fit, obs, len(names))[1]) // 3
    while reject_outliers and max_drop > 0:
        rms, cams = _group_rms(fit, obs, len(names))
        shared = [g for g in range(len(names)) if len(cams[g]) > 1]
        if len(shared) <= MIN_SHARED_VIEWS:
            break
        thr = outlier_threshold(rms[shared])
        worst = max(shared, key=lambda g: rms[g])
        if rms[worst] <= thr:
            break
        rejected[names[worst]] = (f"outlier pair: RMS {rms[worst]:.2f} px > {thr:.2f} px in the joint fit "
                                  "(the cameras disagree on the board: moved between exposures, or a wrong detection)")
        obs, poses = _drop_group(obs, fit.poses, worst)
        names = names[:worst] + names[worst + 1:]
        max_drop -= 1
        fit = rig_adjust(models, obs, fit.intrinsics, fit.extrinsics, poses)
    return fit, obs, names, _group_rms(fit, obs, len(names))[0], rejected


def _single(views, name, pattern_size, square_size, size, model, square_unit, circle=None) -> Calibration:
    """One camera's own calibration (with its image ``circle``, or None), its views' relative flags kept in
    ``meta["relative_views"]``."""
    try:
        cal = calibrate_camera(views, pattern_size, square_size, size, model=model, square_unit=square_unit,
                               image_circle=circle)
    except CalibrationError as exc:
        raise CalibrationError(f"{name}: {exc}") from exc
    rel = {v.name: bool(v.relative) for v in views}
    return dataclasses.replace(cal, meta=dict(cal.meta, relative_views=tuple(rel[n] for n in cal.views)))


def calibrate_rig(views, pattern_size, square_size: float, image_sizes, *, names=None, models="auto",
                  reject_outliers: bool = True, square_unit: str = "", meta: dict | None = None,
                  image_circles=None) -> RigCalibration:
    """Calibrate a rig of C >= 2 cameras (module docstring).

    views : C sequences of :class:`View`, named by frame. image_sizes : C (width, height), or one
    for all. names : C camera names (default cam0, cam1, ...). models : "auto", a lens model name,
    or C of them. image_circles : C image circles
    (:class:`~aicalib_tf.geometry.image_circle.ImageCircle` or None each; default none): each
    camera's calibration keeps its own and uses it as a single camera's does. Raises :class:`CalibrationError` naming the camera that cannot be calibrated or
    placed, or saying that the cameras never see the board at once; ValueError for bad arguments.
    """
    pattern_size = check_lattice(pattern_size)
    C = len(views)
    if C < 2:
        raise ValueError(f"a rig needs at least 2 cameras, got {C}")
    names = [f"cam{k}" for k in range(C)] if names is None else list(names)
    sizes = [tuple(image_sizes)] * C if np.ndim(image_sizes) == 1 else [tuple(s) for s in image_sizes]
    models = [models] * C if isinstance(models, str) else list(models)
    circles = [None] * C if image_circles is None else list(image_circles)
    if len(names) != C or len(sizes) != C or len(models) != C or len(circles) != C or len(set(names)) != C:
        raise ValueError(f"{C} cameras need {C} distinct names, image sizes, models and image circles; got {names}, "
                         f"{sizes}, {models}, {circles}")
    views = [list(v) for v in views]
    cals = [_single(v, n, pattern_size, square_size, s, m, square_unit, c)
            for v, n, s, m, c in zip(views, names, sizes, models, circles)]
    extr = place_cameras(cals, names)
    frames, solo = frame_groups(cals)
    obs, poses, groups = joint_start(cals, extr, frames, solo, views, square_size)
    lens_models = [c.model for c in cals]
    fit, obs, groups, g_rms, rejected = fit_rig(lens_models, [c.lens.intrinsics() for c in cals], extr, obs, poses,
                                                groups, reject_outliers=reject_outliers)
    for k, c in enumerate(cals):
        rejected.update({f"{names[k]}/{n}": why for n, why in c.rejected.items()})
    rig = rig_result(fit, obs, groups, g_rms, cals, names, pattern_size, square_size, square_unit, rejected,
                     dict(meta or {}))
    return dataclasses.replace(rig, single=tuple(cals))
