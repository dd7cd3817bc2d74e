"""OpenCV's fisheye calibration as the benchmarks run it: ``cv2.fisheye.calibrate`` with the start it needs.

OpenCV's fisheye fit starts from its own guess, which fails on wide lenses (an assertion in its
extrinsics' initialisation); then it is run again from K0: f = min(w, h) / π (180° across the
shorter side, equidistant) at the image centre. The evaluate rigs (:mod:`aicalib_tf.bench.rigs`),
``benchmarks/fisheye_calibration.py`` and ``benchmarks/real_repeatability.py`` all fit OpenCV's
fisheye model through :func:`fisheye_calibrate`.
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["CRITERIA", "fisheye_flag", "fisheye_calibrate"]

CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-10)


def fisheye_flag(name: str) -> int:
    """A cv2.fisheye flag: OpenCV 4 keeps them in cv2.fisheye, OpenCV 5 in cv2 (shared with calibrateCamera)."""
    return getattr(cv2.fisheye, name, None) or getattr(cv2, name)


def fisheye_calibrate(objs, imgs, size, criteria=CRITERIA) -> tuple[float, np.ndarray, np.ndarray, str]:
    """``cv2.fisheye.calibrate`` with CALIB_RECOMPUTE_EXTRINSIC | CALIB_FIX_SKEW, first from OpenCV's own
    start, then (when that raises cv2.error) from K0.

    objs : [(1, N, 3) float64] board points per view; imgs : [(1, N, 2) float64] px; size : (w, h) px.
    Returns (RMS px, K (3, 3), D (4, 1), why): ``why`` is "" or the last line of OpenCV's error when
    the start from K0 was needed. A second cv2.error propagates.
    """
    flags = fisheye_flag("CALIB_RECOMPUTE_EXTRINSIC") | fisheye_flag("CALIB_FIX_SKEW")
    try:
        rms, K, D, _, _ = cv2.fisheye.calibrate(objs, imgs, size, None, None, flags=flags, criteria=criteria)
        return rms, K, D, ""
    except cv2.error as exc:
        why = str(exc).strip().splitlines()[-1]
    w, h = size
    f0 = min(w, h) / np.pi
    K0 = np.array([[f0, 0.0, (w - 1) / 2.0], [0.0, f0, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
    rms, K, D, _, _ = cv2.fisheye.calibrate(objs, imgs, size, K0, np.zeros(4), criteria=criteria,
                                            flags=flags | fisheye_flag("CALIB_USE_INTRINSIC_GUESS"))
    return rms, K, D, why
