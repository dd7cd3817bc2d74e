"""Does a solved board flex move the camera's projection by more than a flat fit's own noise?

The held-out check (:func:`~aicalib_tf.calib.flex_check.flex_earned`) asks whether the flex predicts
unseen views better. On real photos that is not enough: on OpenCV's 13 left-camera photos the flex
predicted the other half's views better in 83% of 64 halves (by 7 mpx, median) while the two halves'
calibrations, each with its flex, disagreed twice as much as flat ones (median 0.45 against 0.24 px
over 30 random half-splits; ``benchmarks/real_split_noise.py``): the flex's few millisquares traded
off with the intrinsics and added more scatter than bias removed. A flex is worth keeping when the
bias a flat board leaves is large against the flat fit's own noise.

Rule: Δ, the rotation-fitted projection difference between the flat and the flexed fit (median over
the cells the views' corners cover, :func:`aicalib_tf.calib.diff.projection_diff`), must exceed
:data:`FLEX_SHIFT_SIGMAS` times σ, what the flat fit's covariance predicts for a projection difference
of that fit from the truth (the mean over draws of that median, as
:func:`aicalib_tf.calib.quality.predicted_half_difference` computes it with one calibration's
covariance; computed here to first order, the rotation fitted out, not through the quality module,
which imports the fit). Over 30 random half-splits of each real set (each set's model fixed), the
halves differed (median) by 0.26 px on OpenCV's 13 left photos with this rule and the held-out check
(the held-out check alone 0.42, flat 0.24), 1.95 px on the bent udacity board (1.92; flat 4.19) and
0.61 px over 20 splits of the 185° fisheye (held-out check alone 0.66 over 30; flat 0.48 over the
20). Δ / σ over those halves: 1.7 (median) on the left photos, 5.9 on udacity, 4.2 on the fisheye.
``benchmarks/real_split_noise.py`` (24 splits, ``flex="auto"`` with this rule): 0.30, 1.8 and 0.64 px
(flat 0.27, 4.2 and 0.48).
"""

from __future__ import annotations

import cv2
import numpy as np

from aicalib_tf.calib.diff import grid_points, projection_diff, view_coverage
from aicalib_tf.geometry.lens import Lens

__all__ = ["FLEX_SHIFT_SIGMAS", "flex_shift", "shift_note"]

FLEX_SHIFT_SIGMAS = 4.0
_GRID = (32, 24)


def flex_shift(flat, flexed, views, image_size, grid=_GRID) -> tuple[float, float]:
    """(Δ px, σ px) of the module docstring for two BundleResults of one model (``intrinsics``; the
    flat one with its (4+n, 4+n) ``covariance``) fitted to ``views`` (each with ``corners`` (N, 2) px);
    image_size (w, h) px. NaN σ when the flat fit has no covariance."""
    la, lb = (Lens.from_intrinsics(f.model, f.intrinsics, image_size) for f in (flat, flexed))
    covered = view_coverage([v.corners for v in views], image_size, grid)
    delta = projection_diff(la, lb, grid=grid, covered=covered)["covered_stats"]["median"]
    cov = getattr(flat, "covariance", None)
    if cov is None or not np.all(np.isfinite(cov)):
        return float(delta), float("nan")
    return float(delta), _predicted_median(flat, image_size, covered, np.asarray(cov, np.float64), grid)


def _project(model, intrinsics, image_size, rays, rvec=None) -> np.ndarray:
    lens = Lens.from_intrinsics(model, intrinsics, image_size)
    if rvec is not None:
        rays = rays @ cv2.Rodrigues(np.asarray(rvec, np.float64))[0].T
    return lens.project(rays)


def _predicted_median(fit, image_size, covered, cov, grid, samples: int = 200) -> float:
    """px: the mean over draws δ ~ N(0, cov) of the median over the covered cells of |G·δ|, G the
    projection's Jacobian in the intrinsics (central differences at the cells' rays) less what a small
    rotation of the camera explains (least squares over the covered cells)."""
    intr = np.asarray(fit.intrinsics, np.float64)
    pts = grid_points(image_size, grid)
    rays = Lens.from_intrinsics(fit.model, intr, image_size).unproject(pts)
    ok = np.all(np.isfinite(rays), axis=1) & np.asarray(covered, bool)
    if ok.sum() < 3:
        return float("nan")
    rays = rays[ok]
    cols = []
    for i in range(intr.size):
        h = 1e-6 * max(1.0, abs(intr[i]))
        e = np.zeros_like(intr)
        e[i] = h
        cols.append((_project(fit.model, intr + e, image_size, rays) - _project(fit.model, intr - e, image_size, rays))
                    / (2 * h))
    J = np.stack(cols, axis=-1)  # (M, 2, n)
    A = np.stack([(_project(fit.model, intr, image_size, rays, 1e-6 * e) -
                   _project(fit.model, intr, image_size, rays, -1e-6 * e)) / 2e-6 for e in np.eye(3)], axis=-1)
    keep = np.all(np.isfinite(J), axis=(1, 2)) & np.all(np.isfinite(A), axis=(1, 2))
    J, A = J[keep], A[keep]
    W = np.linalg.lstsq(A.reshape(-1, 3), J.reshape(-1, J.shape[2]), rcond=None)[0]
    G = J - A @ W
    w, V = np.linalg.eigh(cov)
    delta = np.random.default_rng(0).standard_normal((samples, cov.shape[0])) @ (V * np.sqrt(np.maximum(w, 0.0))).T
    d = np.linalg.norm(np.einsum("mij,sj->smi", G, delta), axis=2)
    return float(np.mean(np.median(d, axis=1)))


def shift_note(flat, flexed, views, image_size) -> str:
    """Why the flex is not kept ("" when its shift is beyond :data:`FLEX_SHIFT_SIGMAS` σ, or σ is unknown)."""
    delta, sigma = flex_shift(flat, flexed, views, image_size)
    if not np.isfinite(sigma) or delta > FLEX_SHIFT_SIGMAS * sigma:
        return ""
    return (f"not used: it moves the projection by {delta:.3f} px, within {FLEX_SHIFT_SIGMAS:g}x the flat fit's "
            f"own {sigma:.3f} px (the board is taken as flat)")
