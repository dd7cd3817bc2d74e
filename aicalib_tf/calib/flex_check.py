"""Does a solved board flex stand above the noise of its own estimate?

The fit's covariance, behind the σ rule of :func:`~aicalib_tf.calib.flex.flex_problem`, takes every
corner's error as independent. Real corners' errors are not: the print, the light and the
detector's bias follow a view, so a view's corners err together. On OpenCV's 13 left-camera photos
halves of 6–7 views each found a flex within σ = 0.001 squares of its own, 8σ apart; over random
halves of the real sets the spread of the sag over the views is 2.5–5 times what that σ says.

What the views say about the sag is measured on the views themselves: each view is left out once
and the flex refitted (from the fit's intrinsics), and the V sags s₍ᵢ₎ give the jackknife standard
error σ_J = √((V − 1)/V · Σ (s₍ᵢ₎ − s̄)²), right whatever the errors' correlation within a view. A
refit that keeps no flex (its σ rule) counts with sag 0.

Rule: the sag s = w_x + w_y is kept when |s| > t · max(σ_s, σ_J): σ_s the fit's own σ, t Student's
97.5% quantile with V − 1 degrees of freedom; the sag differs from a flat board's 0 at 95% confidence.
Otherwise the views are refitted flat and the note says why. With fewer than :data:`MIN_JACKKNIFE_VIEWS`
views there is no jackknife: σ_s alone decides, with the normal quantile.

Measured (``benchmarks/board_flex.py``, 20 views, 10 sequences a sag): every flex of 0.005–0.02 squares
kept at noise 0.1 px and 29 of 30 at 0.2 px (the one left flat has |s| = 2.3σ_s), none of a flat
board's. Over 24 random half-splits of the real sets (``benchmarks/real_split_noise.py``) it keeps 7 of
48 halves' flexes on OpenCV's left photos, 7 of 48 on the 185° fisheye and 42 of 48 on the bent udacity
board; the halves differ (median) by 0.31, 0.48 and 2.2 px (flat boards 0.27, 0.48 and 4.2; on
udacity's halves of 9 views the sag is −0.03 to −0.10 squares, and a few halves' own views leave it
within 2.3 standard errors, so one half keeps the flex and the other does not).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from aicalib_tf.calib.bundle import CalibrationError
from aicalib_tf.calib.significance import t_quantile

__all__ = ["MIN_JACKKNIFE_VIEWS", "FLEX_CONFIDENCE", "leave_one_out_sags", "sag_evidence", "confirm_flex",
           "solve_fields"]

MIN_JACKKNIFE_VIEWS = 4  # every leave-one-out refit keeps at least 3 views
FLEX_CONFIDENCE = 0.95  # two-sided: the sag's distance from 0 in standard errors must pass this test


def leave_one_out_sags(views, refit) -> np.ndarray:
    """(V,) squares: the sag w_x + w_y of refit(views less view i, "auto") for each view i (0 where that
    refit keeps no flex). refit(views, mode) -> BundleResult with a unit square; CalibrationError propagates."""
    sags = []
    for i in range(len(views)):
        f = refit(views[:i] + views[i + 1:], "auto")
        sags.append(0.0 if f.flex is None else float(np.sum(f.flex)))
    return np.array(sags)


def _sag_sigma(fit) -> float:
    """squares: the fit's own σ of w_x + w_y (its (2, 2) flex covariance, unit square)."""
    c = np.asarray(fit.flex_covariance, np.float64)
    return float(np.sqrt(max(c[0, 0] + c[1, 1] + 2 * c[0, 1], 0.0)))


def sag_evidence(sag: float, sigma: float, loo=None) -> tuple[bool, str]:
    """(keep, why not) for a sag (squares) with its fit's σ and the leave-one-out sags ``loo`` ((V,) or
    None with fewer than :data:`MIN_JACKKNIFE_VIEWS` views): the rule of the module docstring.

    >>> sag_evidence(0.010, 0.001, 0.010 + 0.002 * np.arange(8))[0]  # σ_J 0.0121: |t| 0.8 < 2.36
    False
    >>> sag_evidence(0.010, 0.001, 0.010 + 0.0005 * np.arange(8))[0]  # σ_J 0.0030: |t| 3.3
    True
    """
    p = 0.5 + FLEX_CONFIDENCE / 2
    if loo is None or len(loo) < MIN_JACKKNIFE_VIEWS:
        se, t, how = sigma, t_quantile(p, float("inf")), "the fit's own σ"
    else:
        s = np.asarray(loo, np.float64)
        jack = float(np.sqrt((len(s) - 1) / len(s) * np.sum((s - s.mean()) ** 2)))
        se, t = max(sigma, jack), t_quantile(p, len(s) - 1)
        how = f"from leaving each of the {len(s)} views out" if jack > sigma else "the fit's own σ"
    if abs(sag) > t * se:
        return True, ""
    return False, (f"not used: the sag {sag:+.4f} squares is within the noise of its estimate (± {se:.4f}, "
                   f"{how}; |t| {abs(sag) / max(se, 1e-300):.1f} < {t:.2f} for {FLEX_CONFIDENCE:.0%}); "
                   "the board is taken as flat")


def confirm_flex(fit, views, refit):
    """``fit`` when it has no flex or its sag passes :func:`sag_evidence` (leave-one-out refits with
    ``refit``); else the views refitted flat, its ``flex_note`` saying why.
    refit(views, "auto" | "off") -> BundleResult (unit square)."""
    if getattr(fit, "flex", None) is None:
        return fit
    try:
        loo = leave_one_out_sags(views, refit) if len(views) >= MIN_JACKKNIFE_VIEWS else None
        keep, why = sag_evidence(float(np.sum(fit.flex)), _sag_sigma(fit), loo)
    except CalibrationError as exc:
        keep, why = False, f"not used: a fit leaving one view out failed ({exc}); the board is taken as flat"
    if keep:
        return fit
    return dataclasses.replace(refit(views, "off"), flex_note=why)


def solve_fields(fit, views) -> dict:
    """The Calibration fields of a solve's flex (fit with a unit square) and rejected corners:
    {"flex_note", "rejected_corners" ({view name: (K, 2) ids}), and "flex", "flex_covariance" when solved}."""
    flex, inliers = getattr(fit, "flex", None), getattr(fit, "inliers", None)
    out = {"flex_note": getattr(fit, "flex_note", ""), "rejected_corners": {}}
    if flex is not None:
        out.update(flex=np.asarray(flex, np.float64).copy(), flex_covariance=np.asarray(fit.flex_covariance, np.float64))
    if inliers is not None:
        for v, keep in zip(views, np.split(np.asarray(inliers, bool), np.cumsum([len(v.ids) for v in views])[:-1])):
            if not keep.all():
                out["rejected_corners"][v.name] = v.ids[~keep].copy()
    return out
