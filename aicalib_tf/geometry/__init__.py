"""Camera geometry: board patterns, lens models and poses (pure numpy/OpenCV, no TensorFlow).

The lowest room of the package: every other part (data_gen's renderer, detection, calibration,
the benchmark) takes its patterns, projections and inverse projections from here, so each piece
of geometry exists once. See ``docs/architecture.md``.
"""
