"""Corner refinement that a shadow edge does not pull (pure numpy/OpenCV).

A chessboard corner c is point-symmetric: I(c + o) = I(c − o). A shadow (or any light change)
multiplies the image by S, so the odd part D(o) = I(c + o) − I(c − o) no longer vanishes; but
when S is a single straight edge (plus a smooth ramp) across the window, S(c + o) / S(c − o)
depends on n·o alone, for the edge's normal n. Then, at the true centre,

    D(o) = E(o) · h(n·o),   E(o) = (I(c + o) + I(c − o)) / 2,   h odd,

for some 1-D profile h (h = 0 without a shadow). :func:`refine_symmetric` finds c by Gauss–Newton
on Σ w(o) (D(o) − E(o)·h(n·o))²: h is free per 1 px bin of |n·o| and eliminated in closed form,
and n is the best of ``directions`` angles in [0, π) or none at all, chosen at each step for each
point. A saddle-point fit (:func:`aicalib_tf.refine.refine_saddle`) is pulled up to a few px
towards a hard shadow edge that crosses the window near the corner; this fit is not, and on clean
and noisy corners it is as accurate (benchmarks/refine_accuracy.py, ``--shading``).

Coordinates are (x, y) px with the centre of pixel (0, 0) at (0.0, 0.0).
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from .refine import saddle_fit_matrix

__all__ = ["asymmetry", "refine_symmetric", "shadow_asymmetry", "symmetric_operators"]


@functools.lru_cache(maxsize=16)
def symmetric_operators(radius: int, directions: int = 12):
    """The fit's fixed arrays for a (2r+1)² window, cached per (radius, directions): read-only.

    Returns offsets (M, 2) float64 (dx, dy) px, weights (M,) (Gaussian, σ = r/2 + 0.5, as the
    saddle fit), mirror (M,) int (index of −o), bins (M, directions·K) 0/1 and signed_bins
    (M, directions·K) ±1/0: offset m lies in bin k of |n·o| (1 px wide) for direction n, with the
    sign of n·o in the signed one.
    """
    r = int(radius)
    d = np.arange(-r, r + 1, dtype=np.float64)
    ox, oy = (a.ravel() for a in np.meshgrid(d, d))
    sigma = r / 2.0 + 0.5
    weights = np.exp(-(ox * ox + oy * oy) / (2 * sigma * sigma))
    ang = np.arange(directions) * np.pi / directions
    proj = np.cos(ang)[:, None] * ox[None] + np.sin(ang)[:, None] * oy[None]  # (directions, M)
    k = np.floor(np.abs(proj) + 0.5).astype(int)
    nk = int(k.max()) + 1
    bins = np.zeros((len(ox), directions, nk))
    bins[np.arange(len(ox))[:, None], np.arange(directions)[None, :], k.T] = 1.0
    signed = bins * np.where(proj >= 0, 1.0, -1.0).T[:, :, None]
    out = (np.stack([ox, oy], 1), weights, np.arange(len(ox))[::-1].copy(),
           bins.reshape(len(ox), -1), signed.reshape(len(ox), -1))
    for a in out:
        a.flags.writeable = False
    return out


def _window(img: np.ndarray, pts: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(P, M) float64: the image at each point + each offset (bilinear, border replicated)."""
    mx = (pts[:, 0:1] + offsets[None, :, 0]).astype(np.float32)
    my = (pts[:, 1:2] + offsets[None, :, 1]).astype(np.float32)
    return cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).astype(np.float64)


def asymmetry(img: np.ndarray, points: np.ndarray, radius: int) -> np.ndarray:
    """(N,) how far the window about each point is from point symmetry: odd energy / even energy.

    Σ w (I(p + o) − I(p − o))² / (4 Σ w (E(o) − Ē)²), with E the even part and the saddle fit's
    Gaussian weights. About 0 at a clean corner's centre (below 0.005 on data_gen's clean boards),
    ~0.002–0.01 under noise σ = 40 grey levels, up to ~0.8 where a shadow edge crosses the window.
    """
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    offsets, w, mirror, _, _ = symmetric_operators(int(radius))
    i = _window(np.asarray(img, np.float32), pts, offsets)
    d, e = i - i[:, mirror], 0.5 * (i + i[:, mirror])
    e = e - (e @ w / w.sum())[:, None]
    return (d * d) @ w / np.maximum(4 * (e * e) @ w, 1e-12)


def shadow_asymmetry(img: np.ndarray, points: np.ndarray, radius: int, directions: int = 12) -> np.ndarray:
    """(N,) :func:`asymmetry` left over once a straight shadow edge is allowed for.

    The odd part D(o) that the best model D = E·h(n·o) (as in :func:`refine_symmetric`: n one of
    ``directions`` angles or none, h free per 1 px bin) leaves unexplained, over 4 Σ w (E − Ē)².
    A shadowed X-junction at its centre leaves almost nothing (below ~0.1 where :func:`asymmetry`
    is 0.3–1.4 on evaluate ``shading``); a T-junction at a board's edge, whose odd part fills two
    opposite quadrants, is not a product of its even part and one edge profile and keeps much of it.
    """
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    if len(pts) == 0:
        return np.zeros(0)
    offsets, w, mirror, bins, signed = symmetric_operators(int(radius), directions)
    i = _window(np.asarray(img, np.float32), pts, offsets)
    d, e = i - i[:, mirror], 0.5 * (i + i[:, mirror])
    we = w * e
    explained = (((we * d) @ signed) ** 2 / ((we * e) @ bins + 1e-12)).reshape(len(pts), directions, -1).sum(2)
    left = (w * d * d).sum(1) - np.maximum(explained.max(axis=1), 0.0)
    ec = e - (e @ w / w.sum())[:, None]
    return np.maximum(left, 0.0) / np.maximum(4 * (ec * ec) @ w, 1e-12)


@functools.lru_cache(maxsize=16)
def _ringed_window(radius: int):
    """The (2r+3)² offsets around a (2r+1)² window, and for each window offset (in
    :func:`symmetric_operators` order) the indices of itself and of its ±x and ±y neighbours in them."""
    r = int(radius)
    d = np.arange(-r - 1, r + 2, dtype=np.float64)
    ox, oy = (a.ravel() for a in np.meshgrid(d, d))
    side = 2 * r + 3
    inner = np.array([(yy + 1) * side + (xx + 1) for yy in range(2 * r + 1) for xx in range(2 * r + 1)])
    out = (np.stack([ox, oy], 1), inner, inner + 1, inner - 1, inner + side, inner - side)
    for a in out:
        a.flags.writeable = False
    return out


def _window_and_gradients(img: np.ndarray, pts: np.ndarray, radius: int):
    """(P, M) each: the window of :func:`symmetric_operators` about each point, and its x and y
    central differences. Bilinear sampling at integer offsets commutes with differencing, so these
    are the image gradients sampled there, from one (2r+3)² sample per point."""
    offsets, inner, px, mx, py, my = _ringed_window(radius)
    big = _window(img, pts, offsets)
    return big[:, inner], 0.5 * (big[:, px] - big[:, mx]), 0.5 * (big[:, py] - big[:, my])


def _step(img, x, y, radius, directions):
    """One Gauss–Newton step per point: (ux, uy), each (P,), of the best model (none or a direction)."""
    offsets, w, mirror, bins, signed = symmetric_operators(radius, directions)
    i, ix, iy = _window_and_gradients(img, np.stack([x, y], 1), radius)
    d = i - i[:, mirror]  # odd part (x2) of the window about the current point
    e = 0.5 * (i + i[:, mirror])  # even part
    jx, jy = ix - ix[:, mirror], iy - iy[:, mirror]  # d(d)/d(point)
    # no-shadow model: sums over the window, each (P,)
    wjx, wjy = w * jx, w * jy
    base = np.stack([(wjx * jx).sum(1), (wjx * jy).sum(1), (wjy * jy).sum(1),
                     (wjx * d).sum(1), (wjy * d).sum(1), (w * d * d).sum(1)])  # (6, P): a11 a12 a22 b1 b2 c0
    # per direction and bin, each (P, directions·K): eliminate h = (Σ w e d) / (Σ w e²) in closed form
    we = w * e
    see = (we * e) @ bins + 1e-12
    sed, sex, sey = (we * d) @ signed, (we * jx) @ signed, (we * jy) @ signed
    p, n = len(x), directions
    gone = np.stack([sex * sex, sex * sey, sey * sey, sex * sed, sey * sed, sed * sed]) / see  # (6, P, n·K)
    cand = np.concatenate([base[:, :, None], base[:, :, None] - gone.reshape(6, p, n, -1).sum(3)], 2)
    # (6, P, 1 + directions): the no-shadow model, then each direction's
    A11, A12, A22, B1, B2, C0 = cand
    det = A11 * A22 - A12 * A12
    good = det > 1e-18 * np.maximum(A11 * A22, 1e-30)
    safe = np.where(good, det, 1.0)
    ux = np.where(good, -(A22 * B1 - A12 * B2) / safe, 0.0)
    uy = np.where(good, -(A11 * B2 - A12 * B1) / safe, 0.0)
    resid = np.where(good, C0 + B1 * ux + B2 * uy, np.inf)  # the model's residual after the step
    best = np.argmin(resid, axis=1)
    rows = np.arange(p)
    return ux[rows, best], uy[rows, best]


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

    img : (H, W) float32, already smoothed (e.g. :class:`aicalib_tf.refine.Smoothed`). points :
    (N, 2) (x, y) px, within about a pixel of a corner. radius : px, half-size of the window.
    max_shift : px, the furthest a point may end from where it started (default: radius).
    Returns refined (N, 2) float32 and ok (N,) bool: False where the last step was 0.05 px or more,
    the point left ``max_shift`` or the image, or the image there is not a saddle (the quadratic
    fit of :func:`aicalib_tf.refine.refine_saddle` at the result); those points are returned unrefined.
    Each point stops on its own, so its result never depends on the others. A point whose step turns
    back against its last one halves its steps from then on: the best model can alternate between
    two points a fraction of a px apart (evaluate ``shading`` #29: 0.16 px, never settling).
    """
    pts0 = np.asarray(points, np.float64).reshape(-1, 2)
    n = len(pts0)
    if n == 0:
        return np.zeros((0, 2), np.float32), np.zeros(0, bool)
    g = np.asarray(img, np.float32)
    r = int(radius)
    max_shift = float(r if max_shift is None else max_shift)
    x, y = pts0[:, 0].copy(), pts0[:, 1].copy()
    last = np.full(n, np.inf)
    prev, damp = np.zeros((n, 2)), np.ones(n)
    act = np.arange(n)
    for _ in range(iterations):
        ux, uy = _step(g, x[act], y[act], r, directions)
        # the model (which shadow direction) can switch between two points a step apart, each
        # sending the fit back to the other: a step against the last one halves the steps from then on
        damp[act] *= np.where(ux * prev[act, 0] + uy * prev[act, 1] < 0, 0.5, 1.0)
        ux, uy = ux * damp[act], uy * damp[act]
        norm = np.sqrt(ux * ux + uy * uy)
        scale = np.minimum(1.0, 1.0 / np.maximum(norm, 1e-12))  # at most 1 px per iteration
        x[act] += ux * scale
        y[act] += uy * scale
        prev[act] = np.stack([ux, uy], 1)
        last[act] = norm
        act = act[norm >= 1e-3]
        if len(act) == 0:
            break
    offsets, fit = saddle_fit_matrix(r)
    a, b, c = fit[:3] @ _window(g, np.stack([x, y], 1), offsets).T
    h, w = g.shape
    ok = (
        (4 * a * c - b * b < 0)
        & (last < 0.05)
        & (np.hypot(x - pts0[:, 0], y - pts0[:, 1]) <= max_shift)
        & (x >= -0.5) & (x <= w - 0.5) & (y >= -0.5) & (y <= h - 0.5)
    )
    out = np.where(ok[:, None], np.stack([x, y], 1), pts0)
    return out.astype(np.float32), ok
