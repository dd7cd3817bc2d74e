"""A named ChArUco board grown along its own lattice, up to the frame's edge.

A marker predicts its square's corners by extrapolating its own small outline: on a steep view
that is up to a fifth of a marker side off, more than the saddle fit may travel in the thin white
margin. The corners already named predict better: a missing corner with at least
:data:`MIN_NEIGHBOURS` of its eight neighbours found is predicted by a homography of the nearest
named corners (:func:`aicalib_tf.detect.chessboard.lattice.predict_ids`; at least 4 of them within two steps,
not on one line) and looked for there, within
:data:`MAX_SHIFT_MARGIN` of the white margin (+ 0.5 px): by
the saddle fit with its window inside the margin, or, where that fails (a steep view squeezes the
margin along one axis and shears the squares), by :func:`refine_in_squares`, the centre of point
symmetry of a window laid along the board's axes.

Its id is the lattice's, and it is decided as :func:`aicalib_tf.detect.charuco.detector.name_lattice`
decides one: a marker of the board (one that named it) lies within
:data:`SUPPORT` squares of the corner, and the named corners put that
marker's square where the marker is (its centre within a quarter square: a lattice predicted from
too few corners, off by a square, names nothing). The image must show a corner there: its white
squares brighter than its black ones by at least :data:`MIN_CONTRAST_SHARE` of the named corners'
median (an object in front has no such contrast), and the window point-symmetric about it
(:func:`asymmetry` at most twice the named corners' median, :data:`MAX_AFFINE_ASYMMETRY` at
least). Passes repeat while corners are added.

At the frame's edge a fit window leaves the image (:func:`at_frame_edge`): its samples there
would be the edge pixels repeated, and the fit is pulled by up to a pixel. A missing corner there
with at least :data:`EDGE_NEIGHBOURS` neighbours found, inside the hull of the pixel centres and
with the board's contrast in its part of the window, is taken at its prediction; and every corner
of a board whose window leaves the image is put, last, where the corners inside predict it
(:func:`place_edge_corners`, within a tenth of a pixel on rendered views).
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np

from aicalib_tf.detect.charuco.refine import bilinear, symmetry_fit
from aicalib_tf.detect.chessboard.lattice import predict_ids
from aicalib_tf.detect.corners.refine import Smoothed, refine_windowed, window_radius
from aicalib_tf.geometry.points import nearest_index

__all__ = ["SUPPORT", "MAX_SHIFT_MARGIN", "MIN_NEIGHBOURS", "EDGE_NEIGHBOURS", "MAX_EDGE_MOVE", "MIN_CONTRAST_SHARE", "MAX_AFFINE_ASYMMETRY", "grow_along_lattice",
           "keep_with_contrast", "margin_px", "refine_in_squares", "asymmetry", "square_contrast", "at_frame_edge", "place_edge_corners"]

SUPPORT = 1.5  # squares from a corner to a marker that names it (Chebyshev, marker centre)
MAX_SHIFT_MARGIN = 0.5  # a refined corner moves at most this share of its margin (plus 0.5 px)
MIN_NEIGHBOURS = 2
EDGE_NEIGHBOURS = 3
MAX_EDGE_MOVE = 1.5  # px: the most a fit on the image's edge was seen pulled (0.9 px), with room
_NEIGHBOURS = np.array([(i, j) for j in (-1, 0, 1) for i in (-1, 0, 1) if (i, j) != (0, 0)], np.int64)


def _sides(quads: np.ndarray) -> np.ndarray:
    """(M,) px: the mean side of each marker outline (M, 4, 2) px."""
    return np.linalg.norm(np.diff(np.concatenate([quads, quads[:, :1]], axis=1), axis=1), axis=2).mean(axis=1)


def margin_px(det, pts: np.ndarray) -> np.ndarray:
    """(N,) px: the white margin between a board corner and the markers beside it, at points (N, 2)
    px, from the side of the nearest of det's markers (0 where det has no marker)."""
    pts = np.asarray(pts, np.float64).reshape(-1, 2)
    if not len(det.marker_corners) or not len(pts):
        return np.zeros(len(pts))
    quads = np.asarray(det.marker_corners, np.float64).reshape(-1, 4, 2)
    side = _sides(quads)
    near = nearest_index(pts, quads.mean(axis=1))  # in row blocks: any number of markers
    return side[near] * (det.board.square - det.board.marker) / (2.0 * det.board.marker)


def _agreeing_markers(det) -> np.ndarray:
    """(K, 2) float64 centres, in corner ids, of det's markers that sit where det's corners put their
    squares: the lattice predicts the square's centre within a quarter square of the marker's."""
    if not len(det.marker_ids) or len(det.ids) < 4:
        return np.zeros((0, 2))
    sq = det.board.marker_square_of()
    centres = np.array([sq[int(k)] for k in det.marker_ids], np.float64) - 0.5  # square (i, j) centre, in corner ids
    quads = np.asarray(det.marker_corners, np.float64).reshape(-1, 4, 2)
    at = predict_ids(det.ids.astype(np.float64), det.corners.astype(np.float64), centres)
    off = np.linalg.norm(at - quads.mean(axis=1), axis=1)
    ok = np.isfinite(off) & (off < 0.25 * _sides(quads) * det.board.square / det.board.marker)
    return centres[ok]


def _supported(det, want: np.ndarray) -> np.ndarray:
    """(M,) bool: a marker that named det, and that sits where det's corners put it, lies within
    SUPPORT squares (Chebyshev) of each corner id (M, 2)."""
    centres = _agreeing_markers(det)
    if not len(centres) or not len(want):
        return np.zeros(len(want), bool)
    d = np.abs(want[:, None, :].astype(np.float64) - centres[None]).max(axis=2)
    return (d <= SUPPORT).any(axis=1)


def _candidates(det) -> tuple[np.ndarray, np.ndarray]:
    """Missing ids (M, 2) on the board, supported, with enough neighbours around them to predict
    them, and their found 8-neighbour counts (M,)."""
    cols, rows = det.board.pattern_size
    have = np.zeros((rows + 2, cols + 2), bool)  # one cell of padding on each side
    have[det.ids[:, 1] + 1, det.ids[:, 0] + 1] = True
    count = sum(have[1 + dj: rows + 1 + dj, 1 + di: cols + 1 + di].astype(int) for di, dj in _NEIGHBOURS)
    r, c = np.nonzero(~have[1:-1, 1:-1] & (count >= MIN_NEIGHBOURS))
    want = np.stack([c, r], axis=1).astype(np.int64)
    ok = _supported(det, want) & np.array([_spans(det.ids, w) for w in want], bool)
    return want[ok], count[r, c][ok]


def _spans(ids: np.ndarray, want: np.ndarray) -> bool:
    """At least 4 found ids within two steps of ``want``, not all on one line (a homography's support)."""
    near = ids[np.abs(ids - want).max(axis=1) <= 2].astype(np.float64)
    return len(near) >= 4 and np.linalg.matrix_rank(near - near.mean(axis=0), tol=1e-6) == 2


AFFINE_RADIUS = 3  # the window: (2r + 1)² samples on a grid along the board's axes
AFFINE_REACH = 1.0  # of the white margin: the window's half-size along each board axis (the markers' black borders beyond it are point-symmetric too)
MAX_AFFINE_ASYMMETRY = 0.05  # of the window's variance: the mean squared difference of opposite samples


def refine_in_squares(img: np.ndarray, pts: np.ndarray, steps: np.ndarray, reach: np.ndarray,
                      iterations: int = 10, max_asymmetry: float = MAX_AFFINE_ASYMMETRY) -> tuple[np.ndarray, np.ndarray]:
    """A corner as the centre of point symmetry of a window laid along the board's axes: where a
    steep view squeezes the white margin along one axis, a square window
    (:func:`aicalib_tf.detect.corners.refine.refine_windowed`) takes in the markers' bits, and the blur of the
    acute corners of a sheared square adds a bowl to the saddle the quadratic fit looks for. This
    window stays in the margin along both axes; an affine map keeps a corner's point symmetry, so
    Gauss–Newton steps minimise the squared differences of opposite samples, I(p + d) − I(p − d).

    img : (H, W) float32, smoothed. pts : (N, 2) px starts. steps : (N, 2, 2) px, columns one board
    square along the board's x and y at each point (the lattice's local Jacobian). reach : (N,) the
    window's half-size in squares. Returns (N, 2) float64 px and ok (N,) bool: settled (last step
    under 0.02 px) and symmetric (:func:`asymmetry` at most ``max_asymmetry``); points not ok are
    returned as started.
    """
    pts = np.asarray(pts, np.float64).reshape(-1, 2)
    steps = np.asarray(steps, np.float64).reshape(-1, 2, 2)
    reach = np.broadcast_to(np.asarray(reach, np.float64), (len(pts),))
    good = np.isfinite(pts).all(axis=1) & np.isfinite(steps).all(axis=(1, 2))
    if not good.all():  # no lattice there: not ok
        out, ok = pts.copy(), np.zeros(len(pts), bool)
        if good.any():
            out[good], ok[good] = refine_in_squares(img, pts[good], steps[good], reach[good], iterations, max_asymmetry)
        return out, ok
    d = _half_window(steps, reach)
    cur, step = symmetry_fit(img, pts, d, iterations=iterations)
    ok = (step < 0.02) & (_asymmetry(img, cur, d) <= max_asymmetry)
    return np.where(ok[:, None], cur, pts), ok


def _half_window(steps: np.ndarray, reach) -> np.ndarray:
    """(N, M, 2) px offsets of one of each opposite pair of a (2r + 1)² grid along the board's axes
    (steps (N, 2, 2) px per square, columns x and y), half-size ``reach`` squares (scalar or (N,))."""
    r = AFFINE_RADIUS
    g = np.arange(-r, r + 1, dtype=np.float64)
    uv = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    uv = uv[: len(uv) // 2]  # the centre and the other half left out
    J = np.asarray(steps, np.float64) * (np.broadcast_to(np.asarray(reach, np.float64), (len(steps),)) / r)[:, None, None]
    return np.einsum("nij,mj->nmi", J, uv)


def asymmetry(img: np.ndarray, pts: np.ndarray, steps: np.ndarray, reach: float) -> np.ndarray:
    """(N,) how far the image is from point symmetry about each point (N, 2) px, on a window along
    the board's axes (steps (N, 2, 2) px per square, half-size ``reach`` squares): the mean squared
    difference of opposite samples over twice their variance; 0 for a corner, about 1 for noise or
    a flat patch, up to 2 for an edge."""
    return _asymmetry(img, np.asarray(pts, np.float64).reshape(-1, 2), _half_window(steps, reach))


def _asymmetry(img: np.ndarray, pts: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(N,) mean squared difference of the samples at pts + d and pts − d (d (N, M, 2) px), over
    twice the samples' variance (1 for a flat window)."""
    a, b = bilinear(img, pts[:, None, :] + d), bilinear(img, pts[:, None, :] - d)
    var = np.concatenate([a, b], axis=1).var(axis=1)
    return np.where(var > 1e-8, ((a - b) ** 2).mean(axis=1) / (2 * np.maximum(var, 1e-12)), 1.0)


def _steps(det, want: np.ndarray) -> np.ndarray:
    """(M, 2, 2) px: one square along the board's x and y at ids ``want`` (M, 2), from the lattice."""
    half = np.array([[0.5, 0.0], [-0.5, 0.0], [0.0, 0.5], [0.0, -0.5]])
    at = predict_ids(det.ids.astype(np.float64), det.corners.astype(np.float64),
                     (want[:, None, :].astype(np.float64) + half[None]).reshape(-1, 2)).reshape(-1, 4, 2)
    return np.stack([at[:, 0] - at[:, 1], at[:, 2] - at[:, 3]], axis=2)


MIN_CONTRAST_SHARE = 0.25  # of the named corners' median: a grown corner's squares at least this distinct
FIT_SIGMA = 0.5  # px, the smoothing of the image for the fit along the board's axes and the evidence tests
_QUADRANTS = np.array([(-1, -1), (1, -1), (-1, 1), (1, 1)], np.float64)  # squares (c, r), (c+1, r), (c, r+1), (c+1, r+1)
_INSET = np.array([(a, b) for a in (0.04, 0.07, 0.1) for b in (0.04, 0.07, 0.1)])  # squares, inside the white margin


def square_contrast(img: np.ndarray, board, ids: np.ndarray, pts: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """(N,) the mean grey of the white squares' corners at each board corner minus that of the black
    ones, sampled inside the white margin along the board's axes (points outside the image left
    out); NaN where no white or no black square's corner is in the image.

    img : (H, W) float32. ids : (N, 2) corner ids (col, row). pts : (N, 2) px. steps : (N, 2, 2) px
    per square along the board's x and y (columns). An object in front of the board, or a flat
    patch, has no such contrast; a corner has the board's own.
    """
    h, w = img.shape
    ids = np.asarray(ids, np.int64).reshape(-1, 2)
    out = np.full(len(ids), np.nan)
    if not len(ids):
        return out
    uv = _QUADRANTS[:, None, :] * _INSET[None]  # (4, 9, 2) squares
    xy = np.asarray(pts, np.float64)[:, None, None, :] + np.einsum("nij,qkj->nqki", steps, uv)  # (N, 4, 9, 2)
    inside = (xy[..., 0] >= 0) & (xy[..., 0] <= w - 1) & (xy[..., 1] >= 0) & (xy[..., 1] <= h - 1)
    vals = np.where(inside, bilinear(img, xy), np.nan)
    with warnings.catch_warnings():  # all-NaN rows (no square of one colour in the image) give NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        mean = np.nanmean(vals, axis=2)  # (N, 4)
        sq_i = ids[:, 0:1] + np.array([0, 1, 0, 1])[None]
        sq_j = ids[:, 1:2] + np.array([0, 0, 1, 1])[None]
        white = board.is_marker_square(sq_i, sq_j)
        out = np.nanmean(np.where(white, mean, np.nan), axis=1) - np.nanmean(np.where(~white, mean, np.nan), axis=1)
    return out


def at_frame_edge(pts: np.ndarray, size: tuple[int, int], radius: np.ndarray) -> np.ndarray:
    """(N,) bool: the fit window of half-size ``radius`` (N,) px about points (N, 2) px leaves the
    image of size (w, h): its samples there would be the edge pixels repeated."""
    w, h = size
    pts = np.asarray(pts, np.float64).reshape(-1, 2)
    return (pts[:, 0] < radius) | (pts[:, 0] > w - 1 - radius) | (pts[:, 1] < radius) | (pts[:, 1] > h - 1 - radius)


def place_edge_corners(det, radius: np.ndarray):
    """det with each corner whose fit window leaves the image (:func:`at_frame_edge`, window
    half-size ``radius`` (N,) px) put where the corners whose windows are inside predict it (a
    fit on edge pixels repeated is pulled by up to a pixel; the prediction from the lattice inside is
    within a tenth of one on rendered views). Corners with fewer than 4 such corners to predict
    them, or whose prediction is more than :data:`MAX_EDGE_MOVE` px away, keep their place."""
    edge = at_frame_edge(det.corners, det.image_size, np.asarray(radius, np.float64))
    ids = det.ids.astype(np.float64)
    if not edge.any() or (~edge).sum() < 4 or np.linalg.matrix_rank(ids[~edge] - ids[~edge].mean(axis=0), tol=1e-6) < 2:
        return det
    at = predict_ids(ids[~edge], det.corners[~edge].astype(np.float64), ids[edge])
    corners = det.corners.copy()
    good = np.isfinite(at).all(axis=1)
    good[good] = np.linalg.norm(at[good] - corners[edge][good], axis=1) <= MAX_EDGE_MOVE  # a fit pulled, not lost
    corners[np.flatnonzero(edge)[good]] = at[good]
    return replace(det, corners=corners)


def keep_with_contrast(det, img: np.ndarray):
    """det without the corners whose squares do not show the board's contrast
    (:func:`square_contrast` under :data:`MIN_CONTRAST_SHARE` of the median of det's corners): a
    corner just behind the edge of an object in front, where the fit found the object's edge across
    the board's. img : (H, W) float32, the image smoothed by :data:`FIT_SIGMA` px."""
    if len(det.corners) < 5:
        return det
    c = square_contrast(img, det.board, det.ids, det.corners, _steps(det, det.ids))
    ref = np.nanmedian(np.append(c, np.nan)) if np.isfinite(c).any() else np.nan
    if not ref > 0:
        return det
    keep = ~(c < MIN_CONTRAST_SHARE * ref)  # NaN (no lattice, or no square of one colour in the image): kept
    return replace(det, corners=det.corners[keep], ids=det.ids[keep])


def grow_along_lattice(gray: np.ndarray, det, smoothed: Smoothed | None = None):
    """det with the missing corners its lattice predicts added (module docstring).

    gray : (H, W) float32. det : a :class:`~aicalib_tf.detect.charuco.detector.CharucoDetection` with at
    least 4 corners (otherwise returned as it is).
    """
    h, w = gray.shape
    no_shadow = lambda idx, saddles: np.zeros(len(idx), bool)  # noqa: E731 - the saddle stands
    contrast = max_asym = None
    for _ in range(int(np.prod(det.board.pattern_size))):  # each pass adds a corner at least
        if len(det.corners) < 4:
            break
        want, count = _candidates(det)
        if not len(want):
            break
        at = predict_ids(det.ids.astype(np.float64), det.corners.astype(np.float64), want.astype(np.float64))
        inside = np.isfinite(at).all(axis=1)
        inside[inside] &= (at[inside, 0] >= 0) & (at[inside, 0] <= w - 1) & (at[inside, 1] >= 0) & (at[inside, 1] <= h - 1)
        want, count, at = want[inside], count[inside], at[inside]
        if not len(want):
            break
        smoothed = Smoothed(gray) if smoothed is None else smoothed
        img = smoothed.sigma(FIT_SIGMA)
        reach = AFFINE_REACH * (det.board.square - det.board.marker) / (2.0 * det.board.square)
        if contrast is None:  # the contrast and the asymmetry of the corners named so far
            st = _steps(det, det.ids)
            contrast = float(np.nanmedian(np.append(square_contrast(img, det.board, det.ids, det.corners, st), np.nan)))
            max_asym = max(MAX_AFFINE_ASYMMETRY, 2.0 * float(np.median(asymmetry(img, det.corners, st, reach))))
            if not contrast > 0:
                break
        margin = margin_px(det, at)
        spacing = np.maximum(0.8 * margin, 2.0) / 0.45
        got, ok = refine_windowed(smoothed, at, spacing, max_shift=MAX_SHIFT_MARGIN * margin + 0.5, shadow_gate=no_shadow)
        if (~ok).any():  # a steep view squeezes the margin along one axis: a window along the board's axes
            miss = np.flatnonzero(~ok)
            again, ok2 = refine_in_squares(img, at[miss], _steps(det, want[miss]), np.full(len(miss), reach),
                                           max_asymmetry=max_asym)
            ok2 &= np.linalg.norm(again - at[miss], axis=1) <= MAX_SHIFT_MARGIN * margin[miss] + 0.5
            got[miss[ok2]], ok[miss[ok2]] = again[ok2], True
        clipped = at_frame_edge(at, (w, h), window_radius(spacing))
        edge = clipped & (count >= EDGE_NEIGHBOURS)
        got[edge] = at[edge]
        ok |= edge
        ok &= (got[:, 0] >= 0) & (got[:, 0] <= w - 1) & (got[:, 1] >= 0) & (got[:, 1] <= h - 1)
        if ok.any():  # the image's evidence: the board's contrast, and point symmetry (not at the frame)
            sel = np.flatnonzero(ok)
            st = _steps(det, want[sel])
            ok[sel] = square_contrast(img, det.board, want[sel], got[sel], st) >= MIN_CONTRAST_SHARE * contrast  # NaN: no
            ok[sel] &= edge[sel] | (asymmetry(img, got[sel], st, reach) <= max_asym)
        if not ok.any():
            break
        det = _union(det, replace(det, corners=got[ok].astype(np.float32), ids=want[ok].astype(np.int32)))
    return det


def _union(a, b):
    """One detection of the corners and markers of a and b (same board, disjoint ids)."""
    ids = np.concatenate([a.ids, b.ids])
    pts = np.concatenate([a.corners, b.corners])
    order = np.lexsort((ids[:, 0], ids[:, 1]))
    mk = dict(zip(b.marker_ids.tolist(), b.marker_corners))
    mk.update(zip(a.marker_ids.tolist(), a.marker_corners))
    keys = sorted(mk)
    cols, rows = a.board.pattern_size
    return replace(a, corners=pts[order], ids=ids[order], marker_ids=np.array(keys, np.int64),
                   marker_corners=np.array([mk[k] for k in keys], np.float64).reshape(-1, 4, 2),
                   complete=len(ids) == cols * rows)
