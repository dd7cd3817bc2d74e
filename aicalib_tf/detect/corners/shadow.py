"""Corner refinement that a shadow edge does not pull (numpy, loops compiled by numba).

A chessboard corner c is point-symmetric: I(c + o) = I(c − o). A shadow (or any light change)
multiplies the image by S, so the odd part D(o) = I(c + o) − I(c − o) no longer vanishes; but
when S is a single straight edge (plus a smooth ramp) across the window, S(c + o) / S(c − o)
depends on n·o alone, for the edge's normal n. Then, at the true centre,

    D(o) = E(o) · h(n·o),   E(o) = (I(c + o) + I(c − o)) / 2,   h odd,

for some 1-D profile h (h = 0 without a shadow). :func:`refine_symmetric` finds c by Gauss–Newton
on Σ w(o) (D(o) − E(o)·h(n·o))²: h is free per 1 px bin of |n·o| and eliminated in closed form,
and n is the best of ``directions`` angles in [0, π) or none at all, chosen at each step for each
point. A saddle-point fit (:func:`aicalib_tf.detect.corners.refine.refine_saddle`) is pulled up to a few px
towards a hard shadow edge that crosses the window near the corner; this fit is not, and on clean
and noisy corners it is as accurate (benchmarks/refine_accuracy.py, ``--shading``). Each point's
Gauss–Newton loop runs in :func:`aicalib_tf.detect.corners.shadow_kernels.symmetric_loop`; windows are sampled bilinearly.

Coordinates are (x, y) px with the centre of pixel (0, 0) at (0.0, 0.0).
"""

from __future__ import annotations

import functools

import numpy as np

from aicalib_tf.detect.corners.saddle import saddle_fit_matrix
from aicalib_tf.detect.corners.sampling import sample_windows
from aicalib_tf.detect.corners.shadow_kernels import symmetric_loop, symmetry_energies
from aicalib_tf.geometry.pose import in_frame

__all__ = ["asymmetry", "refine_symmetric", "shadow_asymmetry", "symmetric_operators"]


@functools.lru_cache(maxsize=16)
def symmetric_operators(radius: int, directions: int = 12):
    """The fit's fixed arrays for a (2r+1)² window, cached per (radius, directions): read-only.

    The M offsets o are the window's in row-major order (dy outer), as the kernels sample them.
    Returns weights (M,) (Gaussian, σ = r/2 + 0.5, as the saddle fit), mirror (M,) int (index of
    −o), kbin (M, directions) int
    (offset m lies in bin round(|n·o|) of 1 px for direction n) and sign (M, directions) (±1, the
    sign of n·o); the directions are ``directions`` angles in [0, π).
    """
    r = int(radius)
    d = np.arange(-r, r + 1, dtype=np.float64)
    ox, oy = (a.ravel() for a in np.meshgrid(d, d))
    sigma = r / 2.0 + 0.5
    weights = np.exp(-(ox * ox + oy * oy) / (2 * sigma * sigma))
    ang = np.arange(directions) * np.pi / directions
    proj = np.cos(ang)[None, :] * ox[:, None] + np.sin(ang)[None, :] * oy[:, None]  # (M, directions)
    kbin = np.floor(np.abs(proj) + 0.5).astype(np.int64)
    sign = np.where(proj >= 0, 1.0, -1.0)
    out = (weights, np.arange(len(ox))[::-1].copy(), kbin, sign)
    for a in out:
        a.flags.writeable = False
    return out


def asymmetry(img: np.ndarray, points: np.ndarray, radius: int) -> np.ndarray:
    """(N,) how far the window about each point is from point symmetry: odd energy / even energy.

    Σ w (I(p + o) − I(p − o))² / (4 Σ w (E(o) − Ē)²), with E the even part and the saddle fit's
    Gaussian weights. About 0 at a clean corner's centre (below 0.005 on data_gen's clean boards),
    ~0.002–0.01 under noise σ = 40 grey levels, up to ~0.8 where a shadow edge crosses the window.
    """
    odd, even, _ = _energies(img, points, int(radius), 12, False)
    return odd / np.maximum(even, 1e-12)


def shadow_asymmetry(img: np.ndarray, points: np.ndarray, radius: int, directions: int = 12) -> np.ndarray:
    """(N,) :func:`asymmetry` left over once a straight shadow edge is allowed for.

    The odd part D(o) that the best model D = E·h(n·o) (as in :func:`refine_symmetric`: n one of
    ``directions`` angles or none, h free per 1 px bin) leaves unexplained, over 4 Σ w (E − Ē)².
    A shadowed X-junction at its centre leaves almost nothing (below ~0.1 where :func:`asymmetry`
    is 0.3–1.4 on evaluate ``shading``); a T-junction at a board's edge, whose odd part fills two
    opposite quadrants, is not a product of its even part and one edge profile and keeps much of it.
    """
    odd, even, explained = _energies(img, points, int(radius), directions, True)
    return np.maximum(odd - np.maximum(explained, 0.0), 0.0) / np.maximum(even, 1e-12)


def _energies(img, points, radius: int, directions: int, shadow: bool):
    """:func:`aicalib_tf.detect.corners.shadow_kernels.symmetry_energies` of the points: odd (N,), even (N,), explained (N,)."""
    pts = np.ascontiguousarray(np.asarray(points, np.float64).reshape(-1, 2))
    w, mirror, kbin, sign = symmetric_operators(radius, directions)
    e = symmetry_energies(np.ascontiguousarray(img, np.float32), pts, radius, w, mirror, kbin, sign, shadow)
    return e[:, 0], e[:, 1], e[:, 2]


def refine_symmetric(
    img: np.ndarray,
    points: np.ndarray,
    *,
    radius: int = 3,
    iterations: int = 8,
    directions: int = 12,
    max_shift: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Move each point to the centre of point symmetry of the image near it, allowing a shadow edge.

    img : (H, W) float32, already smoothed (e.g. :class:`aicalib_tf.detect.corners.refine.Smoothed`). points :
    (N, 2) (x, y) px, within about a pixel of a corner. radius : px, half-size of the window.
    max_shift : px, the furthest a point may end from where it started (default: radius).
    Returns refined (N, 2) float32 and ok (N,) bool: False where the last step was 0.05 px or more,
    the point left ``max_shift`` or the image, or the image there is not a saddle (the quadratic
    fit of :func:`aicalib_tf.detect.corners.refine.refine_saddle` at the result); those points are returned unrefined.
    Each point stops on its own, so its result never depends on the others. A point whose step turns
    back against its last one halves its steps from then on: the best model can alternate between
    two points a fraction of a px apart (evaluate ``shading`` #29: 0.16 px, never settling).
    """
    pts0 = np.asarray(points, np.float64).reshape(-1, 2)
    if len(pts0) == 0:
        return np.zeros((0, 2), np.float32), np.zeros(0, bool)
    g = np.ascontiguousarray(img, np.float32)
    r = int(radius)
    max_shift = float(r if max_shift is None else max_shift)
    w, mirror, kbin, sign = symmetric_operators(r, directions)
    pts, last = symmetric_loop(g, pts0, r, w, mirror, kbin, sign, int(iterations))
    x, y = pts[:, 0], pts[:, 1]
    _, fit = saddle_fit_matrix(r)
    a, b, c = fit[:3] @ sample_windows(g, pts, r).T
    h, w = g.shape
    ok = (
        (4 * a * c - b * b < 0)
        & (last < 0.05)
        & (np.hypot(x - pts0[:, 0], y - pts0[:, 1]) <= max_shift)
        & in_frame(np.stack([x, y], axis=1), (w, h))
    )
    out = np.where(ok[:, None], np.stack([x, y], 1), pts0)
    return out.astype(np.float32), ok
