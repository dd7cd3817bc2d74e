"""Each board corner's contrast against the image's noise about it, and the localisation bound they imply.

A refined corner is the saddle of the smoothed image (:mod:`aicalib_tf.detect.corners.refine`). Where the
junction's contrast is near the noise (a fisheye's rim under a cos⁴ light fall-off: a few grey levels of
contrast under noise σ 4–5), the smoothed noise makes saddles of its own a px or two about the junction, and
which one the refinement settles in depends on where it started: the corner's place is then not decided by
the image (a threshold regime, beyond which the error is no longer the small-noise bound below but the
distance to a noise saddle). This module measures, in each corner's refinement window (radius
:func:`aicalib_tf.detect.corners.refine.window_radius` of the spacing):

* ``noise``: the white noise σ of the pixels about the corner, grey levels, from the response of the mask
  [1 −2 1]ᵀ[1 −2 1] (Immerkær's fast noise estimate: a plane, a light ramp and an edge along a pixel axis
  leave none, white noise a σ of 6σ), robustly (median |response| / 0.6745 / 6), at least one grey level's
  rounding noise (1/√12);
* ``contrast``: the X-junction's signed contrast, grey levels: the mean of the window's pixels in the two
  sectors between the board's lines through the corner (the lattice directions to its neighbours by id)
  that the board's colour order makes bright, less the mean of the two dark ones, pixels within
  ``GAP`` px of either line left out (the edges' blur); negative where the corner's sectors have the
  colours of the other parity (no junction of this board there);
* ``cnr``: contrast / noise, per pixel; ``z``: the contrast in standard errors of the two sector means
  (contrast / (noise · √(1/n₊ + 1/n₋))): whether the window shows this board's junction at all;
* ``bound``: px per axis, the Cramér–Rao-like localisation bound of a junction of that contrast: a blurred
  step of contrast C (edge σ_b px) holds Fisher information C²/(2√π σ_b σ²) per px of line about the shift
  across it; each of the junction's two lines crosses the window's 2r px, so σ_loc = (noise / contrast) ·
  √(√π σ_b / r) (σ_b = ``EDGE`` px, a sharp render's edge: a lower bound, blur only raises it).

A detection's σ is at least this bound (:func:`aicalib_tf.detect.corners.sigma.board_sigmas`). The cnr is no floor on
which corners a board keeps: on the close-up families (``benchmarks/faint_corners.py``: seed 301, both lens
splits, the shipped network and a fine-tuned one) corners of cnr 1–2 miss their truth by a median 0.4–0.7 px
and up to 2.07 px, their saddle fits started a px or two apart end on different noise saddles, and the fine-tuned
network's two wrong boards there (a corner of cnr 1.9 and one of 0.9, 2.07 px off) are the tail of that spread:
a floor of 2 that refuses both also refuses 16 of its 296 hits (the shipped network's: 12 of 292). A corner whose
sectors show the other colour order (``z`` under −``REVERSED_Z``) is no junction of the board in that place, and
:func:`without_reversed` leaves it out of a full board.

Coordinates are (x, y) px with the centre of pixel (0, 0) at (0.0, 0.0).
"""

from __future__ import annotations

import math
import weakref

import numpy as np

from aicalib_tf.detect.corners.refine import window_radius

__all__ = ["GAP", "EDGE", "MIN_SECTOR", "REVERSED_Z", "local_noise", "lattice_directions", "sector_contrast",
           "corner_contrast", "board_contrast", "without_reversed"]

GAP = 0.75  # px: pixels nearer than this to either line through the corner are left out of the sector means
EDGE = 1.0  # px: the edge σ the bound takes (a sharp render's; blur only raises the bound)
MIN_SECTOR = 4  # pixels: fewer in either sign's sectors (lines meeting at a sharp angle) and the contrast is not measured
_MAD = 0.6745  # median |x| / σ of a normal x
_MASK_GAIN = 6.0  # σ of the mask [1 -2 1]ᵀ[1 -2 1]'s response to white noise of σ 1 (√36)


def local_noise(gray: np.ndarray, pts: np.ndarray, radius: np.ndarray, step: float = 1.0) -> np.ndarray:
    """(N,) the white noise σ (grey levels of ``gray``) of the pixels about each corner (module docstring).

    gray : (H, W) uint8 or float. pts : (N, 2) px. radius : (N,) int, each window's radius: the mask's responses
    at the (2r + 1)² pixels about the pixel at or before the corner. step : one grey level in gray's units (1/255 for
    a float image in [0, 1]): the estimate is at least its rounding noise step/√12.
    """
    return _measure(gray, pts, None, radius, step)[2]


def _noise(p: np.ndarray) -> np.ndarray:
    """(N,) σ of white noise from patches p (N, S, S): the median |response| of the mask at the (S − 2)² inner pixels."""
    rows = p[:, :-2] - 2.0 * p[:, 1:-1] + p[:, 2:]  # second differences down the columns
    resp = np.abs(rows[:, :, :-2] - 2.0 * rows[:, :, 1:-1] + rows[:, :, 2:]).reshape(len(p), -1)  # then along the rows
    k = resp.shape[1] // 2  # an odd count: the median is its middle value
    return np.partition(resp, k, axis=1)[:, k] / (_MAD * _MASK_GAIN)


def _patches(gray: np.ndarray, centre: np.ndarray, half: int) -> np.ndarray:
    """(N, 2·half + 1, 2·half + 1) float64: the pixels about each integer centre (N, 2) (x, y), the nearest
    edge pixel beyond the image."""
    h, w = gray.shape
    d = np.arange(-half, half + 1)
    rows = np.clip(centre[:, 1, None] + d, 0, h - 1)
    cols = np.clip(centre[:, 0, None] + d, 0, w - 1)
    return np.asarray(gray[rows[:, :, None], cols[:, None, :]], np.float64)


def lattice_directions(pts: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """(N, 2, 2) unit directions of the board's column line and row line through each corner (the steps to
    its neighbours by id: (c ± 1, r) and (c, r ± 1), centred where it has both, one-sided otherwise; the image
    axes where it has none). pts : (N, 2) px. ids : (N, 2) int (col, row), distinct."""
    pts = np.asarray(pts, np.float64).reshape(-1, 2)
    ids = np.asarray(ids, np.int64).reshape(-1, 2)
    out = np.zeros((len(pts), 2, 2))
    if not len(pts):
        return out
    lo = ids.min(axis=0) - 1
    shape = ids.max(axis=0) - lo + 2
    where = np.full((shape[0], shape[1]), -1, np.int64)
    where[ids[:, 0] - lo[0], ids[:, 1] - lo[1]] = np.arange(len(ids))
    c, r = ids[:, 0] - lo[0], ids[:, 1] - lo[1]
    for axis, (dc, dr) in enumerate(((1, 0), (0, 1))):
        ahead, behind = where[c + dc, r + dr], where[c - dc, r - dr]
        fwd = np.where(ahead[:, None] >= 0, pts[np.maximum(ahead, 0)], pts)
        back = np.where(behind[:, None] >= 0, pts[np.maximum(behind, 0)], pts)
        v = fwd - back
        length = np.hypot(v[:, 0], v[:, 1])
        v = np.where(length[:, None] > 0, v / np.maximum(length, 1e-12)[:, None], np.eye(2)[axis])
        out[:, axis] = v
    return out


def sector_contrast(gray: np.ndarray, pts: np.ndarray, ids: np.ndarray, radius: np.ndarray):
    """The X-junction contrast of each corner from its sectors' means (module docstring), before the board's sign.

    gray : (H, W). pts : (N, 2) px. ids : (N, 2) (col, row). radius : (N,) int window radii.
    Returns contrast (N,) (mean of the sectors between the +column and +row directions and its opposite, less the
    mean of the other two; NaN where either sign has fewer than ``MIN_SECTOR`` pixels) and the two counts (N, 2).
    """
    contrast, counts, _ = _measure(gray, pts, lattice_directions(pts, ids), radius, 1.0)
    return contrast, counts


def _measure(gray: np.ndarray, pts: np.ndarray, dirs: np.ndarray | None, radius: np.ndarray, step: float):
    """contrast (N,), counts (N, 2) and noise (N,) of :func:`sector_contrast` and :func:`local_noise`, from one patch of
    (2r + 3)² pixels about the pixel at or before each corner (the disc of radius r + 0.5 about it lies inside);
    dirs (N, 2, 2) or None (noise only)."""
    pts = np.asarray(pts, np.float64).reshape(-1, 2)
    radius = np.asarray(radius, np.int64).reshape(-1)
    contrast, counts, noise = np.full(len(pts), np.nan), np.zeros((len(pts), 2), np.int64), np.zeros(len(pts))
    for r in sorted(set(radius.tolist())):
        sel = np.flatnonzero(radius == r)
        centre = np.floor(pts[sel]).astype(np.int64)
        p = _patches(gray, centre, int(r) + 1)
        noise[sel] = _noise(p)
        if dirs is None:
            continue
        d = np.arange(-int(r) - 1, int(r) + 2, dtype=np.float64)
        ox = d[None, None, :] + (centre[:, 0] - pts[sel, 0])[:, None, None]
        oy = d[None, :, None] + (centre[:, 1] - pts[sel, 1])[:, None, None]
        u, v = dirs[sel, 0], dirs[sel, 1]
        across_u = u[:, 0, None, None] * oy - u[:, 1, None, None] * ox  # signed distance from the column line
        across_v = v[:, 0, None, None] * oy - v[:, 1, None, None] * ox
        inside = (ox * ox + oy * oy <= (r + 0.5) ** 2) & (np.abs(across_u) > GAP) & (np.abs(across_v) > GAP)
        sign = across_u * across_v
        first, second = inside & (sign < 0), inside & (sign > 0)  # between +u and +v (and −u, −v); the other two
        n1, n2 = first.sum(axis=(1, 2)), second.sum(axis=(1, 2))
        diff = (p * first).sum(axis=(1, 2)) / np.maximum(n1, 1) - (p * second).sum(axis=(1, 2)) / np.maximum(n2, 1)
        contrast[sel] = np.where((n1 >= MIN_SECTOR) & (n2 >= MIN_SECTOR), diff, np.nan)
        counts[sel] = np.stack([n1, n2], axis=1)
    return contrast, counts, np.maximum(noise, step / math.sqrt(12.0))


def corner_contrast(gray: np.ndarray, pts: np.ndarray, ids: np.ndarray, spacing: np.ndarray | None = None,
                    step: float | None = None) -> dict:
    """Each board corner's signed contrast, noise, cnr, z and localisation bound (module docstring).

    gray : (H, W) uint8 or float grey. pts : (N, 2) px. ids : (N, 2) int (col, row), distinct. spacing : (N,) px,
    the distance to the nearest other corner (default: measured from pts). step : one grey level in gray's units
    (default 1 for uint8, 1/255 otherwise).
    Returns a dict of (N,) float64 arrays: ``contrast`` (grey levels, positive where the corner's sectors have the
    board's colour order, the board's sign taken from the median over its corners), ``noise`` (grey levels),
    ``cnr``, ``z``, ``bound`` (px, at most the window's radius: where the contrast is nil or of the other colour
    order the image does not place the corner within its window); NaN where the sectors could not be measured
    (``MIN_SECTOR``).
    """
    from aicalib_tf.detect.corners.junctions import nearest_spacing

    pts = np.asarray(pts, np.float64).reshape(-1, 2)
    ids = np.asarray(ids, np.int64).reshape(-1, 2)
    if step is None:
        step = 1.0 if np.asarray(gray).dtype == np.uint8 else 1.0 / 255.0
    spacing = nearest_spacing(pts) if spacing is None else np.asarray(spacing, np.float64)
    radius = window_radius(spacing)
    raw, counts, noise = _measure(gray, pts, lattice_directions(pts, ids), radius, step)
    parity = np.where(ids.sum(axis=1) % 2 == 0, 1.0, -1.0)
    signed = raw * parity
    known = np.isfinite(signed)
    board = np.sign(np.median(signed[known])) if known.any() else 1.0
    contrast = signed * (board if board != 0 else 1.0)
    cnr = contrast / noise
    n = np.maximum(counts, 1).astype(np.float64)
    z = cnr / np.sqrt(1.0 / n[:, 0] + 1.0 / n[:, 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = np.where(contrast > 0, np.sqrt(math.sqrt(math.pi) * EDGE / radius) / cnr, np.inf)
    bound = np.minimum(bound, radius)  # no contrast of the board's order: the window, not the junction, bounds it
    bound[~known] = np.nan
    return {"contrast": contrast, "noise": noise, "cnr": cnr, "z": z, "bound": bound}


def board_contrast(image, corners: np.ndarray, ids: np.ndarray, size: tuple[int, int]) -> dict:
    """:func:`corner_contrast` of a board in ``image``, converting no more of it than needed.

    image : a :class:`~aicalib_tf.detect.pyramid.Frame` (a grey uint8 frame is read as it is, any other through its
    float grey), or ``region(x0, y0, x1, y1) -> (y1 − y0, x1 − x0) float32`` grey in [0, 1], asked for the part about
    the corners. corners : (N, 2) px. ids : (N, 2). size : (width, height) px.
    The last board's measure is kept for the same Frame object (one detection's, never changed) and the same corners,
    ids and size: the detector asks twice for a returned board (its σ, then :func:`without_reversed`), 0.7 ms CPU a
    54-corner board each. The returned arrays are shared with that memo: read them, do not write to them.
    """
    if getattr(image, "raw", None) is None:  # a region reader: measured each time
        return _board_contrast(image, corners, ids, size)
    key = (np.asarray(corners, np.float64).tobytes(), np.asarray(ids).tobytes(), tuple(size))
    last = _LAST.get("entry")
    if last is not None and last[0]() is image and last[1] == key:
        return last[2]
    ref = weakref.ref(image)
    got = _board_contrast(image, corners, ids, size)
    _LAST["entry"] = (ref, key, got)
    return got


_LAST: dict = {}  # "entry": (weak reference to the image, the corners/ids/size key, board_contrast's result)


def _board_contrast(image, corners: np.ndarray, ids: np.ndarray, size: tuple[int, int]) -> dict:
    """:func:`board_contrast`, measured."""
    pts = np.asarray(corners, np.float64).reshape(-1, 2)
    if len(pts) == 0:
        return {k: np.zeros(0) for k in ("contrast", "noise", "cnr", "z", "bound")}
    raw = getattr(image, "raw", None)
    if raw is not None and raw.dtype == np.uint8 and raw.ndim == 2:
        return corner_contrast(raw, pts, ids)
    region = image.region if raw is not None else image
    pad = int(window_radius(np.array([1e6]))[0]) + 2  # the largest window, its noise mask's ring and rounding
    x0, y0 = (max(int(np.floor(v)) - pad, 0) for v in pts.min(axis=0))
    x1 = min(int(np.ceil(pts[:, 0].max())) + pad + 1, size[0])
    y1 = min(int(np.ceil(pts[:, 1].max())) + pad + 1, size[1])
    from aicalib_tf.detect.corners.junctions import nearest_spacing

    return corner_contrast(region(x0, y0, x1, y1), pts - np.array([x0, y0], np.float64), ids, nearest_spacing(pts),
                           step=1.0 / 255.0)



REVERSED_Z = 3.0  # standard errors: a corner whose sectors show the other colour order by more is not this board's junction


def without_reversed(det, image):
    """A complete detection (:class:`~aicalib_tf.detect.detection.Detection`) without its corners whose sectors have the
    colours of the other parity (``z`` under −``REVERSED_Z``, :func:`board_contrast`): a junction of the board's
    neighbouring order, or none, in the place of this one (a close-up's rim corner placed a square off: 8 px). As it is
    when it has none (or is not complete), else a partial board (complete False) without them. image : as
    :func:`board_contrast`. Over the close-up families (seeds 301 and 97, both lens splits, the shipped network and a
    fine-tuned one) no hit has such a corner: the least z of a hit's corner is positive.
    """
    from dataclasses import replace

    if not det.complete or not len(det.corners):
        return det
    keep = ~(board_contrast(image, det.corners, det.ids, det.image_size)["z"] < -REVERSED_Z)  # NaN: unmeasured, stays
    if keep.all():
        return det
    return replace(det, corners=det.corners[keep], ids=det.ids[keep], scores=det.scores[keep], complete=False,
                   sigmas=None if det.sigmas is None else det.sigmas[keep])
