"""A named ChArUco board, made whole: grids of one board merged, corners beside markers added.

Merging: two detections of the same board description are one board when the markers both
placed sit at the same image places (within :data:`SAME_PLACE_PX`) and their corners have no id in
common; otherwise they stay two (two printed copies of a board have the same ids).

Completion: a marker read by OpenCV fixes its square's four corners through the homography of its
own corners (square corner = marker corner × square / marker about the centre). A marker is used
only when the board's corners already found put its square's centre within a quarter square of the
marker's centre (so a second copy of the board elsewhere never adds corners). A missing corner is
looked for where its markers put it (their predictions within a tenth of a marker side of each
other): a saddle fit with a window inside the white margin must land within
:data:`MAX_SHIFT_MARGIN` of the margin of the prediction. Passes repeat while corners are added. Last, every corner is refined once more from where it is
(:func:`polish`) on the part of its neighbourhood every corner shares, the markers' bits left out
(:mod:`aicalib_tf.detect.charuco.refine`: the margin's small window averages little noise, and a
wider one is pulled by the bits); corners then off their neighbours' lattice are dropped. A board that no grid of corners found is seeded by its
markers alone (:func:`complete_from_markers` on a detection with no corners): then each corner needs
two markers whose predictions agree, and the board at least 4 corners.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import replace

import cv2
import numpy as np

from aicalib_tf.detect.chessboard.lattice import MAX_RESIDUAL, curved_residuals, lattice_residuals, predict_ids
from aicalib_tf.detect.charuco.grow import MAX_SHIFT_MARGIN, _union
from aicalib_tf.detect.corners.refine import Smoothed, refine_windowed, window_radius

__all__ = ["SAME_PLACE_PX", "MAX_SHIFT_MARGIN", "merge_same_board", "complete_from_markers", "square_corners", "polish"]

SAME_PLACE_PX = 2.0
PASSES = 4


def _same_board(a, b) -> bool:
    if a.board != b.board or set(map(tuple, a.ids.tolist())) & set(map(tuple, b.ids.tolist())):
        return False
    shared = set(a.marker_ids.tolist()) & set(b.marker_ids.tolist())
    if not shared:
        return False
    for k in shared:
        ca = a.marker_corners[list(a.marker_ids).index(k)].mean(axis=0)
        cb = b.marker_corners[list(b.marker_ids).index(k)].mean(axis=0)
        if np.linalg.norm(ca - cb) > SAME_PLACE_PX:
            return False
    return True


def merge_same_board(found: list) -> list:
    """Merge detections that are parts of one board (module docstring); the others are kept as they are."""
    out = []
    for det in found:
        for k, kept in enumerate(out):
            if _same_board(kept, det):
                out[k] = _union(kept, det)
                break
        else:
            out.append(det)
    return out


def square_corners(board, marker_id: int, quad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The four corners of a marker's square: ids (4, 2) (col, row) and px (4, 2), from the
    marker's corners ``quad`` (4, 2) px in OpenCV's order."""
    i, j = board.marker_square_of()[int(marker_id)]
    h = board.marker / board.square / 2.0
    src = np.array([[-h, -h], [h, -h], [h, h], [-h, h]], np.float64)
    H = cv2.getPerspectiveTransform(src.astype(np.float32), np.asarray(quad, np.float32))
    unit = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    px = cv2.perspectiveTransform(unit.reshape(-1, 1, 2), H).reshape(4, 2)
    ids = np.array([[i - 1, j - 1], [i, j - 1], [i, j], [i - 1, j]], np.int64)
    return ids, px


def _agreeing(det, read) -> list[tuple[int, np.ndarray]]:
    """The markers of ``read`` (ids (M,), corners (M, 4, 2)) where det's corners put their squares
    (all of them while det has fewer than 4 corners: a seed, whose corners need two markers each)."""
    out = []
    if len(det.ids) < 4:
        return [(int(k), q) for k, q in zip(*read)]
    for k, quad in zip(*read):
        i, j = det.board.marker_square_of()[int(k)]
        centre = predict_ids(det.ids.astype(np.float64), det.corners.astype(np.float64), np.array([[i - 0.5, j - 0.5]]))[0]
        side = np.linalg.norm(np.diff(np.concatenate([quad, quad[:1]]), axis=0), axis=1).mean()
        if np.isfinite(centre).all() and np.linalg.norm(centre - quad.mean(axis=0)) < 0.25 * side * det.board.square / det.board.marker:
            out.append((int(k), quad))
    return out


def _predictions(det, markers) -> dict[tuple[int, int], tuple[np.ndarray, float]]:
    """{missing corner id: (mean predicted px, marker side px)} where the markers agree."""
    cols, rows = det.board.pattern_size
    have = set(map(tuple, det.ids.tolist()))
    preds = defaultdict(list)
    for k, quad in markers:
        side = np.linalg.norm(np.diff(np.concatenate([quad, quad[:1]]), axis=0), axis=1).mean()
        for cid, px in zip(*square_corners(det.board, k, quad)):
            c = (int(cid[0]), int(cid[1]))
            if 0 <= c[0] < cols and 0 <= c[1] < rows and c not in have:
                preds[c].append((px, side))
    out = {}
    votes = 2 if len(have) < 4 else 1  # a seed's corners need two markers that agree
    for c, ps in preds.items():
        if len(ps) < votes:
            continue
        pts = np.array([p for p, _ in ps])
        side = float(np.mean([sd for _, sd in ps]))
        if np.linalg.norm(pts - pts.mean(axis=0), axis=1).max() <= 0.1 * side:
            out[c] = (pts.mean(axis=0), side)
    return out


def complete_from_markers(gray: np.ndarray, det, read, smoothed: Smoothed | None = None):
    """det with the corners its agreeing markers fix added (module docstring).

    gray : (H, W) float32. read : OpenCV's markers of det's board (ids (M,), corners (M, 4, 2) px).
    smoothed : gray's smoothed copies, when the caller shares them.
    """
    margin_ratio = (det.board.square - det.board.marker) / (2.0 * det.board.marker)
    h, w = gray.shape
    for _ in range(PASSES):
        preds = _predictions(det, _agreeing(det, read))
        if not preds:
            break
        smoothed = Smoothed(gray) if smoothed is None else smoothed
        keys = list(preds)
        at = np.array([preds[c][0] for c in keys], np.float64)
        margin = np.array([preds[c][1] * margin_ratio for c in keys])
        spacing = np.maximum(0.8 * margin, 2.0) / 0.45
        no_shadow = lambda idx, saddles: np.zeros(len(idx), bool)  # noqa: E731 - the saddle stands
        got, ok = refine_windowed(smoothed, at, spacing, max_shift=MAX_SHIFT_MARGIN * margin + 0.5, shadow_gate=no_shadow)
        if (~ok).any():  # the smallest window where the margin's failed (a steep view thins the margin)
            again, ok2 = refine_windowed(smoothed, at[~ok], np.full(int((~ok).sum()), 2.0 / 0.45),
                                         max_shift=MAX_SHIFT_MARGIN * margin[~ok] + 0.5, shadow_gate=no_shadow)
            got[~ok], ok[~ok] = again, ok2
        ok &= (got[:, 0] >= 0) & (got[:, 0] <= w - 1) & (got[:, 1] >= 0) & (got[:, 1] <= h - 1)
        if not ok.any():
            break
        add = replace(det, corners=got[ok].astype(np.float32), ids=np.array(keys, np.int32)[ok])
        det = _union(det, add)
    return det


def polish(gray: np.ndarray, det, max_move: float = 1.5, smoothed: Smoothed | None = None):
    """det with each corner refined again from its place, on its plain neighbourhood
    (:func:`aicalib_tf.detect.charuco.refine.refine_on_plain_band`: the black squares and the white
    squares' band along the edges, the markers' bits left out); where that fit does not settle, moves
    more than ``max_move`` px or leaves more asymmetry than :data:`ODD_SHARE` times the board's median
    (an object's edge in the window), by the saddle fit with its window 0.8 of the white margin (from
    the nearest of det's markers; 2 px at least), and a corner whose fit fails both ways keeps its place.
    A corner whose saddle window leaves the image goes where the corners inside predict it
    (:func:`aicalib_tf.detect.charuco.grow.place_edge_corners`); corners without the board's contrast
    are dropped (:func:`aicalib_tf.detect.charuco.grow.keep_with_contrast`). gray : (H, W) float32;
    smoothed : its smoothed copies, when the caller shares them."""
    from aicalib_tf.detect.charuco.grow import FIT_SIGMA, keep_with_contrast, margin_px, place_edge_corners

    if not len(det.corners):
        return det
    pts = det.corners.astype(np.float64)
    smoothed = Smoothed(gray) if smoothed is None else smoothed
    got, ok = _band_fit(det, pts, smoothed.sigma(FIT_SIGMA), max_move)
    radius = np.maximum(0.8 * margin_px(det, pts), 2.0)
    if (~ok).any():
        miss = np.flatnonzero(~ok)
        sad, sad_ok = refine_windowed(smoothed, pts[miss], radius[miss] / 0.45, max_shift=np.full(len(miss), max_move),
                                      shadow_gate=lambda idx, saddles: np.zeros(len(idx), bool))
        got[miss], ok[miss] = sad, sad_ok
    det = replace(det, corners=np.where(ok[:, None], got, pts).astype(np.float32))
    det = keep_with_contrast(place_edge_corners(det, window_radius(radius / 0.45)), smoothed.sigma(FIT_SIGMA))
    return _on_lattice(det)


ODD_SHARE = 2.0  # a plain-band fit leaving more than this times the board's median asymmetry is not taken


def _band_fit(det, pts: np.ndarray, img: np.ndarray, max_move: float) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) px and ok (N,): det's corners pts (N, 2) px refined on their plain neighbourhood, on img
    (H, W) smoothed; ok where the fit settled within ``max_move`` px, its asymmetry at most
    ODD_SHARE times the median of those that settled (MAX_AFFINE_ASYMMETRY at least)."""
    from aicalib_tf.detect.charuco.grow import MAX_AFFINE_ASYMMETRY
    from aicalib_tf.detect.charuco.refine import local_homographies, refine_on_plain_band

    if len(pts) < 4:
        return pts.copy(), np.zeros(len(pts), bool)
    got, ok, left = refine_on_plain_band(img, det.board, det.ids, pts, local_homographies(det.ids, pts))
    ok &= np.linalg.norm(got - pts, axis=1) <= max_move
    if ok.any():
        ok &= left <= max(MAX_AFFINE_ASYMMETRY, ODD_SHARE * float(np.median(left[ok])))
    return got, ok


def _on_lattice(det):
    """det without corners that have no neighbour (8-connected in ids) and without those off their
    neighbours' lattice by more than ``MAX_RESIDUAL`` of a step
    (a corner pulled by the edge of an object in front, or by the paper's edge), worst first; a
    quadratic in the ids predicts each corner where there are enough (a strong lens bends the lattice)."""
    ids = det.ids.astype(np.int64)
    cheb = np.abs(ids[:, None] - ids[None]).max(axis=2)
    np.fill_diagonal(cheb, 99)
    alone = cheb.min(axis=1) > 1 if len(ids) > 1 else np.ones(len(ids), bool)
    det = replace(det, corners=det.corners[~alone], ids=det.ids[~alone])  # no neighbour to check it by
    n = len(det.corners)
    if n < 5:
        return det
    keep = np.arange(n)
    while True:  # the worst first, as lattice.drop_outliers; fewer than 5 left: none is trusted
        measure = curved_residuals if len(keep) > 12 else lattice_residuals
        res = measure(det.ids[keep], det.corners[keep].astype(np.float64))
        if res.max() <= MAX_RESIDUAL:
            break
        keep = np.delete(keep, int(np.argmax(res)))
        if len(keep) < 5:
            keep = keep[:0]
            break
    idx = keep
    cols, rows = det.board.pattern_size
    return replace(det, corners=det.corners[idx], ids=det.ids[idx], complete=len(idx) == cols * rows)
