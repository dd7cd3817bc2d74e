"""A second look at a board darkened towards a fisheye's rim: its region with the shading divided out.

Close to a circular fisheye the light falls towards the image circle, often almost to black: a
board's outer rings there keep 5–20 grey levels of contrast, and the corner map, which sees the
whole image standardised at once, misses most of their corners. The grid then stops a line or
two short of the pattern. Dividing the image by its local mean (a Gaussian of ``SIGMA`` px, plus
``FLOOR``) undoes a shading that varies slowly against the squares: each square keeps its
contrast relative to its surroundings, so the dark rim's corners come out as clear as the
bright middle's, and the same search finds the full board there (on closeup-eq's six misses the
map's recall of the true corners rises from 0.75 to 0.96).

The look costs about a millisecond where it has nothing to find: it reads the region's local
mean first, and goes on only where part of the region is dark beside the grid (:func:`darkened`),
then runs the network on the flattened region and searches it only where that shows new corners,
as many as the grid misses (``NEW_POINTS`` at most; :func:`new_points`). A board cut by the frame
or hidden by an object in front shows none. Three things keep the noise that flattening lifts out
of the board: ``FLOOR`` (near-black pixels are not divided by their own near-zero mean), every
corner the grid placed without a candidate must be marked by the network there, if weakly, and no
corner may be expected off by more than ``MAX_SIGMA`` px on the image (its contrast near the
noise). A miss rather than a corner px off. A corner whose saddle is far flatter than its
neighbours' (:func:`flat_saddles`: a blurred, darkened board corner the fit left 2.5 px along an
edge) is set aside: the board comes back partial without it.

Coordinates are (x, y) px, OpenCV's convention (the centre of pixel (0, 0) at (0.0, 0.0)); a
region ``box = (x0, y0, x1, y1)`` holds pixels x0 … x1 − 1 and y0 … y1 − 1, and a point (x, y)
on it lies at (x0 + x, y0 + y) on the image.
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from aicalib_tf.detect.chessboard.rim import neighbour_median, saddle_sharpness
from aicalib_tf.detect.corners.junctions import SAME_CORNER, nearest_spacing
from aicalib_tf.detect.corners.sigma import board_sigmas
from aicalib_tf.geometry.points import any_within

__all__ = ["SIGMA", "FLOOR", "MIN_SHARE", "NEW_POINTS", "DARK", "FLAT_SADDLE", "LOOK_ENDS", "local_mean", "flatten", "darkened",
           "shading_box", "flattened_look", "new_points", "saddle_sharpness", "flat_saddles"]

SIGMA = 12.0  # px: the local mean's Gaussian, wider than the close-up's squares, narrower than the fall-off
COARSE = 4  # px: the block size the local mean is worked out on
FLOOR = 8.0 / 255.0  # grey (image in [0, 1]) added to the local mean: near-black noise is not lifted
MIN_SHARE = 0.5  # of the pattern's corners: the least a grid holds for the second look
PAD_STEPS = 2.0  # median corner spacings around the grid: the lines the map missed, squeezed at the rim
MARGIN = 3.0 * SIGMA  # px beyond that: the local mean's support
MAX_SIGMA = 0.8  # px: a board whose corner's expected error (sigma.py) on the image exceeds this is not kept
DARK, DARK_SHARE = 0.5, 0.05  # a region whose darkest 5 % is under half its grid's light is darkened
NEW_POINTS = 4  # the flattened region's new network points that start its search (fewer: as many as the grid misses)
NEAR = 2.0  # px: a network point this near a candidate of the search is not new
FLAT_SADDLE = 2.0  # ln: a corner whose saddle_sharpness is this far under its neighbours' median is set aside
LOOK_ENDS = ("no region", "not darkened", "nothing new", "no full board", "unmarked corner", "sigma", "flat saddle",
             "found")  # where flattened_look ends, in its order


def local_mean(gray: np.ndarray) -> np.ndarray:
    """(H, W) float32: gray's local mean, about a Gaussian of ``SIGMA`` px: block means of ``COARSE``
    px, a Gaussian of SIGMA / COARSE on them (the border reflected), enlarged back (bilinear); a
    twentieth of the full-size Gaussian's time, and as smooth."""
    g = np.asarray(gray, np.float32)
    h, w = g.shape
    small = cv2.resize(g, (-(-w // COARSE), -(-h // COARSE)), interpolation=cv2.INTER_AREA)
    small = cv2.GaussianBlur(small, (0, 0), SIGMA / COARSE, borderType=cv2.BORDER_REFLECT)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)


def flatten(gray: np.ndarray, mean: np.ndarray | None = None) -> np.ndarray:
    """gray (H, W) float32 in [0, 1] over its local mean: 0.5·g / (G_σ(g) + ``FLOOR``), clipped to
    [0, 1], float32 (H, W). A region as bright as its surroundings comes out at about 0.5 / (1 +
    FLOOR / mean). mean : :func:`local_mean` of gray when the caller has it."""
    g = np.asarray(gray, np.float32)
    mean = local_mean(g) if mean is None else mean
    return np.clip(0.5 * g / (mean + np.float32(FLOOR)), 0.0, 1.0).astype(np.float32)


def darkened(mean: np.ndarray, points: np.ndarray) -> bool:
    """Whether part of a region is dark beside a grid in it: the ``DARK_SHARE`` quantile of its
    local ``mean`` (H, W) under ``DARK`` of the median of ``mean`` at the grid's ``points`` (K, 2) px
    (in the region's coordinates)."""
    h, w = mean.shape
    at = np.clip(np.round(points).astype(int), 0, [w - 1, h - 1])
    # the quantile over every COARSE-th pixel each way: the mean is that smooth, and sorting all costs ms
    return bool(np.quantile(mean[::COARSE, ::COARSE], DARK_SHARE) < DARK * np.median(mean[at[:, 1], at[:, 0]]))


def shading_box(ij: np.ndarray, points: np.ndarray, pattern_size: tuple[int, int],
                size: tuple[int, int]) -> tuple[int, int, int, int] | None:
    """The region to look at again around a grid that is no full board, or None where none is worth it.

    ij : (K, 2) int lattice positions of the grid's corners, points : (K, 2) px. pattern_size :
    (cols, rows). size : (width, height) px of the image. None when the grid holds fewer than
    ``MIN_SHARE`` of the pattern's corners or does not fit inside the pattern either way round (a
    bigger board); else the grid's bounding box grown by ``PAD_STEPS`` median spacings and
    ``MARGIN`` px, clipped to the image: (x0, y0, x1, y1) int.
    """
    ij = np.asarray(ij, np.int64).reshape(-1, 2)
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    cols, rows = pattern_size
    if len(pts) < max(MIN_SHARE * cols * rows, 4):
        return None
    extent = sorted((ij.max(axis=0) - ij.min(axis=0) + 1).tolist())
    if extent[0] > min(cols, rows) or extent[1] > max(cols, rows):
        return None
    w, h = size
    pad = PAD_STEPS * float(np.median(nearest_spacing(pts))) + MARGIN
    x0, y0 = np.maximum(np.floor(pts.min(axis=0) - pad), 0).astype(int)
    x1, y1 = np.minimum(np.ceil(pts.max(axis=0) + pad) + 1, [w, h]).astype(int)
    return int(x0), int(y0), int(x1), int(y1)


def flattened_look(gray: np.ndarray, pattern_size: tuple[int, int], seen, others: np.ndarray, search, marks,
                   why: list | None = None):
    """The search again, for a full board, on the region of a grid that is none, its shading divided out.

    gray : (H, W) float32 in [0, 1], full size. seen : the largest grid assembled on it (a
    :class:`~aicalib_tf.detect.chessboard.grid.Grid`). others : (M, 2) px, the corner candidates
    found on it. search : ``search(image) -> Detection``, the detector's one-scale search. marks :
    ``marks(image) -> (points (N, 2), weights (N,), weak() -> (K, 2))``, the network's points on an
    image, down to the weak weight (:func:`aicalib_tf.cnn.inference.weak_corner_points`).
    Returns the search's detection in gray's coordinates, or None: no region worth it
    (:func:`shading_box`), or none of it dark beside the grid (:func:`darkened`); the network's points on the flattened region (:func:`new_points`) fewer
    than the corners the grid misses or ``NEW_POINTS`` (the flattening shows nothing the search did
    not have: a board cut by the frame or hidden, not darkened; the search is not run); no complete
    board there; a corner the network does not mark there, even weakly, within ``SAME_CORNER`` px
    (one the grid placed where only noise is left, lifted by the flattening); or a corner whose
    expected error on gray (:func:`aicalib_tf.detect.corners.sigma.board_sigmas`) is over
    ``MAX_SIGMA`` (its contrast near the noise). The board comes back partial (complete False), without
    its corners of a flat saddle (:func:`flat_saddles`), where it has any. why : a list that receives where the
    look ended, one of ``LOOK_ENDS`` (``benchmarks/stage_misses.py`` traces the misses with it).
    """
    def end(reason: str, det=None):
        if why is not None:
            why.append(reason)
        return det

    h, w = gray.shape
    box = shading_box(seen.ij, seen.points, pattern_size, (w, h))
    if box is None:
        return end("no region")
    x0, y0, x1, y1 = box
    offset = np.array([x0, y0], np.float32)
    mean = local_mean(gray[y0:y1, x0:x1])
    if not darkened(mean, np.asarray(seen.points, np.float64) - offset):
        return end("not darkened")
    flat = flatten(gray[y0:y1, x0:x1], mean)
    strong, _, weak = marks(flat)
    if new_points(np.reshape(strong, (-1, 2)) + offset, others) < min(NEW_POINTS, pattern_size[0] * pattern_size[1] - len(seen)):
        return end("nothing new")
    det = search(flat)
    if not det.complete:
        return end("no full board")
    net = np.concatenate([np.reshape(strong, (-1, 2)), np.reshape(weak(), (-1, 2))])
    if not any_within(det.corners[det.scores <= 0], net, SAME_CORNER).all():
        return end("unmarked corner")
    corners = (det.corners + offset).astype(np.float32)
    sigmas = board_sigmas(lambda a, b, c, d: gray[b:d, a:c], corners, det.ids, det.scores, (w, h))
    if sigmas.max() > MAX_SIGMA:
        return end("sigma")
    keep = ~flat_saddles(gray, corners, det.ids)
    return end("found" if keep.all() else "flat saddle",
               replace(det, corners=corners[keep], ids=det.ids[keep], scores=det.scores[keep], complete=bool(keep.all()),
                       image_size=(w, h)))


def new_points(points: np.ndarray, others: np.ndarray) -> int:
    """How many of the network's ``points`` (N, 2) px on the flattened region have none of the
    search's candidates ``others`` (M, 2) px within ``NEAR`` px: the corners the flattening shows."""
    return int(np.sum(~any_within(np.asarray(points, np.float64).reshape(-1, 2),
                                  np.asarray(others, np.float64).reshape(-1, 2), NEAR)))


def flat_saddles(gray: np.ndarray, corners: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """(N,) bool: the corners of a board whose :func:`saddle_sharpness` on ``gray`` (H, W) is more than ``FLAT_SADDLE``
    under the median of their (up to 8) neighbours' on the board. corners : (N, 2) px; ids : (N, 2) int (col, row).
    Blur, darkening and the squeeze change it slowly across a board (on the shading look's true boards a corner
    is at most 1.64 under its neighbours; the corner 2.5 px off an edge's length along it, 2.49)."""
    ids = np.asarray(ids, np.int64).reshape(-1, 2)
    if len(ids) < 2:
        return np.zeros(len(ids), bool)
    sharp = saddle_sharpness(gray, corners)
    grid = np.full((int(ids[:, 1].max()) + 1, int(ids[:, 0].max()) + 1), np.nan)
    grid[ids[:, 1], ids[:, 0]] = sharp
    with np.errstate(all="ignore"):  # a corner with no neighbour on the board: NaN, never flagged
        near = neighbour_median(grid)[ids[:, 1], ids[:, 0]]
    return sharp < near - FLAT_SADDLE
