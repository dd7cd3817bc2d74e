"""Whether to trust a hand-eye calibration: σ, the rotations' spread, two halves' agreement (numpy).

* σ of the transform (from the joint fit's covariance): translation mm and rotation degrees.
* Spread: the RMS rotation of the robot's motions about their principal axes
  (:func:`~aicalib_tf.calib.handeye.solve.rotation_spread`). Hand-eye needs rotations about at least two
  non-parallel axes: a second axis under ``MIN_SPREAD_DEG`` is refused (the transform is not
  fixed), under ``WARN_SPREAD_DEG`` it is a warning naming the axis to turn about.
* Halves: the used views split into even and odd, each fitted alone (intrinsics held), and the two
  transforms compared: their difference in mm and degrees and its Mahalanobis distance under the two
  halves' covariances (they agree when d² ≤ 22.5, χ²₆ at 0.999).

``status`` is "ok" without warnings, else "check".
"""

from __future__ import annotations

import math

import numpy as np

from aicalib_tf.calib.bundle import CalibrationError
from aicalib_tf.calib.handeye.solve import inv, rotation_angle, rotation_spread

__all__ = ["MIN_SPREAD_DEG", "WARN_SPREAD_DEG", "check_spread", "assess", "axis_name"]

MIN_SPREAD_DEG = 1.0
WARN_SPREAD_DEG = 10.0
MAX_SIGMA_DEG, MAX_SIGMA_MM = 0.1, 1.0  # σ of the transform above these: a warning
HALVES_D2 = 22.46  # χ²₆ at 0.999


def axis_name(v) -> str:
    """'x', 'y' or 'z' for a unit vector within ~25° of an axis, else its components."""
    v = np.asarray(v, np.float64)
    k = int(np.argmax(np.abs(v)))
    if abs(v[k]) > 0.9:
        return "xyz"[k]
    return "(" + ", ".join(f"{c:.2f}" for c in v) + ")"


def check_spread(G, setup: str, *, strict: bool = False) -> tuple[dict, list[str]]:
    """({"rms_deg": [3], "axes": 3×3 rows}, warnings) of the robot's motions G (V, 4, 4) (module docstring).

    strict : raise :class:`CalibrationError` when the rotations are about one axis only."""
    spread, axes = rotation_spread(G)
    frame = "flange" if setup == "eye-in-hand" else "base"
    info = {"rms_deg": spread.tolist(), "axes": axes.T.tolist(), "frame": frame}
    main, weak = axis_name(axes[:, 0]), axis_name(axes[:, 1])
    if spread[1] < MIN_SPREAD_DEG:
        msg = (f"all rotations of the robot are about one axis (the {frame}'s {main} axis; the next turns "
               f"{spread[1]:.2f}° RMS): add views turned about the {frame}'s {weak} axis by 15° or more")
        if strict:
            raise CalibrationError(msg)
        return info, [msg]
    warnings = []
    if spread[1] < WARN_SPREAD_DEG:
        warnings.append(f"little rotation about the {frame}'s {weak} axis ({spread[1]:.1f}° RMS): add views turned "
                        f"about it by 15° or more")
    return info, warnings


def _difference(X1, X2) -> np.ndarray:
    """[τ (m), ω (rad)] from X1 to X2 (ω = log(R2 R1ᵀ))."""
    import cv2

    w = cv2.Rodrigues(np.ascontiguousarray(X2[:3, :3] @ X1[:3, :3].T))[0].ravel()
    return np.concatenate([X2[:3, 3] - X1[:3, 3], w])


def _halves(result, half_fit) -> dict:
    V = len(result.views)
    if half_fit is None or V < 6:
        return {"note": "too few views to compare halves" if half_fit is not None else "not run"}
    mask = np.arange(V) % 2 == 0
    try:
        f1, f2 = half_fit(mask), half_fit(~mask)
    except (CalibrationError, ValueError, np.linalg.LinAlgError) as exc:
        return {"note": f"a half could not be fitted: {exc}"}
    p = [3, 4, 5, 0, 1, 2]
    S = f1.cov[:6, :6][np.ix_(p, p)] + f2.cov[:6, :6][np.ix_(p, p)]
    e = _difference(f1.X, f2.X)
    d2 = float(e @ np.linalg.pinv(S) @ e)
    D = inv(f1.X) @ f2.X
    return {"diff_deg": float(math.degrees(rotation_angle(D[:3, :3]))), "diff_mm": float(1e3 * np.linalg.norm(e[:3])),
            "d2": d2, "agree": bool(d2 <= HALVES_D2), "views": [int(mask.sum()), int((~mask).sum())]}


def assess(result, half_fit=None) -> dict:
    """The verdict of a :class:`~aicalib_tf.calib.handeye.calibrate.HandEyeResult`. half_fit : mask (V,) bool ->
    a :class:`~aicalib_tf.calib.handeye.fit.JointFit` of those views, or None to skip the halves."""
    from aicalib_tf.calib.handeye.fit import chain_G

    s_mm, s_deg = result.std_X
    spread, warnings = check_spread(chain_G(result.setup, result.A), result.setup)
    halves = _halves(result, half_fit)
    if halves.get("agree") is False:
        warnings.append(f"the two halves of the views disagree by {halves['diff_deg']:.3f}° and {halves['diff_mm']:.2f} mm "
                        f"(d² {halves['d2']:.1f} > {HALVES_D2}): look for a robot pose or view that does not fit")
    if s_deg.max() > MAX_SIGMA_DEG or s_mm.max() > MAX_SIGMA_MM:
        warnings.append(f"σ of the transform is large ({s_deg.max():.3f}°, {s_mm.max():.2f} mm): add views with "
                        "more rotation, or the board nearer")
    if result.chi2 > 4.0:
        warnings.append(f"the residuals are {math.sqrt(result.chi2):.1f}× what the stated σ explain: the robot's poses "
                        "are noisier than --robot-sigma says, or the board is not rigid")
    return {"status": "ok" if not warnings else "check", "sigma_mm": s_mm.tolist(), "sigma_deg": s_deg.tolist(),
            "spread": spread, "halves": halves, "warnings": warnings, "rejected": len(result.rejected)}
