"""Which frames of a stream are worth a detection, and which detected views are worth keeping.

* :class:`MotionGate` decides, from a 160-px-wide thumbnail, whether to examine a frame at all:
  while the scene moves fast the frame is blurred, and while nothing has changed since the last
  examined frame it adds nothing; both are skipped without running the detector.
* :func:`blur_px`: the width (px) of the board's most blurred family of edges, from the
  directional derivatives across each lattice direction: motion blur widens the edges across
  the motion and leaves the others sharp, so the worse family tells.
* :func:`board_pose` and :func:`near_duplicate`: a view's pose (with the running lens, or a
  guess before the first fit) and whether a kept view already shows the board there.
* :func:`tilt_of`: the board's turn about the image's vertical and horizontal axes (degrees).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from aicalib_tf.calib.bundle import poses_from_rays
from aicalib_tf.geometry.lens import Lens
from aicalib_tf.geometry.pattern import board_points

__all__ = ["MotionGate", "blur_px", "board_pose", "Pose", "near_duplicate", "tilt_of", "THUMB_WIDTH"]

THUMB_WIDTH = 160  # px, the motion gate's thumbnail


class MotionGate:
    """Decide per frame whether to run the detector (module docstring).

    moving : mean absolute thumbnail difference to the previous frame (grey levels) above which the
    scene moves too fast. changed : difference to the last examined frame below which nothing
    changed. max_gap : examine at least every ``max_gap`` frames whatever the motion.
    """

    def __init__(self, moving: float = 2.0, changed: float = 1.5, max_gap: int = 30):
        self.moving, self.changed, self.max_gap = float(moving), float(changed), int(max_gap)
        self._prev = self._last = None
        self._since = 0

    @staticmethod
    def thumbnail(gray: np.ndarray) -> np.ndarray:
        """(h, 160) float32 grey thumbnail (area average)."""
        h, w = gray.shape
        tw = min(THUMB_WIDTH, w)
        return cv2.resize(gray, (tw, max(1, round(h * tw / w))), interpolation=cv2.INTER_AREA).astype(np.float32)

    def check(self, gray: np.ndarray) -> str:
        """"" to examine the frame, else why not (the frame is then not examined)."""
        t = self.thumbnail(gray)
        prev, self._prev = self._prev, t
        self._since += 1
        if self._last is None or prev is None or self._since >= self.max_gap:
            self._last, self._since = t, 0
            return ""
        if float(np.mean(np.abs(t - prev))) > self.moving:
            return "moving fast (blurred)"
        if float(np.mean(np.abs(t - self._last))) < self.changed:
            return "unchanged since the last frame examined"
        self._last, self._since = t, 0
        return ""


def _lattice_steps(corners: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """(2, 2) px per board step along the columns (row 0) and the rows (row 1), an affine fit."""
    A = np.column_stack([ids.astype(np.float64), np.ones(len(ids))])
    coef, *_ = np.linalg.lstsq(A, corners.astype(np.float64), rcond=None)
    return coef[:2]


def blur_px(gray: np.ndarray, corners: np.ndarray, ids: np.ndarray) -> float:
    """Edge width (px) of the board's most blurred edge family: contrast over the 99th percentile of
    the derivative across the edges, for each lattice direction; about 1.3 px for a sharp render,
    about the motion length for motion blur. gray : (H, W) uint8 or float; corners (N, 2) px;
    ids (N, 2) (col, row). NaN when the board's box is too small to tell."""
    c = np.asarray(corners, np.float64)
    steps = _lattice_steps(c, np.asarray(ids))
    pad = 0.5 * float(np.max(np.linalg.norm(steps, axis=1)))
    h, w = gray.shape
    x0, y0 = (int(max(0, math.floor(v - pad))) for v in c.min(axis=0))
    x1, y1 = int(min(w, math.ceil(c[:, 0].max() + pad) + 1)), int(min(h, math.ceil(c[:, 1].max() + pad) + 1))
    if x1 - x0 < 8 or y1 - y0 < 8:
        return float("nan")
    crop = np.asarray(gray[y0:y1, x0:x1], np.float32)
    gx = cv2.Sobel(crop, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(crop, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    lo, hi = np.percentile(crop, [5, 95])
    widths = []
    for s in steps:  # edges along the step direction s: their normal is s turned by 90°
        n = np.array([-s[1], s[0]]) / max(float(np.linalg.norm(s)), 1e-9)
        d = np.abs(gx * n[0] + gy * n[1])
        widths.append((hi - lo) / max(float(np.percentile(d, 99)), 1e-6))
    return float(max(widths))


@dataclass(frozen=True)
class Pose:
    """A view's board pose: rvec, tvec (3,) (board to camera), normal (3,) unit board normal in the
    camera frame, centre (2,) px mean of the corners, size px (sqrt of the corners' hull area)."""

    rvec: np.ndarray
    tvec: np.ndarray
    normal: np.ndarray
    centre: np.ndarray
    size: float


def _guess_lens(image_size) -> Lens:
    w, h = image_size
    f = 0.6 * math.hypot(w, h)
    return Lens("plumb_bob", [[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]], None, image_size)


def board_pose(corners: np.ndarray, ids: np.ndarray, square: float, image_size, lens: Lens | None = None) -> Pose | None:
    """The view's :class:`Pose` under ``lens`` (None: a pinhole guess, f = 0.6 × the diagonal), or None."""
    c = np.asarray(corners, np.float64)
    obj = board_points(np.asarray(ids), square)
    got = poses_from_rays(lens or _guess_lens(image_size), [obj], [c])
    if got is None:
        return None
    rvec, tvec = got[0][0], got[1][0]
    normal = cv2.Rodrigues(rvec)[0][:, 2]
    hull = cv2.convexHull(c.astype(np.float32))
    return Pose(rvec, tvec, normal, c.mean(axis=0), math.sqrt(max(cv2.contourArea(hull), 1.0)))


def near_duplicate(pose: Pose, kept: list[Pose], image_size, *, shift: float = 0.06, scale: float = 0.15,
                   angle_deg: float = 8.0) -> int | None:
    """Index of a kept pose that shows the board at nearly the same place, size and tilt, or None.

    Same place: centres closer than ``shift`` × the image diagonal; same size: sizes within a
    factor exp(``scale``); same tilt: normals within ``angle_deg``.
    """
    diag = math.hypot(*image_size)
    for k, p in enumerate(kept):
        if np.linalg.norm(pose.centre - p.centre) > shift * diag or abs(math.log(pose.size / p.size)) > scale:
            continue
        if math.degrees(math.acos(float(np.clip(pose.normal @ p.normal, -1.0, 1.0)))) < angle_deg:
            return k
    return None


def tilt_of(pose: Pose) -> tuple[float, float]:
    """(about the vertical axis, about the horizontal axis) in degrees: the board normal's turn
    left/right and up/down, relative to the line of sight to the board (so a board off-centre but
    facing the camera has no tilt)."""
    n = pose.normal if pose.normal @ pose.tvec < 0 else -pose.normal  # the normal towards the camera
    sight = -pose.tvec / max(float(np.linalg.norm(pose.tvec)), 1e-12)
    yaw = math.degrees(math.atan2(n[0], n[2]) - math.atan2(sight[0], sight[2]))
    pitch = math.degrees(math.atan2(n[1], n[2]) - math.atan2(sight[1], sight[2]))
    return (yaw + 180.0) % 360.0 - 180.0, (pitch + 180.0) % 360.0 - 180.0
