"""The saddle fit's operator: a Gaussian-weighted least-squares quadratic over a square window.

Shared by the saddle refinement (:mod:`aicalib_tf.detect.corners.refine`) and the shadow-edge fit
(:mod:`aicalib_tf.detect.corners.shadow`), which starts from the same quadratic.
"""

from __future__ import annotations

import functools

import numpy as np

__all__ = ["saddle_fit_matrix"]

@functools.lru_cache(maxsize=16)
def saddle_fit_matrix(radius: int) -> tuple[np.ndarray, np.ndarray]:
    """Offsets and the weighted least-squares operator of the quadratic fit.

    Returns offsets (M, 2) float32 (dx, dy) px on the (2r+1)² grid and P (6, M) float64 with
    coefficients (a, b, c, d, e, f) = P @ values for f(x, y) = a x² + b xy + c y² + d x + e y + f.
    The weights are Gaussian with σ = radius / 2 + 0.5. Cached per radius: read-only arrays.
    """
    r = int(radius)
    d = np.arange(-r, r + 1, dtype=np.float64)
    dx, dy = np.meshgrid(d, d)
    dx, dy = dx.ravel(), dy.ravel()
    sigma = r / 2.0 + 0.5
    w = np.exp(-(dx * dx + dy * dy) / (2 * sigma * sigma))
    a = np.stack([dx * dx, dx * dy, dy * dy, dx, dy, np.ones_like(dx)], axis=1)
    aw = a * w[:, None]
    p = np.linalg.solve(a.T @ aw, aw.T)
    offsets = np.stack([dx, dy], axis=1).astype(np.float32)
    offsets.flags.writeable = p.flags.writeable = False
    return offsets, p


