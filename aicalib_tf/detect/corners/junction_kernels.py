"""Ring statistics about candidate corners and their nearest neighbours' distances, compiled (numba): the maths
is :func:`aicalib_tf.detect.corners.junctions.ring_symmetry`'s and :func:`aicalib_tf.detect.corners.junctions.nearest_spacing`'s.
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.kernels import kernel

from .sampling import _bilinear

__all__ = ["nearest_distances", "ring_stats"]


@kernel("f4[:, ::1]", "f8[:, ::1]")
def nearest_distances(pts):
    """(N,) distance from each point of pts (N, 2), N ≥ 2, to its nearest other one, in pts' dtype.

    The same values, bit for bit, as the square root of the row minima of
    :func:`aicalib_tf.geometry.points.sq_distances` with the diagonal left out (a NaN propagates as there).
    """
    n = pts.shape[0]
    out = np.empty(n, pts.dtype)
    for i in range(n):
        out[i] = np.inf
        for j in range(n):
            if j != i:
                dx, dy = pts[i, 0] - pts[j, 0], pts[i, 1] - pts[j, 1]
                d = dx * dx + dy * dy
                if out[i] == out[i] and not d >= out[i]:  # smaller, or NaN (which then stays)
                    out[i] = d
        out[i] = np.sqrt(out[i])
    return out


@kernel("f4[:, ::1], f8[:, ::1], f8[::1], f8[:, ::1]")
def ring_stats(img, pts, radius, ring):
    """Amplitude and point asymmetry of the image on a ring about each point.

    img (H, W) float32, pts (P, 2) float64 px, radius (P,) px, ring (R, 2) unit directions, R even,
    the second half opposite the first. Returns (P, 2): mean |I − mean I| over the ring and mean
    |I(θ) − I(θ + π)| over its R / 2 opposite pairs.
    """
    nr = ring.shape[0]
    half = nr // 2
    vals = np.empty(nr)
    out = np.empty((pts.shape[0], 2))
    for p in range(pts.shape[0]):
        mean = 0.0
        for k in range(nr):
            vals[k] = _bilinear(img, pts[p, 0] + radius[p] * ring[k, 0], pts[p, 1] + radius[p] * ring[k, 1])
            mean += vals[k]
        mean /= nr
        amp = asym = 0.0
        for k in range(nr):
            amp += abs(vals[k] - mean)
        for k in range(half):
            asym += abs(vals[k] - vals[k + half])
        out[p, 0], out[p, 1] = amp / nr, asym / half
    return out

