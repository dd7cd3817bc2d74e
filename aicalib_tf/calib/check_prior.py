"""What the field check takes from the calibration file: its corner noise, its covariance, and
whether the check can use it at all (:func:`check_fields`).

A file can be well-formed and still useless to a check: a focal length of 1e300 px, a covariance of
1e300 or one that is not positive semi-definite. Such a file is refused with the field named (a
:class:`~aicalib_tf.calib.schema.FieldError`) rather than giving NaN or a linear-algebra error.
"""

from __future__ import annotations

import math

import numpy as np

from aicalib_tf.calib.quality import lens_of
from aicalib_tf.calib.schema import FieldError

__all__ = ["corner_noise", "calibration_covariance", "check_fields", "PARAMS", "MIN_NOISE_PX", "MAX_FOCAL",
           "MIN_FOCAL", "MAX_REL_STD"]

MIN_NOISE_PX = 0.01  # floor of the calibration's corner noise per axis (reported only)
MAX_FOCAL = 1e4  # fx, fy at most this many times the image's larger side (a 0.006° field of view) ...
MIN_FOCAL = 0.01  # ... and at least this fraction of it (a 360° equidistant lens has about 1/6)
MAX_REL_STD = 0.1  # σ of fx or fy above 10% of it, or of cx, cy above 10% of the image: too uncertain to check
MAX_COEFF_VAR = 1e12  # a distortion coefficient's variance above this is not an uncertainty
PARAMS = ("fx", "fy", "cx", "cy")


def corner_noise(cal) -> tuple[float, float]:
    """(σ px per axis, degrees of freedom) of the corner noise the calibration's RMS implies.

    σ² = rms²·N / (2N − 6V − n): N corners of V views (``cal.corner_counts``, or full boards of
    ``cal.pattern_size`` when a file does not say, as an OpenCV camera.yaml), n free intrinsics.
    Floored at :data:`MIN_NOISE_PX`.
    """
    V = len(cal.views)
    counts = np.asarray(cal.corner_counts, np.float64)
    N = float(counts.sum()) if counts.size and counts.sum() > 0 else float(V * cal.pattern_size[0] * cal.pattern_size[1])
    n = 4 + np.asarray(cal.dist).size
    dof = 2 * N - 6 * V - n
    if not (dof > 0 and N > 0 and np.isfinite(cal.rms)):
        return max(float(cal.rms) / math.sqrt(2), MIN_NOISE_PX), math.inf
    return max(float(cal.rms) * math.sqrt(N / dof), MIN_NOISE_PX), dof


def calibration_covariance(cal) -> tuple[np.ndarray, str]:
    """((4+n, 4+n) covariance of [fx, fy, cx, cy, *dist], note): ``cal.covariance``, else the diagonal
    of ``cal.std``, else zeros; the note says when the file did not carry the full covariance."""
    lens = lens_of(cal)
    n = 4 + lens.dist.size
    cov = getattr(cal, "covariance", None)
    if cov is not None and np.asarray(cov).shape == (n, n) and np.all(np.isfinite(cov)):
        return np.asarray(cov, np.float64), ""
    std = getattr(cal, "std", {}) or {}
    if all(k in std and np.isfinite(std[k]) for k in PARAMS):
        from aicalib_tf.geometry.lens import COEFF_NAMES

        names = PARAMS + COEFF_NAMES[lens.model]
        sd = np.array([float(std.get(k, 0.0)) for k in names])
        with np.errstate(over="ignore"):  # a σ of 1e200 squares to inf, which check_fields refuses
            var = np.square(np.where(np.isfinite(sd), sd, 0.0))
        return np.diag(var), "the calibration file carries σ but no covariance: correlations ignored"
    return np.zeros((n, n)), ("the calibration file carries no uncertainty (e.g. an OpenCV camera.yaml): its "
                              "intrinsics are taken as exact, which flags changes more readily; check against camera.json")


def check_fields(cal) -> np.ndarray:
    """The calibration's covariance (:func:`calibration_covariance`) after checking that the check can
    use the file; raises :class:`~aicalib_tf.calib.schema.FieldError` naming the field otherwise:
    fx, fy outside [:data:`MIN_FOCAL`, :data:`MAX_FOCAL`] × the image's larger side, a principal point
    more than ten images away, a covariance that is not symmetric positive semi-definite, or an
    uncertainty too large to detect a change (σ of fx or fy above :data:`MAX_REL_STD` of it, of cx or
    cy above that fraction of the image)."""
    w, h = cal.image_size
    side = float(max(w, h))
    K = np.asarray(cal.K, np.float64)
    for name, v in (("fx", K[0, 0]), ("fy", K[1, 1])):
        if not MIN_FOCAL * side <= v <= MAX_FOCAL * side:
            raise FieldError("camera_matrix", f"{name} {v:.6g} px is not a focal length of a {w}x{h} camera "
                                              f"(expected {MIN_FOCAL * side:g} to {MAX_FOCAL * side:g} px)")
    for name, v, s in (("cx", K[0, 2], w), ("cy", K[1, 2], h)):
        if not -10 * s <= v <= 11 * s:
            raise FieldError("camera_matrix", f"{name} {v:.6g} px is not a principal point of a {w}x{h} camera")
    cov, _ = calibration_covariance(cal)
    key = "covariance" if getattr(cal, "covariance", None) is not None else "std"
    var = np.diag(cov)
    if np.any(var < 0):
        raise FieldError(key, f"holds a negative variance ({float(np.min(var)):.3g}): not a covariance")
    scale = np.array([K[0, 0], K[1, 1], w, h])
    rel = np.sqrt(var[:4]) / scale
    if np.any(rel > MAX_REL_STD):
        k = int(np.argmax(rel))
        raise FieldError(key if key == "covariance" else f"std.{PARAMS[k]}", f"gives σ {PARAMS[k]} {math.sqrt(var[k]):.3g} px: the calibration's uncertainty is too "
                              "large to detect a change; recalibrate")
    if np.any(var[4:] > MAX_COEFF_VAR):
        raise FieldError(key, f"gives a distortion coefficient σ {math.sqrt(float(np.max(var[4:]))):.3g}: the "
                              "calibration's uncertainty is too large to detect a change; recalibrate")
    d = np.sqrt(np.where(var > 0, var, 1.0))
    if not np.all(np.isfinite(var)) or np.max(np.abs(cov - cov.T) / np.outer(d, d)) > 1e-6:
        raise FieldError(key, "must be a symmetric matrix of finite variances and covariances")
    if np.any((var == 0)[:, None] & (cov != 0)) or np.linalg.eigvalsh(cov / np.outer(d, d))[0] < -1e-8:
        raise FieldError(key, "is not positive semi-definite: not a covariance")
    return cov
