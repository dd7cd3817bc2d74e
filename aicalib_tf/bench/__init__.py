"""The benchmark: conditions, the detector registry (the CNN and OpenCV's detectors), scoring
metrics, real photos, the runner, targets and the report. ``python -m aicalib_tf.evaluate`` runs it.
"""
