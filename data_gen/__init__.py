"""data_gen: synthetic chessboards with exact ground truth (numpy + OpenCV, no TensorFlow).

Quick use::

    from data_gen import make_sample
    s = make_sample("noisy", seed=0, index=3)   # s.image (H, W) uint8, s.label dict
    s.corners, s.visible                        # (cols·rows, 2) px (x, y), (cols·rows,) bool

Command line: ``python -m data_gen --out DIR --count N --preset NAME --seed S``.
"""

from aicalib_tf.geometry.camera import Camera, distort_normalized, undistort_normalized
from aicalib_tf.geometry.pose import project_points

from .board import Board, sample_board
from .camera import sample_camera, sample_fisheye
from .dataset import DatasetConfig, write_dataset
from .degrade import DEGRADATIONS, apply_degradations
from .pose import PoseConfig, sample_pose
from .presets import PRESETS, Preset, Rule, get_preset
from .render import render_board
from .sample import Sample, Scene, draw_scene, make_sample, make_sequence

__all__ = [
    "Board",
    "Camera",
    "DEGRADATIONS",
    "DatasetConfig",
    "PRESETS",
    "PoseConfig",
    "Preset",
    "Rule",
    "Sample",
    "Scene",
    "apply_degradations",
    "distort_normalized",
    "get_preset",
    "draw_scene",
    "make_sample",
    "make_sequence",
    "project_points",
    "render_board",
    "sample_board",
    "sample_camera",
    "sample_fisheye",
    "sample_pose",
    "undistort_normalized",
    "write_dataset",
]
