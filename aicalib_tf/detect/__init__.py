"""Chessboard detection: image -> corner map -> candidates -> sub-pixel refinement -> junctions
-> grid -> board order or partial board -> :class:`Detection`.

:mod:`aicalib_tf.detect.pipeline` runs the stages (its result: :mod:`aicalib_tf.detect.detection`),
which live in subpackages along the pipeline:
:mod:`~aicalib_tf.detect.corners` (candidates to refined, tested corners),
:mod:`~aicalib_tf.detect.chessboard` (grids, lattices, board order, partial boards),
:mod:`~aicalib_tf.detect.charuco` and :mod:`~aicalib_tf.detect.boards` (AprilGrid, circle grids);
each imports only those before it. Each compiled kernel sits beside the module whose maths it
implements (``*_kernels.py``; how they are compiled: :mod:`aicalib_tf.kernels`). Never imports the
benchmark. ``python -m aicalib_tf.detect`` is the command line.
"""

from aicalib_tf.detect.draw import draw_detection
from aicalib_tf.detect.dropin import find_chessboard_corners
from aicalib_tf.detect.detection import Detection
from aicalib_tf.detect.pipeline import detect_corners
from aicalib_tf.detect.track import Tracker

__all__ = ["Detection", "Tracker", "detect_corners", "draw_detection", "find_chessboard_corners"]
