"""Corners, shared by every board type: candidate points -> sub-pixel saddle fit (with a shadow edge
allowed) -> X-junction ring tests -> each corner's sigma. Compiled kernels sit beside their maths
(``*_kernels.py``); :mod:`aicalib_tf.detect.corners.sampling` is the bilinear sampler they share.
"""
