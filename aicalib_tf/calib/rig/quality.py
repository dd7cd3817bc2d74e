"""How good is a rig: rectified epipolar errors in-sample and on held-out pairs, baseline and rotation with σ.

Epipolar error: a corner seen by cameras i and j in one frame, rectified with the pair's
:class:`~aicalib_tf.geometry.rectify.Rectification`, should land on the same row in both images
(the same column for a vertical rig); Δy = y_i − y_j in rectified px. In-sample uses the fit of
every frame. Held-out (leave-pairs-out) splits the shared frames into k folds (frames f, f+k, ...);
each fold's frames are left out of a joint refit (warm-started from the full fit) and their Δy
computed with it, so the figure says how well the rig rectifies pairs it has not seen.

σ of the baseline |T| and of the rotation come from the joint fit's covariance (σ²·(JᵀJ)⁻¹): the
rotation's σ is the RMS length of its error vector, sqrt(trace of the rvec covariance), in degrees.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from aicalib_tf.calib.quality import assess
from aicalib_tf.calib.rig.fit import RigCalibration, frame_groups, joint_start, pose_vector
from aicalib_tf.calib.rig.bundle import rig_adjust
from aicalib_tf.geometry.lens import Lens
from aicalib_tf.geometry.rectify import Rectification, compose, invert, rectified_points, rectify_pair

__all__ = ["assess_rig", "pair_rectification", "epipolar_deltas", "held_out_deltas", "baseline_std", "rotation_std_deg",
           "MAX_FOLDS", "rig_verdict"]

MAX_FOLDS = 5  # leave-pairs-out folds (fewer when there are fewer shared frames)
GOOD_PX, FAIR_PX = 0.25, 1.0  # held-out rectified |Δy| RMS (px) of a good rig and of a usable one (block matchers want rows within ~1 px)


def pair_rectification(lenses, R, T, i: int = 0, j: int = 1) -> Rectification:
    """The rectification of cameras (i, j) of a rig with poses R (C, 3, 3), T (C, 3) from camera 0."""
    Rij, Tij = compose(R[j], T[j], *invert(R[i], T[i]))
    return rectify_pair(lenses[i], lenses[j], Rij, Tij)


def epipolar_deltas(lens_i: Lens, lens_j: Lens, rect: Rectification, views_i, views_j, frames=None) -> dict:
    """{frame: Δ (M,) rectified px} over the corners both cameras saw in each frame (both views named alike).

    Δ is y_i − y_j (x_i − x_j for a vertical rig). frames : the frame names to use (default all shared)."""
    by_j = {v.name: v for v in views_j}
    axis = 0 if rect.vertical else 1
    out = {}
    for vi in views_i:
        vj = by_j.get(vi.name)
        if vj is None or (frames is not None and vi.name not in frames) or vi.relative or vj.relative:
            continue
        _, a, b = np.intersect1d(vi.ids[:, 1] * 10000 + vi.ids[:, 0], vj.ids[:, 1] * 10000 + vj.ids[:, 0],
                                 return_indices=True)
        if not len(a):
            continue
        pi = rectified_points(lens_i, rect.R1, rect.P1, vi.corners[a])
        pj = rectified_points(lens_j, rect.R2, rect.P2, vj.corners[b])
        d = pi[:, axis] - pj[:, axis]
        out[vi.name] = d[np.isfinite(d)]
    return out


def _rms(d) -> float:
    d = np.concatenate(list(d)) if isinstance(d, (list, tuple)) else np.asarray(d)
    return float(np.sqrt(np.mean(d * d))) if d.size else float("nan")


def _used(rig: RigCalibration, views) -> list[list]:
    """Per camera, the given views that the rig used (by name), in the rig's order."""
    out = []
    for cam, vs in zip(rig.cameras, views):
        by = {v.name: v for v in vs}
        out.append([by[n] for n in cam.views if n in by])
    return out


def held_out_deltas(rig: RigCalibration, views, pairs, folds: int = MAX_FOLDS) -> tuple[dict, int]:
    """({(i, j): {frame: Δ (M,) px}} on held-out frames, folds used); ({}, 0) with fewer than 4 shared frames."""
    used = _used(rig, views)
    shared = list(rig.frames)
    k = min(folds, len(shared))
    if k < 4:
        return {}, 0
    extr = np.stack([pose_vector(rig.R[c], rig.T[c]) for c in range(len(rig.names))])
    frames, solo = frame_groups(list(rig.cameras))
    obs, poses, names = joint_start(list(rig.cameras), extr, frames, solo, used, rig.square_size)
    out = {p: {} for p in pairs}
    models = [c.model for c in rig.cameras]
    for f in range(k):
        held = set(shared[f::k])
        keep = [g for g, n in enumerate(names) if n not in held]
        renum = {g: i for i, g in enumerate(keep)}
        sub = [dataclasses.replace(o, group=renum[o.group]) for o in obs if o.group in renum]
        fit = rig_adjust(models, sub, [c.lens.intrinsics() for c in rig.cameras], extr, poses[keep], max_nfev=60,
                         covariance=False)
        lenses = [Lens.from_intrinsics(m, v, c.image_size) for m, v, c in zip(models, fit.intrinsics, rig.cameras)]
        R = np.stack([cv2.Rodrigues(e[:3].reshape(3, 1))[0] for e in fit.extrinsics])
        for i, j in pairs:
            rect = pair_rectification(lenses, R, fit.extrinsics[:, 3:], i, j)
            out[(i, j)].update(epipolar_deltas(lenses[i], lenses[j], rect, used[i], used[j], held))
    return out, k


def baseline_std(rig: RigCalibration, k: int = 1) -> float:
    """1σ of |T_k| (square units) from the joint fit's covariance."""
    t = rig.T[k]
    u = t / max(np.linalg.norm(t), 1e-300)
    return float(np.sqrt(max(u @ rig.pose_covariance[k][3:, 3:] @ u, 0.0)))


def rotation_std_deg(rig: RigCalibration, k: int = 1) -> float:
    """1σ of camera k's rotation from camera 0, degrees: sqrt(trace of its rvec covariance)."""
    return float(np.degrees(np.sqrt(max(np.trace(rig.pose_covariance[k][:3, :3]), 0.0))))


def _pair_summary(rig, i, j, inside: dict, held: dict) -> dict:
    Rij, Tij = rig.pair(i, j)
    angle = float(np.degrees(np.linalg.norm(cv2.Rodrigues(Rij)[0])))
    frames = sorted(inside)
    return {
        "cameras": [rig.names[i], rig.names[j]], "pairs": len(frames),
        "in_sample_rms_px": _rms([inside[f] for f in frames]) if frames else float("nan"),
        "held_out_rms_px": _rms([held[f] for f in held]) if held else None,
        "per_frame": {f: {"in_sample_px": _rms(inside[f]), "held_out_px": _rms(held[f]) if f in held else None,
                          "corners": int(inside[f].size)} for f in frames},
        "baseline": float(np.linalg.norm(Tij)), "baseline_std": baseline_std(rig, j) if i == 0 else None,
        "rotation_deg": angle, "rotation_std_deg": rotation_std_deg(rig, j) if i == 0 else None,
    }


def rig_verdict(pair: dict, unit: str = "") -> str:
    """One line on a pair: how well it rectifies (held-out, else in-sample), the baseline and rotation with σ."""
    held = pair["held_out_rms_px"]
    x = held if held is not None else pair["in_sample_rms_px"]
    word = "good" if x <= GOOD_PX else "fair" if x <= FAIR_PX else "poor (check the pairing and that the shots were simultaneous)"
    where = f"{held:.3f} px on held-out pairs, {pair['in_sample_rms_px']:.3f} px in-sample" if held is not None else \
        f"{pair['in_sample_rms_px']:.3f} px in-sample (too few pairs to hold some out)"
    sb = f" ± {pair['baseline_std']:.3g}" if pair["baseline_std"] is not None else ""
    sr = f" ± {pair['rotation_std_deg']:.2g}" if pair["rotation_std_deg"] is not None else ""
    return (f"{pair['cameras'][0]}-{pair['cameras'][1]} {word}: rectified rows agree to {where} (RMS |Δy|, "
            f"{pair['pairs']} pairs); baseline {pair['baseline']:.4g}{sb} {unit}".rstrip()
            + f", rotation {pair['rotation_deg']:.3f}{sr}°")


def assess_rig(rig: RigCalibration, views, *, holdout: bool = True, folds: int = MAX_FOLDS) -> RigCalibration:
    """``rig`` with ``quality`` filled (and each camera's own quality, without its half-vs-half fit).

    views : per camera the views given to :func:`~aicalib_tf.calib.rig.fit.calibrate_rig`. quality =
    {"pairs": [one dict per pair (0, k): cameras, pairs, in_sample_rms_px, held_out_rms_px, per_frame,
    baseline, baseline_std, rotation_deg, rotation_std_deg], "folds": k, "verdict": str}.
    """
    used = _used(rig, views)
    pairs = [(0, k) for k in range(1, len(rig.names))]
    inside = {}
    for i, j in pairs:
        rect = pair_rectification(rig.lenses, rig.R, rig.T, i, j)
        inside[(i, j)] = epipolar_deltas(rig.lenses[i], rig.lenses[j], rect, used[i], used[j])
    held, k = held_out_deltas(rig, views, pairs, folds) if holdout else ({}, 0)
    summaries = [_pair_summary(rig, i, j, inside[(i, j)], held.get((i, j), {})) for i, j in pairs]
    cams = tuple(dataclasses.replace(c, quality=assess(c, u)) for c, u in zip(rig.cameras, used))
    quality = {"pairs": summaries, "folds": k, "verdict": "; ".join(rig_verdict(p, rig.square_unit) for p in summaries)}
    return dataclasses.replace(rig, cameras=cams, quality=quality)
