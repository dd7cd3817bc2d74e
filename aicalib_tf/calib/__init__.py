"""Calibration: views (corners with board ids) -> lens-model fit -> quality report -> files.

Pure numpy/OpenCV (never TensorFlow). :mod:`~aicalib_tf.calib.fit` fits the camera,
:mod:`~aicalib_tf.calib.files` reads and writes OpenCV YAML, JSON and ROS camera_info and
undistorts, :mod:`~aicalib_tf.calib.report` summarises and draws, and
:mod:`~aicalib_tf.calib.workflow` goes from photos to saved files (it runs the detector).
"""

from aicalib_tf.calib.files import load_calibration, save_calibration, undistort
from aicalib_tf.calib.fit import Calibration, CalibrationError, View, calibrate_camera

__all__ = ["Calibration", "CalibrationError", "View", "calibrate_camera", "load_calibration", "save_calibration",
           "undistort"]
