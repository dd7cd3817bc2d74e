"""The options every calibration run shares: photos or the guided loop, one camera or a rig.

``python -m aicalib_tf.calibrate`` parses them once (its ``_common``) and each run's config adds its
own: :class:`~aicalib_tf.calib.workflow.CalibrateConfig` (photos of one camera),
:class:`~aicalib_tf.calib.rig.workflow.RigConfig` (photos of a rig),
:class:`~aicalib_tf.guided.workflow.GuidedRunConfig` (a video, camera or stream) and
:class:`~aicalib_tf.guided.rig_video.RigVideoConfig` (a rig's videos). Every field is keyword-only.
"""

from __future__ import annotations

from dataclasses import dataclass

from aicalib_tf.cnn.spec import DETECTOR_NETWORK

__all__ = ["RunOptions"]


@dataclass(frozen=True, kw_only=True)
class RunOptions:
    """The board, the detector, the lens model and the outputs of a calibration run."""

    pattern: tuple[int, int]  # (cols, rows) inner corners
    square: float = 1.0  # the board's square (or circle spacing), in square_unit
    square_unit: str = ""  # "mm", "cm", "m", "in" or "" (no unit)
    out: str = "calib"  # the output folder
    detector: str = "cnn"
    network: str = DETECTOR_NETWORK  # the cnn detector's: default_int8, default, report or a .tflite/.keras path
    model: str = "auto"  # the lens model: auto or a geometry.lens.MODELS name (a rig: or a comma list, one a camera)
    quiet: bool = False
    workers: int | None = None  # detection processes (None: detect.batch's default); the guided loop takes one
    board: str | None = None  # a ChArUco, AprilGrid or circle-grid description (pattern and square follow from it)
