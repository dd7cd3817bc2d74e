"""Following a board through a stream of frames: search where it was first (pure numpy/OpenCV + the pipeline).

In video, a board moves a few px from one frame to the next, so a frame need not be searched
from scratch. :class:`Tracker` detects frame by frame and, once it has a full board, tries
cheaper searches first:

1. *follow*: the last board's corners, moved by its last motion (constant velocity), are refined
   on the new frame by the saddle fit of :func:`aicalib_tf.detect.pyramid.refine_full` (no network).
   The board is accepted when every corner is refined, none moved more than ``FOLLOW_SHIFT`` of
   the corner spacing from its prediction (a corner that slid to a neighbouring one moves a whole
   spacing), and the corners still form a lattice (:func:`lattice_bent` at most ``MAX_BEND``);
   its order is then decided again by the full-board rule
   (:func:`aicalib_tf.detect.chessboard.board_order.reading`), as :func:`aicalib_tf.detect.pipeline.detect_corners`
   decides it. Its scores are the CNN weights of the board it followed.
2. *region*: :func:`aicalib_tf.detect.pipeline.detect_corners` on the region around the last board
   (:func:`search_box`: its corners' bounding box, ``ROI_STEPS`` spacings and the last motion
   wider), a full board only.
3. *frame*: the whole frame, as a single image.

A frame without a full board (or of another size) forgets the board: the next frame is searched
whole, unless it shows the same scene as the last frame searched whole (*still*: no block of
``STILL_BLOCK`` thumbnail px changed by ``STILL_LEVEL`` grey levels or more on average,
:func:`scene_changed`); then that search's result stands, for at most ``STILL_MAX`` frames in a
row. A live camera pointed at a scene without the board, or at a board too far or too blurred to
find, shows nearly the same image frame after frame: the result of the same image is not searched
for again. The thresholds sit far above a camera's noise in a block's mean (a block averages
thousands of pixels) and far below a board's edge entering it. Coordinates are (x, y) px, OpenCV's convention (the centre of pixel (0, 0) at (0.0, 0.0)); a
box ``(x0, y0, x1, y1)`` holds pixels x0 … x1 − 1 and y0 … y1 − 1.
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from aicalib_tf.detect.chessboard.board_order import full_board_ids, reading
from aicalib_tf.detect.corners.sigma import with_sigmas
from aicalib_tf.detect.corners.junctions import nearest_spacing
from aicalib_tf.detect.detection import Detection
from aicalib_tf.detect.pipeline import detect_corners
from aicalib_tf.detect.pyramid import refine_full
from aicalib_tf.geometry.image_circle import thumbnail
from aicalib_tf.io import load_image, to_gray_float

__all__ = ["FOLLOW_SHIFT", "MAX_BEND", "ROI_STEPS", "STILL_LEVEL", "STILL_MAX", "Tracker", "follow", "lattice_bent",
           "scene_changed", "scene_thumbnail", "search_box"]

FOLLOW_SHIFT = 0.3  # of the median corner spacing: the furthest a followed corner may end from its prediction
MAX_BEND = 0.25  # of the median spacing: the largest second difference along a row or column of a followed board
ROI_STEPS = 2.0  # corner spacings around the last board searched before the whole frame
ALIGN = 32  # px: a region's sides are rounded up to multiples of this (the network keeps a plan per input size)
MARGIN = 8  # px around the predicted corners read for the follow step (beyond the largest saddle window)
STILL_SIDE = 160  # px: the longer side of the thumbnail a frame is compared at
STILL_BLOCK = 8  # thumbnail px: the side of the blocks whose mean change is tested
STILL_LEVEL = 4.0  # grey levels of 255: a block's mean absolute change at or above this is a changed scene
STILL_MAX = 15  # frames: a still scene is searched again at least this often


def lattice_bent(corners: np.ndarray, pattern_size: tuple[int, int]) -> float:
    """How far a full board's corners are from a lattice: the largest second difference along a
    row or a column, px, over the median corner spacing.

    corners : (cols·rows, 2) px, row-major. A board under perspective and lens distortion bends
    little (under 0.1 on evaluate's boards); a corner that slid to its neighbour bends it by about 1.
    """
    cols, rows = pattern_size
    g = np.asarray(corners, np.float64).reshape(rows, cols, 2)
    worst = 0.0
    for a in (g, g.transpose(1, 0, 2)):
        if a.shape[1] >= 3:
            d2 = a[:, 2:] - 2.0 * a[:, 1:-1] + a[:, :-2]
            worst = max(worst, float(np.linalg.norm(d2, axis=2).max()))
    step = float(np.median(nearest_spacing(g.reshape(-1, 2).astype(np.float32))))
    return worst / step if step > 0 else np.inf


def search_box(corners: np.ndarray, size: tuple[int, int], pad: float) -> tuple[int, int, int, int] | None:
    """The region around ``corners`` (N, 2) px, ``pad`` px wider on each side, sides rounded up to
    multiples of ``ALIGN`` px, clipped to the frame of ``size`` (width, height).

    Returns (x0, y0, x1, y1) int, or None when less than 8 px of it lies in the frame on a side.
    """
    w, h = size
    pts = np.asarray(corners, np.float64).reshape(-1, 2)
    if len(pts) == 0 or not np.all(np.isfinite(pts)):
        return None
    lo, hi = pts.min(axis=0) - pad, pts.max(axis=0) + pad
    side = np.ceil((hi - lo + 1) / ALIGN) * ALIGN
    centre = 0.5 * (lo + hi)
    x0, y0 = np.maximum(np.floor(centre - side / 2), 0).astype(int)
    x1, y1 = np.minimum(np.floor(centre - side / 2) + side, [w, h]).astype(int)
    if x1 - x0 < 8 or y1 - y0 < 8:
        return None
    return int(x0), int(y0), int(x1), int(y1)


def _gray(raw: np.ndarray) -> np.ndarray:
    """A frame as the pipeline takes it: a uint8 grey frame as it is, any other through the image gate
    ((H, W) float32 in [0, 1]), so that it is converted once."""
    return raw if raw.ndim == 2 and raw.dtype == np.uint8 else to_gray_float(raw)


def scene_thumbnail(raw: np.ndarray) -> np.ndarray:
    """(h, w) float32 grey levels of 255: a frame (any array the image gate takes) shrunk by area
    averaging to a longer side of ``STILL_SIDE`` px."""
    gray = _gray(raw)
    small = thumbnail(gray, STILL_SIDE)
    return small if gray.dtype == np.uint8 else small * np.float32(255.0)


def scene_changed(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two thumbnails of :func:`scene_thumbnail` show a changed scene: a block of
    ``STILL_BLOCK`` px whose mean absolute difference reaches ``STILL_LEVEL``, or another size."""
    if a.shape != b.shape:
        return True
    d = np.abs(a - b)
    h, w = d.shape
    blocks = cv2.resize(d, (max(1, w // STILL_BLOCK), max(1, h // STILL_BLOCK)), interpolation=cv2.INTER_AREA)
    return bool(blocks.max() >= STILL_LEVEL)


def _crop_gray(raw: np.ndarray, box: tuple[int, int, int, int]) -> np.ndarray:
    """The region ``box`` of a frame (any array the image gate takes) as float32 grey in [0, 1]."""
    x0, y0, x1, y1 = box
    return to_gray_float(raw[y0:y1, x0:x1])


def follow(raw: np.ndarray, predicted: np.ndarray,
           pattern_size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray] | None:
    """Step 1 of the module docstring: the predicted corners refined on the frame, or None.

    raw : (H, W[, C]) frame as the image gate takes it. predicted : (cols·rows, 2) px, row-major.
    Returns the permutation (cols·rows,) int that puts them in the full-board order of the rule
    and the refined corners (cols·rows, 2) float32 px in that order, or None.
    """
    h, w = raw.shape[:2]
    spacing = float(np.median(nearest_spacing(np.asarray(predicted, np.float32))))
    box = search_box(predicted, (w, h), MARGIN + 6)
    if box is None or not np.all((predicted >= 0) & (predicted <= [w - 1, h - 1])):
        return None
    gray = _crop_gray(raw, box)
    offset = np.array(box[:2], np.float32)
    corners, ok = refine_full(gray, predicted - offset, max_shift=FOLLOW_SHIFT * spacing)
    if not ok.all() or lattice_bent(corners, pattern_size) > MAX_BEND:
        return None
    perm = reading(corners, pattern_size, gray)
    return perm, (corners[perm] + offset).astype(np.float32)


def _aligned(before: np.ndarray, now: np.ndarray, pattern_size: tuple[int, int]) -> np.ndarray:
    """``before`` (cols·rows, 2) px re-read by the board's symmetry that brings it nearest to ``now``:
    the same corners in ``now``'s order (the rule's order can change between frames)."""
    from aicalib_tf.geometry.pattern import board_symmetries

    return min((before[p] for p in board_symmetries(pattern_size)),
               key=lambda b: float(np.square(b - now).sum()))


class Tracker:
    """Detects a board in each frame of a stream, searching near the last board first (module docstring).

    pattern_size : (cols, rows) inner corners. model, threshold : as
    :func:`aicalib_tf.detect.pipeline.detect_corners`. Call it with each frame (a path or an array the
    image gate takes); it returns the frame's :class:`~aicalib_tf.detect.detection.Detection`.
    ``how`` says how the last frame's board was found: "follow", "region", "frame" or "" (none), or
    "still" when the frame repeats the scene of the last frame searched whole, whose result it gets.

    >>> from aicalib_tf.detect.warm import synthetic_board
    >>> track = Tracker((9, 6))
    >>> [track(synthetic_board(shift=(3 * k, 0))).complete for k in range(3)], track.how
    ([True, True, True], 'follow')
    """

    def __init__(self, pattern_size: tuple[int, int], *, model=None, threshold: float = 0.5):
        from aicalib_tf.geometry.pattern import check_pattern

        check_pattern(pattern_size)
        self.pattern_size = (int(pattern_size[0]), int(pattern_size[1]))
        self.model, self.threshold = model, threshold
        self.how = ""
        self.reset()

    def reset(self) -> None:
        """Forget the board: the next frame is searched whole."""
        self._last = self._before = self._scores = None
        self._size = None
        self._still = None  # (thumbnail, detection, frames reused) of the last frame searched whole without a board

    def __call__(self, image) -> Detection:
        raw = image if isinstance(image, np.ndarray) and image.ndim in (2, 3) else load_image(image)
        h, w = raw.shape[:2]
        if self._size != (w, h):
            self.reset()
        self._size, self.how = (w, h), ""
        gray = _gray(raw) if self._last is None else None  # read whole only when no board is followed
        thumb = None if gray is None else scene_thumbnail(gray)
        det = self._near(raw, (w, h)) if self._last is not None else self._repeat(thumb)
        if det is None:
            gray = _gray(raw) if gray is None else gray
            det = detect_corners(gray, self.pattern_size, model=self.model, threshold=self.threshold)
            self.how = "frame" if det.complete else ""
            self._still = None if det.complete else (scene_thumbnail(gray) if thumb is None else thumb, det, 0)
        if det.complete:
            # the motion is taken between the two boards in one order
            self._before = None if self._last is None else _aligned(self._last, det.corners, self.pattern_size)
            self._last, self._scores = det.corners, det.scores
        else:
            self._last = self._before = self._scores = None
        return det

    def _repeat(self, thumb: np.ndarray) -> Detection | None:
        """The last whole-frame search's result when ``thumb`` shows its scene (module docstring), or None."""
        if self._still is None:
            return None
        seen, det, reused = self._still
        if reused >= STILL_MAX or scene_changed(thumb, seen):
            return None
        self._still, self.how = (seen, det, reused + 1), "still"
        return det

    def _near(self, raw: np.ndarray, size: tuple[int, int]) -> Detection | None:
        """Steps 1 and 2 of the module docstring around the last board, or None."""
        motion = self._last - self._before if self._before is not None else np.zeros_like(self._last)
        predicted = self._last + motion
        got = follow(raw, predicted, self.pattern_size)
        if got is not None:
            self.how, (perm, corners) = "follow", got
            ids = full_board_ids(self.pattern_size)
            det = Detection(corners, ids, self._scores[perm], self.pattern_size, True, size)
            return with_sigmas(det, lambda x0, y0, x1, y1: _crop_gray(raw, (x0, y0, x1, y1)))
        spacing = float(np.median(nearest_spacing(self._last)))
        pad = ROI_STEPS * spacing + float(np.abs(motion).max())
        box = search_box(np.concatenate([self._last, predicted]), size, pad)
        if box is None:
            return None
        det = detect_corners(_crop_gray(raw, box), self.pattern_size, model=self.model, threshold=self.threshold)
        if not det.complete:
            return None
        self.how = "region"
        return replace(det, corners=det.corners + np.array(box[:2], np.float32), image_size=size)
