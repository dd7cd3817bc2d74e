"""Find an OpenCV circle grid (:mod:`aicalib_tf.geometry.circles`) in an image and place each
circle's centre to a fraction of a pixel.

``cv2.findCirclesGrid`` (its blob detector, dark circles on a light board) finds the grid and
orders it (OpenCV's order, index i·cols + j). Each centre is then placed anew as the centroid of
the circle's dark area, in a window of half-side 0.55 × the distance to the nearest found centre:
the pixels darker than the mean of the window's 5th and 95th percentiles that connect to the blob,
grown by ``GROW`` px (a blurred edge), form the circle's mask; a plane fitted to the pixels away
from every dark blob gives the board's light level L(x, y) (an illumination gradient), the
reflectance is I / L, and each masked pixel weighs ``clip((1 − I/L) / (1 − inner), 0, 1)``
(``inner`` the disc's 5th percentile), its dark fraction, so edge pixels count by the area they
cover. Under a pinhole camera this centroid is the image ellipse's centre, which is not the
projection of the circle's centre: :mod:`aicalib_tf.calib.circle_bias` corrects that after a
first calibration. A circle whose grown mask reaches the window's edge (a neighbour, the image's
border), or whose contrast is under 0.05, keeps OpenCV's centre; ``refine="opencv"`` keeps them all.

Coordinates are (x, y) px with the centre of pixel (0, 0) at (0.0, 0.0).
"""

from __future__ import annotations

import cv2
import numpy as np

from aicalib_tf.geometry.circles import CircleGrid

__all__ = ["find_grid", "refine_centres", "detect_circles", "make_detector", "REFINES"]

REFINES = ("centroid", "opencv")
WINDOW = 0.55  # window half-side over the nearest centre distance
MIN_CONTRAST = 0.05  # light − dark, in the image's [0, 1] levels
GROW = 4  # px the thresholded disc is grown by: its blurred edge counts


def _blob_detector(image_area: int):
    p = cv2.SimpleBlobDetector_Params()
    p.minArea = 9.0
    p.maxArea = float(max(5000, image_area // 20))
    p.minDistBetweenBlobs = 3.0
    return cv2.SimpleBlobDetector_create(p)


def _as_uint8(gray) -> np.ndarray:
    g = np.asarray(gray)
    if g.dtype == np.uint8:
        return g
    return np.round(np.clip(g.astype(np.float64), 0.0, 1.0) * 255).astype(np.uint8)


def find_grid(gray: np.ndarray, board: CircleGrid) -> np.ndarray | None:
    """OpenCV's centres (cols·rows, 2) float64 px of the whole grid, in OpenCV's order, or None."""
    g = _as_uint8(gray)
    found, centres = cv2.findCirclesGrid(g, board.grid, flags=board.cv_flags(),
                                         blobDetector=_blob_detector(g.size))
    if not found or centres is None:
        return None
    return np.asarray(centres, np.float64).reshape(-1, 2)


def _nearest(centres: np.ndarray) -> np.ndarray:
    d = np.linalg.norm(centres[:, None] - centres[None], axis=2)
    np.fill_diagonal(d, np.inf)
    return d.min(axis=1)


def _light_plane(win: np.ndarray, background: np.ndarray) -> np.ndarray | None:
    """The board's light level over the window: a plane a + b·x + c·y fitted to the background pixels."""
    ys, xs = np.nonzero(background)
    if len(xs) < 12:
        return None
    A = np.stack([np.ones(len(xs)), xs, ys], axis=1).astype(np.float64)
    coef, *_ = np.linalg.lstsq(A, win[ys, xs], rcond=None)
    yy, xx = np.mgrid[0:win.shape[0], 0:win.shape[1]]
    return coef[0] + coef[1] * xx + coef[2] * yy


def _centroid(img: np.ndarray, c: np.ndarray, half: float) -> np.ndarray | None:
    """The dark-area centroid of the circle at about ``c`` in the float image, or None."""
    h, w = img.shape
    x0, y0 = int(np.floor(c[0] - half)), int(np.floor(c[1] - half))
    x1, y1 = int(np.ceil(c[0] + half)) + 1, int(np.ceil(c[1] + half)) + 1
    if x0 < 0 or y0 < 0 or x1 > w or y1 > h or x1 - x0 < 5 or y1 - y0 < 5:
        return None
    win = img[y0:y1, x0:x1]
    dark, light = np.percentile(win, 5), np.percentile(win, 95)
    if light - dark < MIN_CONTRAST:
        return None
    dark_px = (win < (dark + light) / 2).astype(np.uint8)
    _, labels = cv2.connectedComponents(dark_px, connectivity=8)
    lab = labels[int(round(c[1])) - y0, int(round(c[0])) - x0]
    if lab == 0:
        return None
    grown = cv2.dilate((labels == lab).astype(np.uint8), _disc(GROW)).astype(bool)
    if grown[0].any() or grown[-1].any() or grown[:, 0].any() or grown[:, -1].any():
        return None
    level = _light_plane(win, ~cv2.dilate(dark_px, _disc(GROW)).astype(bool))
    if level is None or np.min(level) <= 0:
        return None
    norm = win / level  # the board's reflectance: 1 on the light board, under a smooth illumination
    inner = np.percentile(norm[labels == lab], 5)
    if 1 - inner < MIN_CONTRAST:
        return None
    wgt = np.clip((1 - norm) / (1 - inner), 0.0, 1.0) * grown
    total = wgt.sum()
    ys, xs = np.mgrid[y0:y1, x0:x1]
    return np.array([(wgt * xs).sum() / total, (wgt * ys).sum() / total])


def _disc(r: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))


def refine_centres(gray: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """(N, 2) float64 px: each of ``centres`` (N, 2) placed at its circle's dark-area centroid
    (the module docstring); a circle that cannot be measured keeps its centre."""
    g = np.asarray(gray)
    img = g.astype(np.float64) / 255.0 if g.dtype == np.uint8 else g.astype(np.float64)
    out = np.asarray(centres, np.float64).copy()
    for k, half in enumerate(WINDOW * _nearest(out)):
        c = _centroid(img, out[k], half)
        if c is not None:
            out[k] = c
    return out


def detect_circles(gray: np.ndarray, board: CircleGrid, refine: str = "centroid"):
    """(centres (N, 2) float64 px, ids (N, 2) int64 lattice ids) of the whole grid, or None."""
    if refine not in REFINES:
        raise ValueError(f"refine must be one of {', '.join(REFINES)}, got {refine!r}")
    centres = find_grid(gray, board)
    if centres is None:
        return None
    if refine == "centroid":
        centres = refine_centres(gray, centres)
    return centres, board.circle_ids()


def make_detector(board: CircleGrid, refine: str = "centroid"):
    """A calibration detector (as :func:`aicalib_tf.calib.workflow.make_detector` returns): ``detect(gray)
    -> (corners (N, 2), ids (N, 2)) or None`` with ``info``, ``why``, ``relative`` and ``sigmas``."""

    def detect(gray):
        hit = detect_circles(gray, board, refine)
        detect.why = "" if hit is not None else "cv2.findCirclesGrid found no whole grid"
        return hit

    detect.info = {"board": board.describe(), "kind": "circle grid"}
    detect.why, detect.relative, detect.sigmas = "", False, None
    return detect
