"""Which of the candidate views to calibrate with: the subset whose information predicts the lowest
projection uncertainty (an A-optimal design over the views seen).

The loop keeps views one at a time, in the order the source shows them, and cannot take a view back.
By the end it has also seen many views it did not keep (near-duplicates, views that added little at
the time); together they are the candidates. Each candidate's information about the intrinsics,
its pose eliminated (:func:`aicalib_tf.calib.quality.view_information`), is known under the running
fit; the predicted mean squared uncertainty over the image of a subset S is
trace(A · (Σ_{v∈S} I_v)⁻¹), with A = Σ_m G_mᵀ G_m over the grid points m
(:func:`aicalib_tf.calib.quality.uncertainty_basis`). :func:`elimination_order` removes, one at a
time, the view whose loss raises that least (backward elimination: each subset is well determined
at every step, unlike a forward greedy that starts from one singular view), so the last ``k`` views
of the order are a good ``k``-view design for every ``k``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["design_weight", "predicted_mse", "elimination_order"]


def design_weight(G: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """(n, n) A = Σ_m G_mᵀ G_m over the usable grid points: trace(A·Σ) / M is the mean over the M
    points of the squared projection uncertainty (both axes summed) for a covariance Σ.

    G : (M, 2, n) d(pixel)/d(intrinsics) with the camera rotation compensated; ok : (M,) bool."""
    Gs = np.asarray(G, np.float64)[np.asarray(ok, bool)]
    Gs = Gs[np.all(np.isfinite(Gs), axis=(1, 2))]
    return np.einsum("mij,mik->jk", Gs, Gs)


def predicted_mse(information: np.ndarray, A: np.ndarray) -> float:
    """trace(A · information⁻¹) (px², summed over the points), or inf when ``information`` (n, n) is
    singular (condition number above 10¹² once each parameter is scaled to unit information): a
    subset that leaves an intrinsic undetermined is never preferred."""
    info = np.asarray(information, np.float64)
    s = 1.0 / np.sqrt(np.maximum(np.diag(info), 1e-300))
    S = np.outer(s, s)  # I -> S I S and A -> S A S keep trace(A I⁻¹); the parameters' units differ widely
    lam, V = np.linalg.eigh(info * S)
    if not np.all(np.isfinite(lam)) or lam[0] <= 1e-12 * lam[-1]:
        return float("inf")
    W = V.T @ (np.asarray(A, np.float64) * S) @ V
    return float(np.sum(np.diag(W) / lam))


def elimination_order(infos, A: np.ndarray, keep: int = 3) -> list[int]:
    """Indices into ``infos`` in the order backward elimination removes them, down to ``keep`` views
    left (those come last, in no particular order): the subset of the last k indices is the design
    of k views, for every k ≥ keep.

    infos : sequence of (n, n) information matrices, one per view (the same scale for all);
    A : (n, n) :func:`design_weight`. Ties (and views whose loss leaves the rest singular, which
    are removed last) resolve to the lowest index.
    """
    I = [np.asarray(m, np.float64) for m in infos]
    left = list(range(len(I)))
    total = np.sum(I, axis=0) if I else None
    order: list[int] = []
    while len(left) > max(int(keep), 0):
        costs = [predicted_mse(total - I[i], A) for i in left]
        j = int(np.argmin(costs))
        i = left.pop(j)
        order.append(i)
        total = total - I[i]
    return order + left
