"""Cluttered backgrounds with distractors that can fool a chessboard detector.

Layers: a smooth gradient, low-frequency texture, random shapes (rectangles, ellipses,
polygons, lines), text, and small checker-like patches (2×2 to 3×3 squares: real X-junctions
that are not the board).
"""

from __future__ import annotations

import math
import string

import cv2
import numpy as np

__all__ = ["make_background", "checker_patch"]

_SHIFT = 4  # cv2 drawing with 1/16-px precision
_ONE = 1 << _SHIFT
_FONTS = (
    cv2.FONT_HERSHEY_SIMPLEX,
    cv2.FONT_HERSHEY_DUPLEX,
    cv2.FONT_HERSHEY_COMPLEX,
    cv2.FONT_HERSHEY_TRIPLEX,
    cv2.FONT_HERSHEY_PLAIN,
)


def _fp(pts: np.ndarray) -> np.ndarray:
    return np.round(np.asarray(pts) * _ONE).astype(np.int32)


def _grey(rng: np.random.Generator) -> int:
    return int(rng.integers(0, 256))


def checker_patch(canvas: np.ndarray, rng: np.random.Generator, centre, square: float) -> None:
    """Draw a small rotated, sheared checker (2–3 squares a side) centred at ``centre`` (x, y) px."""
    nx, ny = int(rng.integers(2, 4)), int(rng.integers(2, 4))
    ang = rng.uniform(0.0, math.pi)
    shear = rng.uniform(-0.3, 0.3)
    A = square * np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]]) @ np.array(
        [[1.0, shear], [0.0, rng.uniform(0.7, 1.3)]]
    )
    dark, light = sorted(rng.integers(0, 256, size=2).tolist())
    light = max(light, dark + 60)
    origin = np.asarray(centre, dtype=np.float64) - A @ np.array([nx / 2.0, ny / 2.0])
    for i in range(nx):
        for j in range(ny):
            quad = np.array([[i, j], [i + 1, j], [i + 1, j + 1], [i, j + 1]], dtype=np.float64)
            pts = quad @ A.T + origin
            colour = dark if (i + j) % 2 == 0 else min(light, 255)
            cv2.fillConvexPoly(canvas, _fp(pts), colour, cv2.LINE_AA, _SHIFT)


def _random_text(rng: np.random.Generator) -> str:
    alphabet = string.ascii_letters + string.digits + "  #+-=x"
    return "".join(alphabet[i] for i in rng.integers(0, len(alphabet), size=int(rng.integers(2, 14))))


def make_background(
    rng: np.random.Generator,
    size: tuple[int, int],
    *,
    clutter: float = 1.0,
    checker_distractors: float = 1.0,
) -> np.ndarray:
    """Render a background of ``size`` = (width, height).

    clutter : expected number of shapes and text items per 100 000 px (0 = plain gradient).
    checker_distractors : expected checker-like patches per 300 000 px.

    Returns (H, W) float32 in [0, 1].
    """
    w, h = size
    area = w * h
    # Smooth base: a linear gradient between two grey levels plus low-frequency texture.
    g0, g1 = rng.uniform(0.1, 0.9, size=2)
    ang = rng.uniform(0.0, 2.0 * math.pi)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    proj = xx * math.cos(ang) + yy * math.sin(ang)
    ramp = (proj - proj.min()) / max(float(np.ptp(proj)), 1.0)
    base = g0 + (g1 - g0) * ramp
    small = rng.standard_normal((max(2, h // 64), max(2, w // 64))).astype(np.float32)
    tex = cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC) * rng.uniform(0.0, 0.08)
    canvas = np.clip((base + tex) * 255.0, 0, 255).astype(np.uint8)

    scale = math.sqrt(area / 307_200.0)
    n_items = int(rng.poisson(clutter * area / 100_000.0))
    for _ in range(n_items):
        kind = int(rng.integers(0, 6))
        c = rng.uniform([0.0, 0.0], [w, h])
        r = rng.uniform(5.0, 80.0) * scale
        col = _grey(rng)
        if kind == 0:  # rotated rectangle
            box = cv2.boxPoints(((float(c[0]), float(c[1])), (float(r * 2), float(r * rng.uniform(0.3, 2))), float(rng.uniform(0, 180))))
            cv2.fillConvexPoly(canvas, _fp(box), col, cv2.LINE_AA, _SHIFT)
        elif kind == 1:  # ellipse, filled or outlined
            thick = -1 if rng.random() < 0.6 else int(rng.integers(1, 5))
            axes = (int(r * _ONE), int(r * rng.uniform(0.3, 1.0) * _ONE))
            cv2.ellipse(canvas, tuple(_fp(c).tolist()), axes, float(rng.uniform(0, 180)), 0, 360, col, thick, cv2.LINE_AA, _SHIFT)
        elif kind == 2:  # polygon
            n = int(rng.integers(3, 8))
            a = np.sort(rng.uniform(0, 2 * math.pi, n))
            rr = r * rng.uniform(0.4, 1.0, n)
            pts = np.stack([c[0] + rr * np.cos(a), c[1] + rr * np.sin(a)], axis=1)
            cv2.fillPoly(canvas, [_fp(pts)], col, cv2.LINE_AA, _SHIFT)
        elif kind == 3:  # line segments (edges, T and L junctions where they meet shapes)
            p1 = c + rng.uniform(-3 * r, 3 * r, size=2)
            cv2.line(canvas, tuple(_fp(c).tolist()), tuple(_fp(p1).tolist()), col, int(rng.integers(1, 6)), cv2.LINE_AA, _SHIFT)
        else:  # text
            font = _FONTS[int(rng.integers(len(_FONTS)))]
            fs = rng.uniform(0.4, 2.0) * scale
            org = (int(c[0]), int(c[1]))
            cv2.putText(canvas, _random_text(rng), org, font, fs, col, int(rng.integers(1, 4)), cv2.LINE_AA)
    n_check = int(rng.poisson(checker_distractors * area / 300_000.0))
    for _ in range(n_check):
        checker_patch(canvas, rng, rng.uniform([0.0, 0.0], [w, h]), rng.uniform(6.0, 40.0) * scale)
    return canvas.astype(np.float32) / 255.0
