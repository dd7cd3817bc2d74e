"""Per-corner weights of a calibration fit: σ_ref / σ from each corner's σ, 0 for rejected corners.

σ_ref is the median σ, so the weighted residuals stay in px-like units and a fit whose corners all
share one σ weighs them all 1 (the unweighted fit's numbers).
"""

from __future__ import annotations

import numpy as np

__all__ = ["corner_weights"]


def corner_weights(sigmas, inliers, n: int) -> np.ndarray | None:
    """(n,) float64 weights σ_ref / σ (σ_ref the median σ; 1 without sigmas), 0 for corners not in ``inliers``;
    None when neither is given (every weight 1). sigmas : list of (N_v,) px or one (n,) array."""
    if sigmas is None and inliers is None:
        return None
    w = np.ones(n)
    if sigmas is not None:
        sig = np.concatenate([np.asarray(s, np.float64).ravel() for s in sigmas]) if isinstance(sigmas, (list, tuple)) \
            else np.asarray(sigmas, np.float64).ravel()
        if sig.size != n or not np.all(np.isfinite(sig)) or np.any(sig <= 0):
            raise ValueError(f"sigmas must hold {n} finite values > 0 px, one per corner")
        w = np.median(sig) / sig
    if inliers is not None:
        keep = np.asarray(inliers, bool).ravel()
        if keep.size != n:
            raise ValueError(f"inliers must hold {n} values, one per corner, got {keep.size}")
        w = np.where(keep, w, 0.0)
    return w
