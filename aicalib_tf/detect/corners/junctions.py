"""X-junction evidence where a corner is expected (numpy, numba).

A chessboard's inner corner is an X-junction: point-symmetric, with two dark and two bright arcs
on a ring around it. This module cleans the CNN's candidate points (:func:`nearest_spacing`,
:func:`dedupe`), measures the ring evidence (:func:`ring_symmetry`) and builds the callback that
grid assembly and partial boards use to look for a corner at a lattice prediction
(:func:`proposer`: windowed saddle refinement, then the ring test).

Coordinates are (x, y) px with the centre of pixel (0, 0) at (0.0, 0.0).
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.detect.corners.junction_kernels import nearest_distances, ring_stats
from aicalib_tf.detect.corners.refine import (
    SHADOW_SIGMA,
    Smoothed,
    refine_windowed,
    window_radius,
)
from aicalib_tf.detect.corners.shadow import shadow_asymmetry
from aicalib_tf.geometry.points import any_within, close_pairs

__all__ = ["dedupe", "nearest_spacing", "proposer", "ring_symmetry", "typical_amplitude"]


def nearest_spacing(pts: np.ndarray) -> np.ndarray:
    """(N,) distance from each point of pts (N, 2) to its nearest other point (px); 8 when alone.

    Float32 points give float32 distances, others float64 (a compiled loop,
    :func:`aicalib_tf.detect.corners.junction_kernels.nearest_distances`: the detector asks three times per image).
    """
    if len(pts) < 2:
        return np.full(len(pts), 8.0)
    pts = np.asarray(pts)
    return nearest_distances(pts if pts.dtype == np.float32 else np.asarray(pts, np.float64))


SAME_CORNER = 1.5  # px: two points this near are one corner (dedupe; a weak network point or a proposal there)


def dedupe(pts: np.ndarray, scores: np.ndarray, min_distance: float = SAME_CORNER) -> np.ndarray:
    """Indices of points to keep: of points closer than ``min_distance`` px, only the strongest.

    The close pairs come from :func:`aicalib_tf.geometry.points.close_pairs` (memory O(N + pairs)).
    """
    order = np.argsort(-scores, kind="stable")
    p = pts[order]
    i, j = close_pairs(p, p, min_distance, strict=True)
    later = j > i  # each pair once, from its stronger point
    i, j = i[later], j[later]
    alive = np.ones(len(order), bool)
    starts = np.searchsorted(i, np.arange(len(order) + 1))
    for a in np.unique(i).tolist():  # strongest first; a point near none is kept as it is
        if alive[a]:
            alive[j[starts[a]:starts[a + 1]]] = False
    return order[alive]


_RING = np.stack([np.cos(np.linspace(0, 2 * np.pi, 16, endpoint=False)),
                  np.sin(np.linspace(0, 2 * np.pi, 16, endpoint=False))], 1)


def ring_symmetry(gray: np.ndarray, pts: np.ndarray, radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """X-junction evidence on a ring around each point.

    An X-junction is point-symmetric (I(p + d) = I(p − d)) and its ring alternates two dark and
    two bright arcs. gray : (H, W) float32. pts : (M, 2) px. radius : (M,) px.
    Returns amplitude (M,) (mean |I − mean| on the ring) and asymmetry (M,) (mean |I(θ) − I(θ + π)|).
    """
    pts = np.ascontiguousarray(np.asarray(pts, np.float64).reshape(-1, 2))
    radius = np.ascontiguousarray(np.broadcast_to(np.asarray(radius, np.float64), (len(pts),)))
    out = ring_stats(np.ascontiguousarray(gray, np.float32), pts, radius, _RING)
    return out[:, 0], out[:, 1]


def typical_amplitude(ring_image: np.ndarray, pts: np.ndarray, least: int) -> float:
    """The ring amplitude of a typical corner among ``pts`` (N, 2) px, N ≥ 1, strongest first.

    :func:`ring_symmetry` on a ring of 0.3 of each point's :func:`nearest_spacing`; the median over
    the stronger half of the points, at least the ``least`` strongest (np.median's value, from one sort).
    ring_image : (H, W) float32, smoothed (σ = 1 px): :func:`proposer`'s ``ring_image``.
    """
    amp, _ = ring_symmetry(ring_image, np.asarray(pts, np.float64), 0.3 * nearest_spacing(pts))
    a = np.sort(amp[: max(least, len(amp) // 2)])
    n = len(a)
    return float(a[n // 2]) if n % 2 else float((a[n // 2 - 1] + a[n // 2]) / 2)


GATE = 0.15  # of the reference ring amplitude: below it at the saddle, no shadow-robust fit (see proposer)
SHADOWED_X = 0.01  # most robust_refine.shadow_asymmetry of an X-junction under a shadow edge


def _shadowed_x(smoothed: Smoothed, pts: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """(M,) bool: an X-junction whose ring test a shadow edge broke.

    A shadow multiplies the image, so a corner it crosses is no longer point-symmetric; but the
    odd part left is its even part times a profile across the edge, which
    :func:`aicalib_tf.detect.corners.shadow.shadow_asymmetry` allows for (on the image and window, one px
    wider, of the shadow-robust refinement). True X-junctions that fail the ring test on evaluate
    ``shading`` leave at most 0.0074 of it; T-junctions at board edges and corners by an object's
    edge 0.01–0.3 (benchmarks of the proposer's asks on shading, occluded, partial and clutter).
    pts : (M, 2) px. radius : (M,) int, the refinement window radius.
    """
    out = np.zeros(len(pts), bool)
    img = smoothed.sigma(SHADOW_SIGMA)
    for r in np.unique(radius):
        sel = np.flatnonzero(radius == r)
        out[sel] = shadow_asymmetry(img, pts[sel], int(r) + 1) <= SHADOWED_X
    return out


_KEY = np.dtype((np.void, 24))  # a prediction's memory key: its x, y and step as float64 bytes


def proposer(smoothed: Smoothed, ring_image: np.ndarray, ref_amp: float, weak=None):
    """Look for a corner at each grid prediction: saddle refinement plus the ring test.

    smoothed : the image for :func:`aicalib_tf.detect.corners.refine.refine_windowed`. ring_image : (H, W)
    float32, smoothed (σ = 1 px). ref_amp : the ring amplitude of a typical corner of the image.
    Returns ``propose(pred (M, 2) px, step (M,) px) -> (M, 2)`` with NaN rows where no corner is:
    a window fitted to the step, the corner within 0.3 step, a ring of 0.3 step. Its attribute
    ``tight`` looks for a corner beside an object in front: the smallest fit window (2 px), the
    corner within 0.1 step, a ring of 0.15 step (at least 2 px). Either needs a ring amplitude of
    0.3·``ref_amp`` and asymmetry at most half the amplitude (a T-junction at a board edge has
    asymmetry ≈ 1.3·amplitude), or, where a shadow edge crosses the ring (asymmetry up to ~1.5·amplitude
    on evaluate ``shading``), the fit window point-symmetric once a straight shadow edge is allowed
    for (:func:`_shadowed_x`). The shadow-robust refinement, the costly part, is only tried where the ring about
    the saddle has at least ``GATE``·``ref_amp`` of amplitude: behind an object or on plain paper
    the ring test (``0.3``·``ref_amp``) then fails either way (on evaluate's occluded, partial,
    shading, clutter and tilt60 images the gate changed no answer). A point asked again (same prediction and step) is answered from
    memory: each point's answer depends on that point alone (:func:`aicalib_tf.detect.corners.refine.refine_saddle`).

    Its attribute ``bent`` (for a grid bent by a fisheye, :func:`aicalib_tf.detect.chessboard.grid.assemble_grids`
    with ``bend``) also takes a saddle whose ring test failed where one of the network's ``weak``
    points (``weak() -> (K, 2)`` px, weights under the candidate threshold; asked only then) lies
    within ``SAME_CORNER`` of it and the ring keeps ``GATE``·``ref_amp``. Towards a fisheye's rim the light falls to black and the
    blur grows: the ring's amplitude falls with the light, its asymmetry grows with the light's
    gradient across it and with the squares' squeeze, and the network's weight falls with the
    contrast, so none of the three alone tells a corner there; the grid's prediction, the saddle
    fit, and the network's weak point together do.
    """
    # size: three callbacks sharing the image, the reference amplitude, the weak points and their
    # memories; apart, each would take all of them
    h, w = ring_image.shape
    weak_pts = []  # weak(), once asked

    def weak_near(q: np.ndarray) -> np.ndarray:  # (M,) bool: a weak network point within SAME_CORNER of q
        if not weak_pts:
            weak_pts.append(np.zeros((0, 2)) if weak is None else np.asarray(weak(), np.float64).reshape(-1, 2))
        if len(weak_pts[0]) == 0:
            return np.zeros(len(q), bool)
        return any_within(q, weak_pts[0], SAME_CORNER)  # any number of weak points: memory O(M + K)

    def look(pred, step, margin, window, shift, ring, memo, bent=False):
        pred, step = np.asarray(pred, np.float64), np.asarray(step, np.float64)
        keys = np.column_stack([pred, step]).view(_KEY).ravel().tolist()  # each row's 24 bytes: x, y, step
        todo = np.array([m for m, key in enumerate(keys) if key not in memo], int)
        if len(todo):  # each point's answer depends on it alone: asked again, it is remembered
            got = np.full((len(todo), 2), np.nan)
            saddle = np.full((len(todo), 2), np.nan)  # a saddle that failed the ring test alone (``bent``)
            p, s = pred[todo], step[todo]
            k = np.flatnonzero(np.all((p >= margin) & (p <= np.array([w - 1 - margin, h - 1 - margin])), axis=1))
            if len(k):
                radius = ring(s[k])

                def ringed(idx, q):  # the shadow-robust fit only where the ring test could pass
                    return ring_symmetry(ring_image, q.astype(np.float64), radius[idx])[0] >= GATE * ref_amp

                # no restarts of the shadow fit: a prediction starts within a fraction of a step, and
                # beside objects most windows are asymmetric (restarts doubled evaluate occluded's time)
                q, ok = refine_windowed(smoothed, p[k], window(s[k]), max_shift=shift * s[k], restarts=False,
                                        shadow_gate=ringed)
                amp, asym = np.zeros(len(q)), np.zeros(len(q))  # the ring asked about the saddles that hold
                held = np.flatnonzero(ok)
                if len(held):
                    amp[held], asym[held] = ring_symmetry(ring_image, q[held].astype(np.float64), radius[held])
                fitted = ok & (amp >= GATE * ref_amp)
                ok &= amp >= 0.3 * ref_amp
                odd = np.flatnonzero(ok & (asym > 0.5 * amp))  # a shadow edge across the ring, or no X-junction
                if len(odd):
                    ok[odd] = _shadowed_x(smoothed, q[odd], window_radius(window(s[k[odd]])))
                got[k[ok]] = q[ok]
                saddle[k[fitted & ~ok]] = q[fitted & ~ok]
            for m, g, g2 in zip(todo.tolist(), got, saddle):
                memo[keys[m]] = (g, g2)
        out = np.array([memo[key][0] for key in keys]).reshape(-1, 2)
        if bent and weak is not None:  # a saddle the network marks, if weakly
            cand = np.array([memo[key][1] for key in keys]).reshape(-1, 2)
            ask = np.flatnonzero(np.isfinite(cand[:, 0]))
            if len(ask):
                ask = ask[weak_near(cand[ask])]
                out[ask] = cand[ask]
        return out

    memo_wide, memo_tight = {}, {}

    def propose(pred: np.ndarray, step: np.ndarray) -> np.ndarray:
        return look(pred, step, 1, lambda s: s, 0.3, lambda s: 0.3 * s, memo_wide)

    def tight(pred: np.ndarray, step: np.ndarray) -> np.ndarray:
        return look(pred, step, 3, lambda s: np.full(len(s), 4.0), 0.1, lambda s: np.maximum(2.0, 0.15 * s), memo_tight)

    def bent(pred: np.ndarray, step: np.ndarray) -> np.ndarray:
        return look(pred, step, 1, lambda s: s, 0.3, lambda s: 0.3 * s, memo_wide, bent=True)

    propose.tight = tight
    propose.bent = bent
    return propose
