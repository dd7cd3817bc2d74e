"""Subpixel corner refinement on the original image (numpy/OpenCV, loops compiled by numba).

An ideal X-junction is point-symmetric: the intensity at c + d equals the intensity at c − d,
whatever the angles of its two lines. Any symmetric blur keeps that, so the centre is a
stationary point (a saddle) of the smoothed image. :func:`refine_saddle` finds it: it fits a
quadratic surface to a Gaussian-weighted window of the smoothed image around each estimate, moves
to the quadratic's saddle point and repeats until the step is below 1e-3 px, each point on its
own (:func:`aicalib_tf.detect.corners.saddle_kernels.saddle_refine`), so its result never depends on the others. :func:`refine_windowed` picks
each point's window to fit inside its squares, on an image smoothed once per window size
(:class:`Smoothed`). A hard shadow edge across the window pulls the saddle up to ~3 px towards it
(evaluate ``shading``: 15 wrong boards); where the window about the saddle is not point-symmetric
(:func:`aicalib_tf.detect.corners.shadow.asymmetry` above ``MAX_ASYMMETRY``), the fit that models a
shadow edge (:func:`aicalib_tf.detect.corners.shadow.refine_symmetric`) decides instead, started again
around the point where its result is not symmetric even with a shadow edge (``RESTART``).
A smooth light ramp (a lens's vignetting, towards a fisheye's rim) also moves the saddle, by up
to ~0.2 px in a direction set by the lines' angles, yet leaves the window nearly symmetric:
:func:`refine_ramp` fits the centre of symmetry allowing for a linear ramp, and :func:`polish` moves
a board's corners by it where a ramp is there (not applied by the detector, see there). The detector's
boards go through :func:`polish_board` (:func:`polish_in_region`): the ramp fit's places where its shifts
from the saddles form a smooth field over the board.
:func:`refine_subpix` wraps OpenCV's ``cornerSubPix`` behind the same signature, for comparison.

Coordinates are (x, y) px with the centre of pixel (0, 0) at (0.0, 0.0).
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from aicalib_tf.detect.corners.saddle import saddle_fit_matrix
from aicalib_tf.detect.corners.saddle_kernels import ramp_symmetric, saddle_refine

__all__ = ["Smoothed", "gaussian", "board_basis", "polish", "polish_board", "polish_in_region", "ramp_asymmetry", "ramp_inflation", "refine_ramp", "refine_saddle", "refine_subpix", "refine_windowed",
           "refine_candidates", "window_radius"]


def refine_saddle(
    gray: np.ndarray,
    points: np.ndarray,
    *,
    sigma: float = 1.0,
    radius: int = 3,
    iterations: int = 6,
    max_shift: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Move each point to the saddle of the smoothed image near it.

    gray : (H, W) float or uint8. points : (N, 2) (x, y) px, within about a pixel of a corner.
    sigma : px, Gaussian smoothing (more for noisy images). radius : px, half-size of the fit window.
    max_shift : px, the furthest a point may end from where it started (default: radius).
    Returns refined (N, 2) float32 and ok (N,) bool: False where the fit is not a saddle, did not
    settle, or left ``max_shift``; those points are returned unrefined.
    """
    pts0 = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(pts0) == 0:
        return np.zeros((0, 2), np.float32), np.zeros(0, bool)
    g = np.asarray(gray, dtype=np.float32)
    if sigma > 0:
        g = gaussian(g, sigma)
    _, fit = saddle_fit_matrix(radius)
    max_shift = float(radius if max_shift is None else max_shift)
    out, ok = saddle_refine(np.ascontiguousarray(g), pts0, fit, int(radius), int(iterations), max_shift)
    return out.astype(np.float32), ok


def gaussian(gray: np.ndarray, sigma: float) -> np.ndarray:
    """``gray`` blurred by a Gaussian of ``sigma`` px, its kernel cut at 3σ (OpenCV's default for
    float images is 4σ, a third more work for under 0.3% of the kernel's weight); borders reflected."""
    k = 2 * int(np.ceil(3.0 * sigma)) + 1
    return cv2.GaussianBlur(gray, (k, k), sigma)


class Smoothed:
    """The image smoothed for each refinement radius r (σ = 0.4·r) or σ, made once per image on demand.

    window_sigma : None, or one σ (px) for every radius: one smoothing serves all windows (the
    detector's quick passes, whose corners are refined again on the full image).
    """

    def __init__(self, gray: np.ndarray, window_sigma: float | None = None):
        self.gray, self.cache, self.window_sigma = gray, {}, window_sigma

    def __getitem__(self, r: int) -> np.ndarray:
        return self.sigma(0.4 * r if self.window_sigma is None else self.window_sigma)

    def sigma(self, sigma: float) -> np.ndarray:
        """The image smoothed with a Gaussian of ``sigma`` px."""
        key = round(float(sigma), 6)
        if key not in self.cache:
            self.cache[key] = gaussian(self.gray, key)
        return self.cache[key]


MAX_ASYMMETRY = 0.004  # above it (robust_refine.asymmetry at the saddle) the shadow-robust fit decides
SHADOWED = 0.02  # above it, and the shadow-robust fit failing, the point is not refined (ok False)
SHADOW_SIGMA = 0.7  # px, the smoothing of the image for the shadow-robust fit


def window_radius(spacing: np.ndarray) -> np.ndarray:
    """Refinement window half-size (px) that fits inside squares of ``spacing`` px: 2..5."""
    return np.minimum(np.maximum(np.round(0.45 * np.asarray(spacing, np.float64)), 2), 5).astype(int)  # np.clip's values


def refine_windowed(smoothed: Smoothed, pts: np.ndarray, spacing: np.ndarray, max_shift: np.ndarray | None = None,
                    *, restarts: bool = True, shadow_gate=None):
    """Saddle refinement with a window that fits inside the local squares.

    pts : (N, 2). spacing : (N,) px, the local corner spacing. max_shift : (N,) px or None.
    restarts : let the shadow-robust fit start again where its result is not symmetric (see
        :func:`_shadow_fit`; costly where many windows are asymmetric, e.g. beside objects).
    shadow_gate : None, or ``gate(idx (M,) int, saddles (M, 2)) -> (M,) bool``: which of the points
        ``idx`` whose window is not point-symmetric about their saddle ``saddles`` may still be a
        corner. The shadow-robust fit, the costly part, runs for those only; the others keep their
        saddle and stay ok (without a gate, a far-from-symmetric window whose shadow fit failed
        would not be ok), so the caller's own test must reject them. None: all.
    Returns refined (N, 2) float32 and ok (N,) bool.
    """
    from aicalib_tf.detect.corners.shadow import asymmetry  # it uses this module's saddle fit

    pts = np.asarray(pts, np.float64).reshape(-1, 2)
    radius = window_radius(spacing)
    out = pts.astype(np.float32)
    ok = np.zeros(len(pts), bool)
    for r in sorted(set(radius.tolist())):
        sel = np.flatnonzero(radius == r)
        img = smoothed[int(r)]
        out[sel], ok[sel] = refine_saddle(img, pts[sel], sigma=0.0, radius=int(r))
        held = np.flatnonzero(ok[sel])
        if not len(held):
            continue
        # a shadow edge across the window pulls the saddle fit: where the window is not point-symmetric
        # about it, the fit that allows a shadow edge decides (asked only about the saddles that hold)
        asym = np.zeros(len(sel))
        asym[held] = asymmetry(img, out[sel[held]], int(r))
        odd = ok[sel] & (asym > MAX_ASYMMETRY)
        if shadow_gate is not None and odd.any():
            odd[odd] = shadow_gate(sel[odd], out[sel[odd]])
        if odd.any():
            # restarts only where a shadow edge is likely (SHADOWED), not for the asymmetry of noise alone
            got, got_ok = _shadow_fit(smoothed, pts[sel[odd]], int(r), restarts & (asym[odd] > SHADOWED))
            out[sel[odd][got_ok]] = got[got_ok]
            # neither fit to be trusted where the window is far from symmetric and this fit failed
            ok[sel[odd][~got_ok & (asym[odd] > SHADOWED)]] = False
    if max_shift is not None:
        d = out - pts
        ok &= np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) <= max_shift  # np.linalg.norm's values
    return out, ok


SQUEEZED_WINDOW = 0.6  # a failed fit tries again in the window of squares this much narrower


def refine_candidates(smoothed: Smoothed, pts: np.ndarray, spacing: np.ndarray):
    """:func:`refine_windowed` for the network's corner candidates, with a second, narrower try.

    A corner squeezed towards a fisheye's rim has squares narrower across than the corner spacing
    says, and the window sized from the spacing straddles them: where that fit fails, the point is
    fitted again in the window of squares ``SQUEEZED_WINDOW`` times as wide, when that window is
    smaller. pts : (N, 2) px. spacing : (N,) px. Returns refined (N, 2) float32 and ok (N,) bool.
    """
    refined, ok = refine_windowed(smoothed, pts, spacing)
    again = np.flatnonzero(~ok & (window_radius(SQUEEZED_WINDOW * spacing) < window_radius(spacing)))
    if len(again):
        refined[again], ok[again] = refine_windowed(smoothed, np.asarray(pts)[again], SQUEEZED_WINDOW * spacing[again])
    return refined, ok


RESTART = 0.012  # above it (robust_refine.shadow_asymmetry at its result) the shadow-robust fit starts again nearby
RESTARTS = 4  # starts on a circle of 0.4 window radius around the point (8: the same boards on evaluate
# and data_gen hard seed 5, about 5% slower on tilt60, occluded, shading and partial)


def _shadow_fit(smoothed: Smoothed, pts: np.ndarray, r: int, restarts=True) -> tuple[np.ndarray, np.ndarray]:
    """The shadow-robust fit (:func:`aicalib_tf.detect.corners.shadow.refine_symmetric`) of a radius-``r`` window's points.

    On a lightly smoothed image (more smoothing mixes the shadow into the board), in a window one
    px wider. The fit can settle on the wrong side of a shadow edge, up to ~2 px off (evaluate
    ``shading`` #86): where the window about a result is not point-symmetric even allowing for a
    shadow edge (``RESTART``), it starts again from ``RESTARTS`` points around the first start; the
    restart that leaves the least of it, within r + 1 px of the start, replaces the first result
    only where it leaves at most ``RESTART`` and less than half the first's (under heavy noise no
    window is symmetric, and the least asymmetric of several noisy fits can be a neighbouring
    feature: data_gen ``hard`` seed 5, 6 wrong ids). restarts : bool, or (M,) bool per point: which
    points may start again.
    Returns (M, 2) float32 and ok (M,) bool.
    """
    from aicalib_tf.detect.corners.shadow import refine_symmetric, shadow_asymmetry

    img = smoothed.sigma(SHADOW_SIGMA)
    got, ok = refine_symmetric(img, pts, radius=r + 1)
    left = shadow_asymmetry(img, got, r + 1)
    again = np.flatnonzero(ok & (left > RESTART) & np.broadcast_to(restarts, ok.shape))
    if len(again):
        ang = 2 * np.pi * np.arange(RESTARTS) / RESTARTS
        ring = 0.4 * r * np.stack([np.cos(ang), np.sin(ang)], 1)
        starts = (pts[again, None, :] + ring[None]).reshape(-1, 2)
        more, more_ok = refine_symmetric(img, starts, radius=r + 1)
        more_ok &= np.linalg.norm(more - np.repeat(pts[again], RESTARTS, axis=0), axis=1) <= r + 1
        more_left = np.where(more_ok, shadow_asymmetry(img, more, r + 1), np.inf).reshape(-1, RESTARTS)
        best = np.argmin(more_left, axis=1)
        least = more_left[np.arange(len(again)), best]
        better = (least <= RESTART) & (least < 0.5 * left[again])
        got[again[better]] = more.reshape(-1, RESTARTS, 2)[better, best[better]]
    return got, ok


RAMP_SIGMA = 0.7  # px, the smoothing of the image for the ramp fit (more smoothing: more noise, benchmarks/refine_accuracy.py)
RAMP_ITERATIONS = 10
POLISH_SHIFT = 0.5  # px: the furthest :func:`polish` moves a corner
MIN_RAMP_Z = 4.0  # standard errors: a ramp under it may be the window's noise (real photos' sensor noise, print)
MIN_RAMP = 0.002  # 1/px: a weaker ramp moves the saddle by under ~0.007 px (about 7 px² · g), the ramp fit's own bias


def refine_ramp(smoothed: Smoothed, pts: np.ndarray, spacing: np.ndarray, max_shift: float = POLISH_SHIFT):
    """The centre of point symmetry of the image near each point, allowing a linear light ramp.

    A lens's vignetting multiplies the image by a light V that falls towards the rim: about a corner,
    V(c + o) ≈ V(c)·(1 + g·o), and the saddle fit's quadratic takes the ramp's linear term for a
    shift of the saddle: on data_gen's vignetted fisheyes (``fisheye_closeup`` with only its light
    fall-off) the saddle misses the truth by a median 0.08-0.11 px at 0.5-0.8 of the circle's radius,
    in a direction set by the squares' orientation (so a calibration cannot absorb it). The odd part
    of the image about the true centre is then 2·E(o)·(g·o) (E the even part), which this fit models
    (:func:`aicalib_tf.detect.corners.saddle_kernels.ramp_symmetric`): 0.02 px there. On a lightly
    smoothed image (σ ``RAMP_SIGMA``), in a window one px wider than the saddle fit's.
    pts : (N, 2) px, started within a fraction of a px. spacing : (N,) px, the local corner spacing.
    Returns (N, 2) float32 and ok (N,) bool: False where the fit did not settle (last step 0.05 px
    or more) or moved the point more than ``max_shift`` px; those points are returned unmoved.
    """
    pts = np.asarray(pts, np.float64).reshape(-1, 2)
    radius = window_radius(spacing) + 1
    img = np.ascontiguousarray(smoothed.sigma(RAMP_SIGMA), np.float32)
    out, ok = pts.copy(), np.zeros(len(pts), bool)
    h, w = img.shape
    for r in sorted(set(radius.tolist())):
        sel = np.flatnonzero(radius == r)
        got, last = ramp_symmetric(img, np.ascontiguousarray(pts[sel]), int(r), _ramp_weights(int(r)), RAMP_ITERATIONS)
        d = got - pts[sel]
        good = (last < 0.05) & (np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) <= max_shift)
        good &= (got[:, 0] >= -0.5) & (got[:, 0] <= w - 0.5) & (got[:, 1] >= -0.5) & (got[:, 1] <= h - 0.5)
        out[sel[good]], ok[sel] = got[good], good
    return out.astype(np.float32), ok


def polish(smoothed: Smoothed, pts: np.ndarray, spacing: np.ndarray) -> np.ndarray:
    """A board's corners moved by :func:`refine_ramp` where a light ramp explains the window's asymmetry.

    The ramp fit's result is kept where the window about it is point-symmetric once the ramp is
    allowed for (:func:`ramp_asymmetry` at most ``MAX_ASYMMETRY``, the bar of :func:`refine_windowed`'s
    saddle fit): a hard shadow edge is not a ramp, and such points keep the shadow-robust fit's place;
    so does a point whose ramp fit fails, or whose ramp is under ``MIN_RAMP`` or ``MIN_RAMP_Z`` standard
    errors (there the saddle fit, on a smoother image, is the more precise: refine_accuracy's noise-free
    corners 0.003 px against 0.009).

    Measured (``benchmarks/refine_accuracy.py``, ``benchmarks/fisheye_ramp.py``): on data_gen's vignetted
    fisheyes the detector's corners at 0.5-0.8 of the circle's radius 0.08-0.11 px from the truth, 0.02
    polished; refine_accuracy's shading 0.040 -> 0.034 px, its noise 0-40 held. Not applied by the
    detector: over 200 random half-splits of real photos (flat fits) the 185° fisheye's halves differed by
    0.567 px against the saddle's 0.589 without the z test (lower on 139 splits), 0.594 with it (lower on
    133), but a webcam's (opencv_left) by 0.204-0.221 against 0.192 (lower on 76), as with the symmetric
    fit without a ramp and the ramp fit on the saddle's smoothing: there the saddle's place is the better.
    pts : (N, 2) px. spacing : (N,) px. Returns (N, 2) float32.
    """
    pts = np.asarray(pts, np.float32).reshape(-1, 2)
    out = pts.copy()
    if not len(pts):
        return out
    got, ok = refine_ramp(smoothed, pts, spacing)
    radius = window_radius(spacing) + 1
    for r in sorted(set(radius[ok].tolist())):
        sel = np.flatnonzero(ok & (radius == r))
        left, ramp, z = ramp_asymmetry(smoothed.sigma(RAMP_SIGMA), got[sel], int(r))
        keep = (left <= MAX_ASYMMETRY) & (np.hypot(ramp[:, 0], ramp[:, 1]) >= MIN_RAMP) & (z >= MIN_RAMP_Z)
        out[sel[keep]] = got[sel[keep]]
    return out


BOARD_DEGREE = 2  # the degree in the corners' (col, row) ids of the smooth field fitted to a board's ramp-fit shifts
MIN_FIELD_F = 9.0  # the smooth field's mean square over its residuals' (per degree of freedom) for a board to be polished
# (real boards: a 185° fisheye's 3.1-32, 11 of 15 from 9; opencv_left's 1.4-8.4, polished they repeated no better)
MAX_INFLATION = 3.0  # the most a board's (median) ramp terms may inflate the centre's variance (blur σ 1-2 px: 2-5; 3-4: 13-23)


def polish_board(smoothed: Smoothed, pts: np.ndarray, ids: np.ndarray, spacing: np.ndarray) -> np.ndarray:
    """A board's corners moved to :func:`refine_ramp`'s places where its shifts form a smooth field over the board.

    A light ramp moves the saddle one way at a corner and the other way at its neighbours (the squares'
    colours swap; the ramp's own term does not), so the shifts it causes alternate over a board (data_gen's
    vignetted fisheyes: F ratios 0.3-2.3). On real photos the saddle and the finer fits (this ramp fit,
    ``cornerSubPix``) also disagree by a field the same at neighbouring corners, smooth over each board
    (a 185° fisheye: 0.04-0.12 px RMS a board, F 3-32), whose cause is not the light; there the finer places
    repeat better. The shifts (place less saddle) are fitted by a polynomial of degree ``BOARD_DEGREE`` in
    the ids (least squares), leaving out (and unmoved) corners whose ramp fit failed or whose window, a px
    wider than the saddle's, reaches past 0.45 of the spacing (steep tilts); the board takes the ramp fit's places
    where that field holds ``MIN_FIELD_F`` times the mean square per degree of freedom of what it leaves (an
    F ratio), and keeps its saddles otherwise, as does a board with fewer fitted corners than twice the
    field's terms, or one so blurred against the window that the ramp fit cannot tell a shift from a ramp
    (:func:`ramp_inflation` over ``MAX_INFLATION``; evaluate's blur σ 4 px board: 0.07 -> 0.18 px).
    Over 200 random half-splits of the fisheye's 15 photos (flat fits, ``benchmarks/real_split_noise.py``'s
    default column) 0.589 -> 0.575 px, lower on 137 (OpenCV's classic corners: 0.527); no board of
    opencv_left or udacity is polished. pts : (N, 2) px, saddle-refined. ids : (N, 2) int (col, row).
    spacing : (N,) px, the local corner spacing. Returns (N, 2) float32.
    """
    pts = np.asarray(pts, np.float32).reshape(-1, 2)
    ids = np.asarray(ids, np.float64).reshape(-1, 2)
    if not len(pts):
        return pts.copy()
    got, ok = refine_ramp(smoothed, pts, spacing)
    radius = window_radius(spacing) + 1
    ok &= radius <= 0.45 * np.asarray(spacing)  # its window inside the squares, as the saddle's (steep tilts: not)
    basis = board_basis(ids)
    n, k = int(ok.sum()), basis.shape[1]
    if n < 2 * k:
        return pts.copy()
    shift = (got - pts)[ok].astype(np.float64)
    coef, *_ = np.linalg.lstsq(basis[ok], shift, rcond=None)
    field = basis[ok] @ coef
    left = shift - field
    f_ratio = (np.sum(field * field) / (2 * k)) / max(np.sum(left * left) / (2 * (n - k)), 1e-30)
    if f_ratio < MIN_FIELD_F:
        return pts.copy()
    inflation = np.concatenate([ramp_inflation(smoothed.sigma(RAMP_SIGMA), got[ok & (radius == r)], int(r))
                                for r in sorted(set(radius[ok].tolist()))])
    return np.where(ok[:, None], got, pts).astype(np.float32) if np.median(inflation) <= MAX_INFLATION else pts.copy()


def ramp_inflation(img: np.ndarray, pts: np.ndarray, radius: int) -> np.ndarray:
    """(N,) how much the ramp fit's two ramp terms inflate the variance of its centre at ``pts``: the trace of
    the centre's block of the inverse normal matrix of :func:`aicalib_tf.detect.corners.saddle_kernels.ramp_symmetric`
    (centre and ramp) over that of the centre alone; 1 where the terms are independent, large where blur leaves
    the window's odd part a shift or a ramp alike. img : (H, W) float32, the ramp fit's image. pts : (N, 2) px.
    radius : px, the ramp fit's window."""
    from aicalib_tf.detect.corners.sampling import sample_windows

    r, side = int(radius), 2 * int(radius) + 3
    big = sample_windows(np.ascontiguousarray(img, np.float32), np.ascontiguousarray(pts, np.float64).reshape(-1, 2),
                         r + 1).reshape(-1, side, side)
    d = np.arange(-r, r + 1, dtype=np.float64)
    ox, oy = np.meshgrid(d, d)
    half = ((oy > 0) | ((oy == 0) & (ox > 0))).ravel()  # each pair (o, −o) once
    even = big[:, 1:-1, 1:-1] + big[:, -2:0:-1, -2:0:-1]
    gx, gy = 0.5 * (big[:, 1:-1, 2:] - big[:, 1:-1, :-2]), 0.5 * (big[:, 2:, 1:-1] - big[:, :-2, 1:-1])
    v = np.stack([gx - gx[:, ::-1, ::-1], gy - gy[:, ::-1, ::-1], -even * ox, -even * oy], axis=3)
    v = v.reshape(len(big), -1, 4)[:, half]
    a = np.einsum("m,nmi,nmj->nij", _ramp_weights(r)[half], v, v) + 1e-12 * np.eye(4)
    both = np.trace(np.linalg.inv(a)[:, :2, :2], axis1=1, axis2=2)
    return both / np.trace(np.linalg.inv(a[:, :2, :2]), axis1=1, axis2=2)


def board_basis(ids: np.ndarray) -> np.ndarray:
    """(N, K) the monomials up to ``BOARD_DEGREE`` of the ids (col, row) (N, 2), each centred and scaled to [-1, 1]."""
    lo, hi = ids.min(axis=0), ids.max(axis=0)
    u = (ids - 0.5 * (lo + hi)) / np.maximum(0.5 * (hi - lo), 1.0)
    return np.stack([u[:, 0] ** a * u[:, 1] ** b for a in range(BOARD_DEGREE + 1)
                     for b in range(BOARD_DEGREE + 1 - a)], axis=1)


def polish_in_region(region, size: tuple[int, int], pts: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """:func:`polish_board` of a detected board on the part of the image about it.

    region : ``region(x0, y0, x1, y1) -> (y1 − y0, x1 − x0) float32`` grey, pixels x0 … x1 − 1, y0 … y1 − 1
    (a :class:`~aicalib_tf.detect.pyramid.Frame`'s ``region``). size : (W, H) px. pts : (N, 2) px.
    ids : (N, 2) int (col, row). Returns (N, 2) float32.
    """
    from aicalib_tf.detect.corners.junction_kernels import nearest_distances

    pts = np.asarray(pts, np.float32).reshape(-1, 2)
    if len(pts) < 2:
        return pts.copy()
    spacing = nearest_distances(pts)  # junctions.nearest_spacing's, px
    margin = int(window_radius(spacing).max()) + 2 + int(np.ceil(3 * RAMP_SIGMA)) + 2
    x0, y0 = np.maximum(np.floor(pts.min(axis=0)).astype(int) - margin, 0)
    x1, y1 = np.minimum(np.ceil(pts.max(axis=0)).astype(int) + margin + 1, size)
    offset = np.array([x0, y0], np.float32)
    return polish_board(Smoothed(region(int(x0), int(y0), int(x1), int(y1))), pts - offset, ids, spacing) + offset


def ramp_asymmetry(img: np.ndarray, pts: np.ndarray, radius: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N,) the window's asymmetry about each point (as :func:`aicalib_tf.detect.corners.shadow.asymmetry`:
    odd energy over 4 × the even part's energy, Gaussian weights) left once the best linear light ramp
    is allowed for: the odd part D(o) less 2·E(o)·(g·o), g fitted per point by weighted least squares;
    that ramp g (N, 2) (1/px: the light's relative change per px) and its significance z (N,) (its length
    in standard errors, from the residual). img : (H, W) float32. pts : (N, 2) px. radius : px."""
    from aicalib_tf.detect.corners.sampling import sample_windows

    win = sample_windows(np.ascontiguousarray(img, np.float32), np.ascontiguousarray(pts, np.float64).reshape(-1, 2),
                         int(radius))
    w = _ramp_weights(int(radius))
    d = np.arange(-radius, radius + 1, dtype=np.float64)
    ox, oy = (a.ravel() for a in np.meshgrid(d, d))
    odd, even = win - win[:, ::-1], 0.5 * (win + win[:, ::-1])  # offset k's mirror −o is M − 1 − k
    xs = np.stack([2 * even * ox, 2 * even * oy], axis=2)  # (N, M, 2): the ramp's regressors
    a = np.einsum("m,nmi,nmj->nij", w, xs, xs) + 1e-12 * np.eye(2)
    g = np.linalg.solve(a, np.einsum("m,nmi,nm->ni", w, xs, odd)[..., None])[..., 0]
    left = np.einsum("m,nm->n", w, (odd - np.einsum("nmi,ni->nm", xs, g)) ** 2)
    mean = (even @ w) / w.sum()
    spread = np.einsum("m,nm->n", w, (even - mean[:, None]) ** 2)
    # the ramp's significance: g's Mahalanobis length under its covariance 2·A⁻¹·(left / (Σw / 2))
    # (each pair (o, −o) enters the sums twice)
    z2 = np.einsum("ni,nij,nj->n", g, a, g) * (w.sum() / 4.0) / np.maximum(left, 1e-30)
    return left / np.maximum(4 * spread, 1e-12), g, np.sqrt(z2)


@functools.lru_cache(maxsize=16)
def _ramp_weights(radius: int) -> np.ndarray:
    """((2r+1)²,) the ramp fit's Gaussian weights (σ = r/2 + 0.5, as the saddle fit), row-major (dy outer)."""
    d = np.arange(-radius, radius + 1, dtype=np.float64)
    dx, dy = np.meshgrid(d, d)
    sigma = radius / 2.0 + 0.5
    w = np.exp(-(dx * dx + dy * dy).ravel() / (2 * sigma * sigma))
    w.flags.writeable = False
    return w


def refine_subpix(gray: np.ndarray, points: np.ndarray, *, half_window: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's ``cornerSubPix`` (30 iterations or 1e-3 px) behind :func:`refine_saddle`'s signature.

    ok is False where the point moved more than ``half_window`` px (it slid off the corner).
    """
    pts0 = np.asarray(points, dtype=np.float32).reshape(-1, 2)
    if len(pts0) == 0:
        return pts0.copy(), np.zeros(0, bool)
    g = np.asarray(gray, dtype=np.float32)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3)
    out = cv2.cornerSubPix(g, pts0.reshape(-1, 1, 2).copy(), (half_window, half_window), (-1, -1), crit).reshape(-1, 2)
    ok = np.linalg.norm(out - pts0, axis=1) <= half_window
    return np.where(ok[:, None], out, pts0), ok
