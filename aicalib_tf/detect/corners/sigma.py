"""Each detected corner's σ: how far off its position is likely to be, from what the image shows there.

A refined corner is the saddle of the smoothed image in a window about it (:mod:`aicalib_tf.detect.corners.refine`).
Its error grows with the noise in that window and with whatever breaks the X-junction's point
symmetry (a shadow edge, an object in front, JPEG blocks, salt-and-pepper pixels), with blur, and
with lines that bend across the window (a strong lens), and shrinks with the junction's contrast. It
is measured in each corner's window of the unsmoothed image (bilinear samples on the (2r + 1)² grid
about the corner, r the refinement's radius for the distance to the nearest other corner,
:func:`aicalib_tf.detect.corners.refine.window_radius`, at most 3 px; :func:`aicalib_tf.detect.corners.sigma_kernels.window_measures`):

* ``odd``: √(Σ w o²), o(d) = (I(c + d) − I(c − d)) / 2 the part of the window that is not
  point-symmetric about the corner (noise and asymmetry), w the saddle fit's Gaussian weights
  (summing to 1), grey levels in [0, 1]; ``odd_median``: the median of |o|, the same for noise but
  hardly moved by an edge or a few impulsive pixels (odd / odd_median: impulsiveness);
* ``even``: the weighted standard deviation of the symmetric part, the junction's contrast;
* ``residual``: the weighted RMS of what the saddle fit's quadratic leaves (small under blur);
* ``curvature``: √|det| of the quadratic's Hessian, grey per px² (over the contrast: how sharp the saddle is);
* ``bend``: |c(i−1) − 2c(i) + c(i+1)| along the board's rows and columns by id, px
  (:func:`aicalib_tf.detect.corners.sigma_kernels.lattice_bend`), over the corner spacing;
* ``smoothed odd``: ``odd`` of the window smoothed by [1 2 1]/4 along x and y, over ``odd``: the share of
  the asymmetry at the low frequencies the saddle fit sees (about 0.4 for white noise; near 1 for a
  smooth asymmetry such as an object's edge or JPEG blocks);
* the board's ``flat noise``: σ in the flat middles of its squares, from the second differences of
  the pixels there (:func:`aicalib_tf.detect.corners.sigma_kernels.flat_noise`, with the rounding
  noise of 8-bit grey levels as its floor). Against the window's noise it tells white sensor noise
  (window/flat about e^−0.95) from noise that lives at the edges only: JPEG's ringing and blocks
  (compression flattens the squares' middles), render aliasing (noise-free images);
* each corner's ``edge width`` σ_b, px, from how much of the board's black/white contrast (the squares'
  flat middles, :func:`aicalib_tf.detect.corners.sigma_kernels.square_contrast`) its window keeps: for a
  Gaussian-blurred X-junction in the Gaussian window the ``even`` measure is (C/2)·(2/π)·asin(s²/(s² + σ_b²))
  (:func:`aicalib_tf.detect.corners.sigma_kernels.edge_width`, the noise's share of ``even`` taken out; about
  0.9 px on a sharp render, growing as the blur's σ beyond it, and unlike the fit's residual not drowned by
  the noise under heavy blur); over the corner spacing it tells how far the blur reaches towards the
  neighbouring squares' edges;
* the board's JPEG ``blockiness``: the mean step across 8-px block borders over the mean step
  elsewhere in the board's box (:func:`aicalib_tf.detect.corners.sigma_kernels.blockiness`; 1 for
  an image never compressed);
* the network's ``score``.

The model has two parts (``COLUMNS``). The board's: medians over its corners of these features (the
noise is one per image, so the board's median ``odd_median`` is its estimate), their spread (90th
percentile over median) and a few hinges (the detector's own error floor on clean images, impulsive
noise, strongly bent lines), the blur's reach, each corner's own: (the board's median edge width / the nearer
neighbour's distance along each lattice axis)² beyond :data:`aicalib_tf.detect.corners.sigma_kernels.SPREAD_KNOT`, summed
over the two axes (a foreshortened board's far side, whose squares are short along one axis), the median edge width, the flat noise over the contrast, window over flat noise,
blockiness and the median smoothed/raw asymmetry (white noise's on a board of corners closer than
``SMOOTHED_MIN_SPACING``: there the smoothed window reaches the next squares). Each corner's: its excess over the board's
median of each feature, and a hinge on its own asymmetry (a window with more than noise in it, such
as an object's edge, pulls the saddle in proportion). log σ₀ = c₀ + Σ cₖ xₖ, x the columns of :func:`design` clipped to
[``LOW``, ``HIGH``], the range they took in fitting (0.1th to 99.9th percentiles). An edge that replaces the pattern
beside the corner (an object's, which no shadow edge explains) pulls the saddle beyond that range, in proportion to its
amplitude (:func:`foreign_amplitude`, px): σ² = σ₀² + (``FOREIGN`` · amplitude)². σ px is one standard deviation per
axis (isotropic). A detection's σ (:func:`with_sigmas`) is at least the Cramér–Rao-like bound of each corner's junction
contrast over the noise about it (:mod:`aicalib_tf.detect.corners.contrast`): the fit saw few corners as faint as a
fisheye's dark rim makes them, where the model can put a corner 2 px off at 0.33 px. Over the full boards of the
close-up families (seed 301, the shipped network and a fine-tuned one) this lifts σ at 9–13% of the corners and the
errors' mean negative log-likelihood per corner from −3.35 to −3.58 (equidistant lenses: cover-70-90, vig-cos4,
blur-linear, contrast-low) and −4.85 to −4.86 (DS/EUCM, all 14 families; −0.29 to −0.68 on corners of contrast under
3 noise σ); on real photos it lifts 45 of 4368 corners' σ (at most 0.05 px).

``COEFFS``, ``LOW``, ``HIGH`` and ``FOREIGN`` were fitted on rendered boards with exact truth (data_gen renders of
the benchmark's sweeps and named conditions with other seeds than the benchmark's): the corner's
part by the maximum likelihood of the errors with a free scale per image (so it only orders the
corners inside an image, and its spread matches theirs), then the board's part to make each image's
mean σ² agree with its mean squared error per axis, then ``FOREIGN`` by the likelihood of the errors. ``python benchmarks/corner_sigma.py --fit``
refits and prints them; ``python benchmarks/corner_sigma.py`` compares predicted and measured errors
per condition on scenes the fit never saw (the benchmark's own seeds and three more).
"""

from __future__ import annotations

import functools
from dataclasses import replace

import numpy as np

from aicalib_tf.detect.corners.sigma_kernels import ASYMMETRY_COLUMN, BOARD_COLUMNS as _BOARD_COLUMNS, board_columns
from aicalib_tf.detect.corners.refine import window_radius
from aicalib_tf.detect.corners.saddle import saddle_fit_matrix

__all__ = ["COLUMNS", "BOARD_COLUMNS", "FOREIGN_COLUMN", "COEFFS", "LOW", "HIGH", "FOREIGN", "design", "sigma_from_design",
           "foreign_amplitude", "board_design", "board_sigmas", "with_sigmas"]

COLUMNS = ("noise/contrast", "residual/contrast", "impulsive noise", "bend/spacing", "score", "(noise/contrast)²",
           "curvature/contrast", "spacing", "bend hinge²", "noise/contrast p90 excess", "bend p90 excess",
           "impulsive × noise hinge", "own impulsiveness", "noise floor hinge", "edge width", "flat noise/contrast",
           "window/flat noise", "JPEG blockiness", "smoothed/raw asymmetry", "blur reach hinge",  # the board's
           "Δ noise/contrast", "Δ own asymmetry", "Δ residual/contrast", "Δ own impulsiveness", "Δ bend/spacing",
           "Δ score", "Δ curvature/contrast", "Δ bend hinge²", "Δ smoothed/raw asymmetry",
           "Δ own asymmetry hinge",  # each corner's excess over the board's median
           "foreign edge amplitude")  # px, added to σ in quadrature (FOREIGN), not in log σ's sum
FOREIGN_COLUMN = ASYMMETRY_COLUMN
BOARD_COLUMNS = _BOARD_COLUMNS
# log σ₀ = COEFFS[0] + Σ COEFFS[1 + k] · clip(design[:, k], LOW[k], HIGH[k]) over the columns before FOREIGN_COLUMN,
# σ² = σ₀² + (FOREIGN · design[:, FOREIGN_COLUMN])²; refit: python benchmarks/corner_sigma.py --fit
COEFFS = np.array([1.038, 0.677, 0.194, 0.358, 0.057, 0.475, 0.032, -0.485, -0.215, 0.050, 0.031, 0.016, 0.552, -0.077,
                   -0.189, -0.371, 0.400, 0.278, 0.378, 1.883, 11.342, 0.879, 0.428, -0.041, 0.379, 0.030, -0.056,
                   -0.398, 0.142, 0.419, 1.073])
LOW = np.array([-5.009, -2.331, 0.201, -5.891, -0.625, 1.069, -1.899, 1.622, 0.000, 0.012, 0.033, 0.000, -0.215, 0.000,
                -0.506, -5.474, -2.043, -0.406, -1.282, 0.000, -0.424, -1.582, -0.578, -0.734, -3.436, -2.944, -0.546,
                -1.547, -0.861, 0.000])
HIGH = np.array([-1.034, -0.231, 1.360, -0.912, -0.008, 25.089, -1.018, 4.582, 4.358, 0.815, 0.837, 0.584, 0.086, 1.509,
                 1.712, -0.000, 3.460, 1.110, -0.301, 0.067, 0.595, 1.383, 0.492, 1.202, 1.032, 0.290, 0.679, 1.524,
                 0.679, 0.883])
FOREIGN = 0.973  # σ px per px of foreign edge amplitude (fitted)
FOREIGN_GATE = 4.0  # a window whose odd energy over its even energy is more than this many times the board's median
# holds more than noise: the part of it a straight shadow edge does not explain is a foreign edge's (an object's)
MIN_SCORE = 0.05  # a corner the network missed (score 0) counts as this weak
SMOOTHED_MIN_SPACING = 10.0  # px: on a board of closer corners the smoothed window (r + 1 = 4 px) reaches the
# neighbouring squares' edges, so its asymmetry is the lattice's, not JPEG's or an object's: the board's
# smoothed/raw asymmetry column is then taken as white noise's (WHITE_SMOOTHED)
WHITE_SMOOTHED = -0.95  # log(smoothed / raw antisymmetric part) of white noise in the window
_SMOOTHED_COLUMN = COLUMNS.index("smoothed/raw asymmetry")
_SPACING_COLUMN = COLUMNS.index("spacing")  # the median log corner spacing
_REACH_COLUMN = COLUMNS.index("blur reach hinge")  # the one board column that is each corner's own
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


def design(gray: np.ndarray, corners: np.ndarray, ids: np.ndarray, scores: np.ndarray,
           origin: tuple[int, int] = (0, 0), foreign: bool = True) -> np.ndarray:
    """The model's columns (N, 31) (``COLUMNS``) of one board's corners, unclipped (module docstring).

    gray : (H, W) float32 grey in [0, 1] or uint8, unsmoothed (every column is a ratio of grey levels
    or of px, or a log length in px, so either scale gives the same). corners : (N, 2) (x, y) px.
    ids : (N, 2) int (col, row), distinct. scores : (N,) network responses in [0, 1].
    Columns 0..``BOARD_COLUMNS`` − 1 are the board's (the same for all its corners but the blur's reach), the next
    each corner's excess over the board's median of its feature (a corner with no row or column through it takes the
    board's median bend: :func:`aicalib_tf.detect.corners.sigma_kernels.design_columns`), the last (``FOREIGN_COLUMN``)
    its foreign edge amplitude, px (:func:`foreign_amplitude`; 0 without measuring it when ``foreign`` is False).
    origin : (x, y) px of gray's pixel (0, 0) in the whole image (where its JPEG blocks start) when
    gray is a part of it.
    """
    from aicalib_tf.detect.corners.junctions import nearest_spacing

    pts = np.ascontiguousarray(np.asarray(corners, np.float64).reshape(-1, 2))
    if len(pts) == 0:
        return np.zeros((0, len(COLUMNS)))
    spacing = nearest_spacing(pts)
    radius = np.minimum(window_radius(spacing), _MAX_RADIUS)
    fits, weights = _operators()
    img = gray if gray.dtype == np.uint8 and gray.ndim == 2 else np.asarray(gray, np.float32)
    x = board_columns(np.ascontiguousarray(img), pts, np.asarray(ids, np.int64).reshape(-1, 2), spacing, radius,
                      np.asarray(scores, np.float64).reshape(-1), fits, weights, MIN_SCORE,
                      _TINY * (255.0 if img.dtype == np.uint8 else 1.0), 1.0 if img.dtype == np.uint8 else 1.0 / 255.0,
                      int(origin[0]), int(origin[1]))
    if x[0, _SPACING_COLUMN] < np.log(SMOOTHED_MIN_SPACING):
        x[:, _SMOOTHED_COLUMN] = WHITE_SMOOTHED
    x[:, FOREIGN_COLUMN] = foreign_amplitude(img, pts, radius, np.exp(x[:, FOREIGN_COLUMN])) if foreign else 0.0
    return x


def foreign_amplitude(img: np.ndarray, pts: np.ndarray, radius: np.ndarray, asymmetry: np.ndarray) -> np.ndarray:
    """(N,) px: how far a foreign edge in each corner's window (an object's, not a shadow's) may pull its saddle.

    img (H, W) uint8 or float32 grey; pts (N, 2) px; radius (N,) int window radii; asymmetry (N,) each window's odd
    energy over its even energy (``odd``² / ``even``², module docstring). Where it exceeds ``FOREIGN_GATE`` times the
    board's median, the part of it a straight shadow edge does not explain
    (:func:`aicalib_tf.detect.corners.shadow.shadow_asymmetry`: a shadowed X-junction leaves almost none, an edge that
    replaces the pattern much), less that many medians, is the foreign edge's energy; its square root is its amplitude
    over the contrast, times the window's scale r/2 + 1/2 px a length (a saddle shift in proportion). 0 elsewhere.
    """
    from aicalib_tf.detect.corners.shadow import shadow_asymmetry

    out = np.zeros(len(pts))
    if len(pts) == 0:
        return out
    floor = FOREIGN_GATE * _median(asymmetry)
    gated = np.flatnonzero(asymmetry > floor)
    for r in set(radius[gated].tolist()):
        idx = gated[radius[gated] == r]
        side = 2 * int(r) + 4  # the window and the bilinear sample's next pixel, from one px before it
        base = np.floor(pts[idx]).astype(np.int64) - int(r) - 1
        rows = np.clip(base[:, 1, None] + np.arange(side), 0, img.shape[0] - 1)  # the image's edge pixel beyond it,
        cols = np.clip(base[:, 0, None] + np.arange(side), 0, img.shape[1] - 1)  # as the kernels sample
        patches = img[rows[:, :, None], cols[:, None, :]].astype(np.float32)  # (M, side, side), side by side:
        strip = np.ascontiguousarray(patches.transpose(1, 0, 2).reshape(side, -1))
        local = pts[idx] - base
        local[:, 0] += np.arange(len(idx)) * side
        left = shadow_asymmetry(strip, local, int(r)) - floor
        out[idx] = (0.5 * r + 0.5) * np.sqrt(np.maximum(left, 0.0))
    return out


def _median(v: np.ndarray) -> float:
    """np.median of v (N,), N ≥ 1, at a fifth of its cost on a board's few values."""
    k = len(v) // 2
    part = np.partition(v, (k - 1, k) if len(v) % 2 == 0 else k)
    return float(0.5 * (part[k - 1] + part[k]) if len(v) % 2 == 0 else part[k])


def sigma_from_design(x: np.ndarray, coeffs: np.ndarray = COEFFS, low: np.ndarray = LOW, high: np.ndarray = HIGH,
                      foreign: float = FOREIGN) -> np.ndarray:
    """σ (N,) float32 px of design columns x (N, 31) under the model (``coeffs`` (31,), clip bounds (30,) each, σ px per
    px of foreign edge amplitude ``foreign``)."""
    x = np.asarray(x, np.float64).reshape(-1, len(COLUMNS))
    s0 = np.exp(coeffs[0] + np.clip(x[:, :FOREIGN_COLUMN], low, high) @ np.asarray(coeffs[1:], np.float64))
    return np.hypot(s0, foreign * x[:, FOREIGN_COLUMN]).astype(np.float32)


def board_design(image, corners: np.ndarray, ids: np.ndarray, scores: np.ndarray, size: tuple[int, int],
                 foreign: bool = True) -> np.ndarray:
    """:func:`design` (N, 31) of a board in ``image``, converting no more of it than needed.

    image : a :class:`~aicalib_tf.detect.pyramid.Frame` (a grey uint8 frame is read as it is, any other
    through its float grey), or ``region(x0, y0, x1, y1) -> (y1 − y0, x1 − x0) float32`` grey of the
    image, asked for the part about the corners. corners : (N, 2) px. ids : (N, 2). scores : (N,).
    size : (width, height) px. foreign : as :func:`design`.
    """
    pts = np.asarray(corners, np.float64).reshape(-1, 2)
    if len(pts) == 0:
        return np.zeros((0, len(COLUMNS)))
    raw = getattr(image, "raw", None)
    if raw is not None and raw.dtype == np.uint8 and raw.ndim == 2:
        return design(raw, pts, ids, scores, foreign=foreign)
    region = image.region if raw is not None else image
    pad = _MAX_RADIUS + 2  # the largest window and the bilinear sample's next pixel
    x0, y0 = (max(int(np.floor(v)) - pad, 0) for v in pts.min(axis=0))
    x1 = min(int(np.ceil(pts[:, 0].max())) + pad + 1, size[0])
    y1 = min(int(np.ceil(pts[:, 1].max())) + pad + 1, size[1])
    return design(region(x0, y0, x1, y1), pts - np.array([x0, y0], np.float64), ids, scores, (x0, y0), foreign)


def board_sigmas(image, corners: np.ndarray, ids: np.ndarray, scores: np.ndarray, size: tuple[int, int],
                 own: bool = False) -> np.ndarray:
    """Each corner's σ (N,) float32 px, one standard deviation per axis (:func:`board_design`'s arguments).

    own : False (the detector's gates, which ask whether a corner's contrast is near the noise): without what lies beside
    each corner, its foreign edge and its own blur reach (the board's median reach for all); True: each corner's whole
    σ (:func:`with_sigmas`), and at least the Cramér–Rao-like bound of its junction's contrast over the noise about it
    (:func:`aicalib_tf.detect.corners.contrast.board_contrast`: a faint corner at a fisheye's dark rim, whose error the
    model, fitted where such corners are rare, can put at a sixth of what it is).
    """
    if len(corners) == 0:
        return np.zeros(0, np.float32)
    x = board_design(image, corners, ids, scores, size, foreign=own)
    if not own:
        x[:, _REACH_COLUMN] = _median(x[:, _REACH_COLUMN])
        return sigma_from_design(x)
    from aicalib_tf.detect.corners.contrast import board_contrast

    # at least the localisation bound of the corner's contrast over its noise (unmeasured: NaN, left to the model)
    return np.fmax(sigma_from_design(x), board_contrast(image, corners, ids, size)["bound"].astype(np.float32))


def with_sigmas(det, image):
    """``det`` (a :class:`~aicalib_tf.detect.detection.Detection`) with its corners' ``sigmas`` (:func:`board_sigmas`).

    image : as :func:`board_design` (a Frame, or a region function), over the image the corners are in. A detection without
    corners is returned as it is.
    """
    if not det.found:
        return det
    return replace(det, sigmas=board_sigmas(image, det.corners, det.ids, det.scores, det.image_size, own=True))
