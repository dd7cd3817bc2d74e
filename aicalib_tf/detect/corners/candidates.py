"""Saddle-point candidates: where an X-junction could be (pure numpy/OpenCV).

The report's network is a patch classifier, so it needs places to look. A chessboard corner is a
saddle of the smoothed intensity: the Hessian determinant Ixx·Iyy − Ixy² is negative there. The
candidates are the strongest local maxima of −det(H), a cheap, classical proposal step.
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["saddle_points"]


def saddle_points(gray: np.ndarray, *, sigma: float = 1.5, max_points: int = 800, radius: int = 2) -> np.ndarray:
    """The ``max_points`` strongest saddle points of a grey image.

    gray : (H, W) float or uint8.
    sigma : px, the Gaussian smoothing before the Hessian.
    radius : px, the local-maximum neighbourhood (a (2r+1)² window).
    Returns (N, 2) int32 (x, y) pixel positions, strongest first, N ≤ max_points.
    """
    g = cv2.GaussianBlur(np.asarray(gray, dtype=np.float32), (0, 0), sigma)
    ixx = cv2.Sobel(g, cv2.CV_32F, 2, 0, ksize=3)
    iyy = cv2.Sobel(g, cv2.CV_32F, 0, 2, ksize=3)
    ixy = cv2.Sobel(g, cv2.CV_32F, 1, 1, ksize=3)
    s = ixy * ixy - ixx * iyy
    peak = cv2.dilate(s, np.ones((2 * radius + 1, 2 * radius + 1), np.uint8))
    ys, xs = np.nonzero((s >= peak) & (s > 0))
    order = np.argsort(-s[ys, xs], kind="stable")[:max_points]
    return np.stack([xs[order], ys[order]], axis=1).astype(np.int32)
