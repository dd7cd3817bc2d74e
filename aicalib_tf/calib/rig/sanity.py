"""Whether a rig calibration is fit to be written as a rig: the checks that catch an absurd one.

A joint fit always returns numbers. These checks say when the numbers cannot describe a real rig:

* **no baseline**: at the board's median distance, the baseline moves the board by less than
  :data:`MIN_DISPARITY_NOISE` times the corner noise between the cameras (the same images given
  for two cameras give a baseline of 1e-13);
* **unrelated frames**: more than :data:`MAX_REJECTED_SHARE` of the shared frames were rejected
  as pairs whose cameras disagree, or the kept frames' median RMS is over
  :data:`DISAGREE_FACTOR` times the worst camera's RMS alone (images paired from different
  moments, or from cameras that never saw the board together);
* **a lens made worse**: the joint fit moves a camera's fx, fy, cx or cy from its own calibration
  by more than :data:`MOVED_SIGMAS` combined standard deviations.

A rig with a problem is written with ``"status": "failed"`` and its problems in ``rig.json``;
each camera keeps its own calibration, never the joint fit's (:mod:`aicalib_tf.calib.rig.workflow`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["rig_problems", "MIN_DISPARITY_NOISE", "MAX_REJECTED_SHARE", "DISAGREE_FACTOR", "MOVED_SIGMAS"]

MIN_DISPARITY_NOISE = 2.0  # the baseline's disparity at the board (px) over the corner noise (px)
MIN_NOISE_PX = 0.05  # the corner noise is taken as at least this (px): a perfect synthetic fit is not noise-free
MAX_REJECTED_SHARE = 0.5  # of the shared frames rejected as disagreeing pairs
DISAGREE_FACTOR = 3.0  # median kept-frame RMS over the worst camera's own RMS
DISAGREE_MIN_PX = 1.0  # ... and at least this many px
MOVED_SIGMAS = 4.0  # how far (combined σ) the joint fit may move a camera's fx, fy, cx, cy
MOVED_MIN_PX = 0.5  # ... and at least this many px


def _baseline_problems(rig) -> list[str]:
    cam0 = rig.cameras[0]
    noise = max(float(np.median(cam0.per_view_rms)) if len(cam0.per_view_rms) else 0.0, MIN_NOISE_PX)
    distance = float(np.median(np.linalg.norm(cam0.tvecs, axis=1))) if len(cam0.tvecs) else float("nan")
    out = []
    for k in range(1, len(rig.names)):
        disparity = cam0.fx * rig.baseline(k) / distance
        if not np.isfinite(disparity) or disparity < MIN_DISPARITY_NOISE * noise:
            out.append(f"{rig.names[0]}-{rig.names[k]}: the baseline ({rig.baseline(k):.3g} {rig.square_unit}".rstrip()
                       + f") shifts the board by {disparity:.2g} px between the cameras, below the corner noise "
                       f"({noise:.2g} px): are both cameras given the same images?")
    return out


def _disagreement_problems(rig) -> list[str]:
    rejected = sum(1 for k, why in rig.rejected.items() if "/" not in k and str(why).startswith("outlier pair"))
    total = len(rig.frames) + rejected
    out = []
    if total and rejected / total > MAX_REJECTED_SHARE:
        out.append(f"the cameras disagree on {rejected} of {total} shared frames: are the images paired right "
                   "(taken at the same moments)?")
    if rig.single and len(rig.frame_rms):
        alone = max(float(c.rms) for c in rig.single)
        joint = float(np.median(rig.frame_rms))
        if joint > max(DISAGREE_FACTOR * alone, DISAGREE_MIN_PX):
            out.append(f"the shared frames fit to a median {joint:.2f} px in the joint fit against {alone:.2f} px for "
                       "each camera alone: the pairs do not show one board pose (wrong pairing?)")
    return out


def _moved_problems(rig) -> list[str]:
    out = []
    for name, joint, own in zip(rig.names, rig.cameras, rig.single):
        for p in ("fx", "fy", "cx", "cy"):
            a, b = float(getattr(own, p)), float(getattr(joint, p))
            sa, sb = float(own.std.get(p, 0.0)), float(joint.std.get(p, 0.0))
            sigma = float(np.hypot(sa, sb))
            if not np.isfinite(b) or (abs(b - a) > MOVED_SIGMAS * sigma and abs(b - a) > MOVED_MIN_PX):
                out.append(f"{name}: the joint fit moves {p} from {a:.1f} ± {sa:.2g} (the camera alone) to "
                           f"{b:.1f} ± {sb:.2g}")
    return out


def rig_problems(rig) -> list[str]:
    """What makes ``rig`` (a :class:`~aicalib_tf.calib.rig.result.RigCalibration`) absurd; [] when nothing does."""
    return _baseline_problems(rig) + _disagreement_problems(rig) + _moved_problems(rig)
