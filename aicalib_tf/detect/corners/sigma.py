"""Each detected corner's σ: how far off its position is likely to be, from what the image shows there.

A refined corner is the saddle of the smoothed image in a window about it (:mod:`aicalib_tf.detect.corners.refine`).
Its error grows with the noise in that window and with whatever breaks the X-junction's point
symmetry (a shadow edge, an object in front, JPEG blocks), with blur, and with lines that bend
across the window (a strong lens), and shrinks with the junction's contrast. It is measured in
each corner's window of the unsmoothed image (bilinear samples on the (2r + 1)² grid about the
corner, r the refinement's radius for the distance to the nearest other corner,
:func:`aicalib_tf.detect.corners.refine.window_radius`, at most 3 px; :func:`aicalib_tf.detect.corners.sigma_kernels.window_measures`):

* ``odd``: √(Σ w o²), o(d) = (I(c + d) − I(c − d)) / 2 the part of the window that is not
  point-symmetric about the corner (noise and asymmetry), w the saddle fit's Gaussian weights
  (summing to 1), grey levels in [0, 1]; ``odd_median``: the median of |o|, the same for noise but
  hardly moved by an edge across part of the window;
* ``even``: the weighted standard deviation of the symmetric part, the junction's contrast;
* ``residual``: the weighted RMS of what the saddle fit's quadratic leaves (small under blur);
* ``bend``: |c(i−1) − 2c(i) + c(i+1)| along the board's rows and columns by id, px
  (:func:`aicalib_tf.detect.corners.sigma_kernels.lattice_bend`), over the corner spacing;
* the network's ``score``.

The noise is one per image, so it is taken as the board's median ``odd_median`` (a corner's own is
a noisy estimate of it); the corner's own enters as its excess over that. The model is
log σ = c₀ + Σ cₖ xₖ, x the columns of :func:`design` clipped to [``LOW``, ``HIGH``], the range they
took in fitting; σ px is one standard deviation per axis (isotropic).

``COEFFS``, ``LOW`` and ``HIGH`` were fitted on rendered boards with exact truth (data_gen renders of
the benchmark's sweeps and named conditions with other seeds than the benchmark's), to make the
mean σ² of each image agree with its mean squared error per axis, with a small maximum-likelihood
term (each error Gaussian with its corner's σ). ``python benchmarks/corner_sigma.py --fit`` refits
and prints them; ``python benchmarks/corner_sigma.py`` compares predicted and measured errors per
condition on the benchmark's own renders.
"""

from __future__ import annotations

import functools
from dataclasses import replace

import numpy as np

from aicalib_tf.detect.corners.sigma_kernels import board_columns
from aicalib_tf.detect.corners.refine import window_radius
from aicalib_tf.detect.corners.saddle import saddle_fit_matrix

__all__ = ["COLUMNS", "COEFFS", "LOW", "HIGH", "design", "sigma_from_design", "board_design", "board_sigmas",
           "with_sigmas"]

COLUMNS = ("noise/contrast", "own excess asymmetry", "residual/contrast", "impulsive noise", "bend/spacing", "score",
           "(noise/contrast)²")
# log σ = COEFFS[0] + Σ COEFFS[1 + k] · clip(design[:, k], LOW[k], HIGH[k]); refit: python benchmarks/corner_sigma.py --fit
COEFFS = np.array([-0.679, 0.497, 2.325, 0.464, -0.230, 0.100, -0.707, -0.092])
LOW = np.array([-4.855, -0.901, -2.336, 0.266, -6.022, -0.693, 1.274])
HIGH = np.array([-1.129, 0.720, -0.252, 1.187, -1.660, 0.000, 23.575])
MIN_SCORE = 0.05  # a corner the network missed (score 0) counts as this weak
_TINY = 1e-6  # grey levels (px for the bend): keeps the logarithms finite in a flat window
_MAX_RADIUS = 3  # px: the refinement's window radius, at most this (a 7×7 window: the measures' cost)


@functools.lru_cache(maxsize=1)
def _operators() -> tuple[np.ndarray, np.ndarray]:
    """Each radius' quadratic fit (R + 1, 6, (2R+1)²) and normalized Gaussian weights (R + 1, (2R+1)²), R = ``_MAX_RADIUS``."""
    big = (2 * _MAX_RADIUS + 1) ** 2
    fits, weights = np.zeros((_MAX_RADIUS + 1, 6, big)), np.zeros((_MAX_RADIUS + 1, big))
    for r in range(1, _MAX_RADIUS + 1):
        offsets, p = saddle_fit_matrix(r)
        s = r / 2.0 + 0.5
        w = np.exp(-(offsets[:, 0].astype(np.float64) ** 2 + offsets[:, 1].astype(np.float64) ** 2) / (2 * s * s))
        fits[r, :, :p.shape[1]], weights[r, :len(w)] = p, w / w.sum()
    return fits, weights


def design(gray: np.ndarray, corners: np.ndarray, ids: np.ndarray, scores: np.ndarray) -> np.ndarray:
    """The model's columns (N, 7) (``COLUMNS``) of one board's corners, unclipped (module docstring).

    gray : (H, W) float32 grey in [0, 1] or uint8, unsmoothed (every column is a ratio of grey levels
    or of px, so either scale gives the same). corners : (N, 2) (x, y) px. ids : (N, 2) int
    (col, row), distinct. scores : (N,) network responses in [0, 1].
    Columns: log(board noise / contrast), log(own odd_median / board's), log(residual / contrast),
    log(board odd / board odd_median) (salt-and-pepper pixels raise the first, not the second),
    log(bend / spacing), log(score), and the first column squared (the error grows faster than the
    noise once it is well above the floor of a clean render). The board's values are medians of the
    logarithms over its corners; a corner with no row or column through it takes the board's median bend
    (:func:`aicalib_tf.detect.corners.sigma_kernels.design_columns`).
    """
    from aicalib_tf.detect.corners.junctions import nearest_spacing

    pts = np.ascontiguousarray(np.asarray(corners, np.float64).reshape(-1, 2))
    if len(pts) == 0:
        return np.zeros((0, len(COLUMNS)))
    spacing = nearest_spacing(pts)
    radius = np.minimum(window_radius(spacing), _MAX_RADIUS)
    fits, weights = _operators()
    img = gray if gray.dtype == np.uint8 and gray.ndim == 2 else np.asarray(gray, np.float32)
    return board_columns(np.ascontiguousarray(img), pts, np.asarray(ids, np.int64).reshape(-1, 2), spacing, radius,
                         np.asarray(scores, np.float64).reshape(-1), fits, weights, MIN_SCORE,
                         _TINY * (255.0 if img.dtype == np.uint8 else 1.0))


def sigma_from_design(x: np.ndarray, coeffs: np.ndarray = COEFFS, low: np.ndarray = LOW, high: np.ndarray = HIGH) -> np.ndarray:
    """σ (N,) float32 px of design columns x (N, 7) under the model (``coeffs`` (8,), clip bounds (7,) each)."""
    x = np.clip(np.asarray(x, np.float64).reshape(-1, len(COLUMNS)), low, high)
    return np.exp(coeffs[0] + x @ np.asarray(coeffs[1:], np.float64)).astype(np.float32)


def board_design(image, corners: np.ndarray, ids: np.ndarray, scores: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """:func:`design` (N, 7) of a board in ``image``, converting no more of it than needed.

    image : a :class:`~aicalib_tf.detect.pyramid.Frame` (a grey uint8 frame is read as it is, any other
    through its float grey), or ``region(x0, y0, x1, y1) -> (y1 − y0, x1 − x0) float32`` grey of the
    image, asked for the part about the corners. corners : (N, 2) px. ids : (N, 2). scores : (N,).
    size : (width, height) px.
    """
    pts = np.asarray(corners, np.float64).reshape(-1, 2)
    if len(pts) == 0:
        return np.zeros((0, len(COLUMNS)))
    raw = getattr(image, "raw", None)
    if raw is not None and raw.dtype == np.uint8 and raw.ndim == 2:
        return design(raw, pts, ids, scores)
    region = image.region if raw is not None else image
    pad = _MAX_RADIUS + 2  # the largest window and the bilinear sample's next pixel
    x0, y0 = (max(int(np.floor(v)) - pad, 0) for v in pts.min(axis=0))
    x1 = min(int(np.ceil(pts[:, 0].max())) + pad + 1, size[0])
    y1 = min(int(np.ceil(pts[:, 1].max())) + pad + 1, size[1])
    return design(region(x0, y0, x1, y1), pts - np.array([x0, y0], np.float64), ids, scores)


def board_sigmas(image, corners: np.ndarray, ids: np.ndarray, scores: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Each corner's σ (N,) float32 px, one standard deviation per axis (:func:`board_design`'s arguments)."""
    if len(corners) == 0:
        return np.zeros(0, np.float32)
    return sigma_from_design(board_design(image, corners, ids, scores, size))


def with_sigmas(det, image):
    """``det`` (a :class:`~aicalib_tf.detect.pipeline.Detection`) with its corners' ``sigmas`` (:func:`board_sigmas`).

    image : as :func:`board_design` (a Frame, or a region function), over the image the corners are in. A detection without
    corners is returned as it is.
    """
    if not det.found:
        return det
    return replace(det, sigmas=board_sigmas(image, det.corners, det.ids, det.scores, det.image_size))
