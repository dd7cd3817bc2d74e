"""The pinhole models' start: OpenCV's plumb_bob calibration from several initial focal lengths.

OpenCV initialises from homographies that ignore distortion; under strong barrel distortion its
Levenberg–Marquardt can then settle in a wrong minimum, so :func:`opencv_start` also starts it from
three pinhole fields of view and keeps the lowest RMS.
"""

from __future__ import annotations

import cv2
import numpy as np

from aicalib_tf.calib.bundle import CalibrationError
from aicalib_tf.geometry.pattern import board_points

__all__ = ["opencv_start", "k_starts"]

_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)


def k_starts(image_size) -> list:
    """Initial K guesses: OpenCV's own (None) and three pinhole fields of view.

    OpenCV initialises from homographies that ignore distortion; under strong barrel distortion
    Levenberg–Marquardt can then settle in a wrong minimum (measured: fx +28% on a data_gen
    sequence whose true fx it finds from a better start). The fit with the lowest RMS wins.
    """
    w, h = (float(s) for s in image_size)
    starts = [None]
    for hfov in (50.0, 80.0, 110.0):
        f = 0.5 * w / np.tan(np.radians(hfov) / 2)
        starts.append(np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]]))
    return starts


def opencv_start(views: list[View], square_size: float, image_size, flags: int):
    """plumb_bob by OpenCV from :func:`k_starts` (flags 0 or CALIB_FIX_K3), the lowest RMS kept:
    (K (3, 3), dist (5,), rvecs (V, 3), tvecs (V, 3)), the bundle fit's start."""
    obj = [board_points(v.ids, square_size).astype(np.float32) for v in views]
    img = [v.corners.astype(np.float32).reshape(-1, 1, 2) for v in views]
    size = tuple(int(s) for s in image_size)
    best, last_error = None, None
    for K0 in k_starts(image_size):
        try:
            if K0 is None:
                fit = cv2.calibrateCamera(obj, img, size, None, None, flags=flags, criteria=_CRITERIA)
            else:
                fit = cv2.calibrateCamera(obj, img, size, K0, np.zeros(5), flags=flags | cv2.CALIB_USE_INTRINSIC_GUESS,
                                          criteria=_CRITERIA)
        except cv2.error as exc:
            last_error = exc
            continue
        if np.isfinite(fit[0]) and (best is None or fit[0] < best[0]):
            best = fit
    if best is None:
        raise CalibrationError(f"OpenCV could not calibrate from {len(views)} views: {getattr(last_error, 'err', last_error)}")
    _, K, dist, rvecs, tvecs = best
    return (K, dist.ravel()[:5], np.asarray(rvecs, np.float64).reshape(-1, 3),
            np.asarray(tvecs, np.float64).reshape(-1, 3))
