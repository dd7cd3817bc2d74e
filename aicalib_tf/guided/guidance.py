"""What the user should show the camera next, and what is still missing.

:func:`next_views` ranks candidate views by the projection uncertainty they would leave: a board
in each of the image's nine regions, at the kept views' median distance, facing the camera or
turned by 35° about the image's vertical or horizontal axis. Each candidate's information (its
pose eliminated; :func:`aicalib_tf.calib.quality.view_information`) is added to the current
fit's, and the predicted 1σ map is averaged over the image (the idea of Rojtberg & Kuijper,
ISMAR 2018: the current covariance picks the next pose). :func:`missing` lists the regions no
board has covered and the tilts no kept view has, in words a user can act on.

With an image circle (a circular fisheye's) neither points outside it: a region's board is centred
no further out than :data:`RIM_FRACTION` of the radius in the region's direction, only its corners
imaged inside the circle count, and a region outside the circle is not listed as missing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from aicalib_tf.calib.coverage import uncovered_regions
from aicalib_tf.calib.quality import sigma_from_basis, view_information
from aicalib_tf.geometry.lens import Lens
from aicalib_tf.geometry.pattern import board_points, pattern_ids
from aicalib_tf.geometry.pose import in_frame

__all__ = ["Suggestion", "next_views", "candidate_points", "missing", "REGIONS", "TILTS", "MIN_TILT_DEG",
           "RIM_FRACTION"]

REGIONS = {"top-left": (0, 0), "top": (1, 0), "top-right": (2, 0), "left": (0, 1), "centre": (1, 1),
           "right": (2, 1), "bottom-left": (0, 2), "bottom": (1, 2), "bottom-right": (2, 2)}
TILTS = {"facing the camera": (0.0, 0.0), "turned left about its vertical axis": (35.0, 0.0),
         "turned right about its vertical axis": (-35.0, 0.0), "tilted back about its horizontal axis": (0.0, 35.0),
         "tilted forward about its horizontal axis": (0.0, -35.0)}
MIN_TILT_DEG = 20.0  # a tilt family counts as shown once a kept view is turned this far
RIM_FRACTION = 0.7  # with an image circle: a suggested board's centre lies at most this share of its radius out


@dataclass(frozen=True)
class Suggestion:
    """region : a :data:`REGIONS` name; tilt : a :data:`TILTS` name; sigma_px : the predicted mean 1σ
    over the image with that view added; text : one line for the user."""

    region: str
    tilt: str
    sigma_px: float
    text: str


def _region_centre(region: str, image_size, circle=None) -> np.ndarray:
    """(2,) px: the centre of a :data:`REGIONS` cell of the frame, drawn in towards the image ``circle``'s
    centre to :data:`RIM_FRACTION` of its radius when it lies further out (None: no circle)."""
    w, h = image_size
    i, j = REGIONS[region]
    p = np.array([(i + 0.5) / 3.0 * w - 0.5, (j + 0.5) / 3.0 * h - 0.5])
    if circle is None:
        return p
    c = np.array([circle.cx, circle.cy], np.float64)
    d = float(np.linalg.norm(p - c))
    reach = RIM_FRACTION * circle.radius
    return p if d <= reach else c + (p - c) * (reach / d)


def _facing(ray: np.ndarray) -> np.ndarray:
    """(3, 3) rotation taking the board's z axis onto ``ray`` (the board faces the camera along it)."""
    d = ray / np.linalg.norm(ray)
    axis = np.cross([0.0, 0.0, 1.0], d)
    s = float(np.linalg.norm(axis))
    return np.eye(3) if s < 1e-12 else cv2.Rodrigues(axis / s * math.atan2(s, d[2]))[0]


def candidate_points(lens: Lens, region: str, tilt: str, distance: float, pattern, square: float,
                     circle=None) -> np.ndarray | None:
    """(N, 3) camera-frame corners of a board centred on ``region`` at ``distance`` with ``tilt``,
    only those imaged inside the frame (and inside the image ``circle``, an
    :class:`~aicalib_tf.geometry.image_circle.ImageCircle` or None); None when fewer than 12 are."""
    ray = lens.unproject(_region_centre(region, lens.image_size, circle))
    if not np.all(np.isfinite(ray)):
        return None
    yaw, pitch = (math.radians(a) for a in TILTS[tilt])
    R = cv2.Rodrigues(np.array([0.0, yaw, 0.0]))[0] @ cv2.Rodrigues(np.array([pitch, 0.0, 0.0]))[0] @ _facing(ray)
    obj = board_points(pattern_ids(pattern), square)
    centre = obj.mean(axis=0)
    P = (obj - centre) @ R.T + distance * ray / np.linalg.norm(ray)
    uv = lens.project(P)
    ok = np.all(np.isfinite(uv), axis=1) & (P[:, 2] > 0) & in_frame(uv, lens.image_size, border=2.0)
    if circle is not None:
        ok &= circle.contains(np.where(np.isfinite(uv), uv, -1e9), margin=-2.0)
    return P[ok] if ok.sum() >= 12 else None


def _where(region: str, circle) -> str:
    """Where to hold the board, in words: "the top-left corner of the image", or, with an image
    circle, "the top-left of the image circle, towards its rim"."""
    if region == "centre":
        return "the centre of the image" + (" circle" if circle is not None else "")
    if circle is not None:
        return f"the {region} of the image circle, towards its rim"
    return f"the {region} {'corner' if '-' in region else 'edge'} of the image"


def next_views(lens: Lens, information: np.ndarray, basis, distance: float, pattern, square: float,
               sigma2: float, circle=None) -> list[Suggestion]:
    """Candidate views ranked best first (module docstring).

    information : (4+n, 4+n) the current fit's inverse covariance. basis : (G, ok) of
    :func:`aicalib_tf.calib.quality.uncertainty_basis` (ok: the grid points to average over; with an
    image circle, those inside it). distance : board distance (board units). sigma2 : the fit's
    residual variance, px², which scales a new view's JᵀJ. circle : the image circle or None.
    """
    G, ok = basis
    out = []
    for region in REGIONS:
        for tilt in TILTS:
            P = candidate_points(lens, region, tilt, distance, pattern, square, circle)
            if P is None:
                continue
            cov = np.linalg.pinv(information + view_information(lens, P) / sigma2, hermitian=True)
            s = float(np.nanmean(sigma_from_basis(G, ok, cov)))
            out.append(Suggestion(region, tilt, s, f"next: hold the board at {_where(region, circle)}, {tilt}"))
    return sorted(out, key=lambda c: c.sigma_px)


def missing(views, tilts: list[tuple[float, float]], image_size, circle=None) -> list[str]:
    """What no kept view shows yet, one sentence each: uncovered image regions, then tilt families.

    views : the kept views (``corners`` (N, 2) px); tilts : (about vertical, about horizontal) degrees
    of each (:func:`aicalib_tf.guided.selection.tilt_of`). circle : the image circle of a circular
    fisheye (regions outside it cannot be covered and are not asked for), or None."""
    out = []
    for region in uncovered_regions(views, image_size, circle):
        out.append(f"{region} corner not covered" if "-" in region else f"{region} of the image not covered")
    yaw = max((abs(t[0]) for t in tilts), default=0.0)
    pitch = max((abs(t[1]) for t in tilts), default=0.0)
    if yaw < MIN_TILT_DEG:
        out.append("tilt the board about its vertical axis (turn it left or right by 30-45 degrees)")
    if pitch < MIN_TILT_DEG:
        out.append("tilt the board about its horizontal axis (top towards or away from the camera by 30-45 degrees)")
    return out
