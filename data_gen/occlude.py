"""Occluders: objects (a hand, a clamp, a mug) in front of part of the board.

An occluder is a polygon in pixels. A corner counts as hidden when it lies inside an occluder
or within :data:`HIDE_MARGIN_PX` of its outline, where no detector can localise it.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = ["sample_occluders", "draw_occluders", "occluded", "HIDE_MARGIN_PX"]

HIDE_MARGIN_PX = 2.0


def sample_occluders(
    rng: np.random.Generator, corners_px: np.ndarray, *, severity: float, count: int = 1
) -> list[np.ndarray]:
    """Draw ``count`` polygons, each centred near a board corner.

    corners_px : (N, 2) float (x, y) px of the board's in-frame inner corners.
    severity : occluder radius as a fraction of the board's apparent diagonal (0.1 small, 0.4 big).

    Returns a list of (M, 2) float64 polygons in px.
    """
    if len(corners_px) == 0 or severity <= 0:
        return []
    pts = np.asarray(corners_px, dtype=np.float64)
    diag = float(np.hypot(*(pts.max(axis=0) - pts.min(axis=0))))
    polys = []
    for _ in range(count):
        centre = pts[int(rng.integers(len(pts)))] + rng.normal(0.0, 0.05 * diag, size=2)
        radius = severity * diag * rng.uniform(0.7, 1.3)
        if rng.random() < 0.5:  # blob: star-convex polygon
            n = int(rng.integers(5, 11))
            a = (np.arange(n) + rng.uniform(0.0, 1.0, size=n)) * (2.0 * math.pi / n)  # encloses the centre
            r = radius * rng.uniform(0.5, 1.0, size=n)
            poly = np.stack([centre[0] + r * np.cos(a), centre[1] + r * np.sin(a)], axis=1)
        else:  # bar: a long rotated rectangle, like an arm or a ruler across the board
            box = ((float(centre[0]), float(centre[1])), (float(radius * 4.0), float(radius * 0.7)), float(rng.uniform(0, 180)))
            poly = cv2.boxPoints(box).astype(np.float64)
        polys.append(poly)
    return polys


def draw_occluders(img: np.ndarray, polys: list[np.ndarray], levels: list[float]) -> np.ndarray:
    """Paint each polygon, anti-aliased, in its flat grey ``levels[k]`` (0..1). (H, W) float32."""
    out = img.copy()
    h, w = img.shape
    for poly, level in zip(polys, levels, strict=True):
        mask = np.zeros((h, w), np.uint8)
        cv2.fillPoly(mask, [np.round(poly * 16).astype(np.int32)], 255, cv2.LINE_AA, shift=4)
        m = mask.astype(np.float32) / 255.0
        out = out * (1.0 - m) + np.float32(level) * m
    return out


def occluded(points_px: np.ndarray, polys: list[np.ndarray], margin: float = HIDE_MARGIN_PX) -> np.ndarray:
    """(N,) bool: which points lie inside an occluder or within ``margin`` px of its outline."""
    pts = np.asarray(points_px, dtype=np.float64).reshape(-1, 2)
    hidden = np.zeros(len(pts), dtype=bool)
    for poly in polys:
        contour = poly.astype(np.float32).reshape(-1, 1, 2)
        for i, (x, y) in enumerate(pts):
            if not hidden[i] and np.isfinite(x) and np.isfinite(y):
                hidden[i] = cv2.pointPolygonTest(contour, (float(x), float(y)), True) >= -margin
    return hidden
