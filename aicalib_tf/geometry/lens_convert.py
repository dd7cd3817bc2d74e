"""One lens model's best approximation of another: the start of a fit, or a conversion for a file.

:func:`fit_lens` finds the intrinsics of ``model`` whose projections of rays up to ``max_angle``
off-axis (four azimuths, 48 angles each) are nearest, in px, to those of a given lens, the
principal point held. Levenberg–Marquardt on the analytic Jacobian
(:func:`~aicalib_tf.geometry.lens.projection_jacobian`) from the model's ``FIT_START`` and a few
nearby coefficient sets; a step that leaves the model's valid range is refused. Numpy only.
"""

from __future__ import annotations

import math

import numpy as np

from .lens import Lens, get_model, projection_jacobian

__all__ = ["fit_lens"]


def _rays(max_angle: float) -> np.ndarray:
    t = np.linspace(0.02, max_angle, 48)
    phi = np.radians([0.0, 45.0, 90.0, 135.0])
    t, phi = np.meshgrid(t, phi)
    return np.stack([np.sin(t) * np.cos(phi), np.sin(t) * np.sin(phi), np.cos(t)], axis=-1).reshape(-1, 3)


def _residual(x, model, lens, rays, target):
    """(r (2M,) px, J (2M, 2 + n)) of the intrinsics x = [fx, fy, *dist]; None when x is not a valid lens."""
    K = np.array([[x[0], 0.0, lens.cx], [0.0, x[1], lens.cy], [0.0, 0.0, 1.0]])
    try:
        uv, _, Ji = projection_jacobian(rays, model, K, x[2:])
    except ValueError:
        return None
    if not np.isfinite(uv).all():
        return None
    J = np.concatenate([Ji[:, :, :2], Ji[:, :, 4:]], axis=2).reshape(len(rays) * 2, -1)
    return (uv - target).ravel(), J


def _lm(x, model, lens, rays, target, iterations=60):
    out = _residual(x, model, lens, rays, target)
    if out is None:
        return None, math.inf
    r, J = out
    cost, lam = float(r @ r), 1e-3
    for _ in range(iterations):
        A, g = J.T @ J, J.T @ r
        step_taken = False
        while lam < 1e10:
            dx = -np.linalg.solve(A + lam * np.diag(np.maximum(np.diag(A), 1e-12)), g)
            new = _residual(x + dx, model, lens, rays, target)
            if new is not None and float(new[0] @ new[0]) < cost:
                x, (r, J), lam, step_taken = x + dx, new, lam / 3.0, True
                done = cost - float(r @ r) <= 1e-14 * cost
                cost = float(r @ r)
                break
            lam *= 10.0
        if not step_taken or done:
            break
    return x, cost


def fit_lens(lens: Lens, model: str, max_angle: float | None = None) -> Lens:
    """The ``model`` lens nearest to ``lens`` (px, over rays up to ``max_angle`` radians off-axis).

    max_angle : default the narrower of the two models' widest imaged angles, less 2°, and at most
    100°. Returns a :class:`Lens` of ``model`` with ``lens``'s principal point and image size.
    Raises ValueError when no valid start of ``model`` images those rays.
    """
    spec = get_model(model)
    top = min(lens.max_angle(), spec.MAX_ANGLE) - math.radians(2.0)
    a = min(top, math.radians(100.0)) if max_angle is None else float(max_angle)
    rays = _rays(a)
    target = lens.project(rays)
    keep = np.isfinite(target).all(axis=1)
    rays, target = rays[keep], target[keep]
    best, best_cost = None, math.inf
    d0 = np.array(spec.FIT_START, dtype=np.float64)
    for shift in (0.0, -0.15, 0.15):
        d = d0 + shift * (np.arange(d0.size) == 0)
        for f_scale in (1.0, 0.8, 1.25):
            x, cost = _lm(np.concatenate([[lens.fx * f_scale, lens.fy * f_scale], d]), model, lens, rays, target)
            if x is not None and cost < best_cost:
                best, best_cost = x, cost
    if best is None:
        raise ValueError(f"{model}: no start images the rays up to {math.degrees(a):.0f}° of the {lens.model} lens")
    K = [[best[0], 0.0, lens.cx], [0.0, best[1], lens.cy], [0.0, 0.0, 1.0]]
    return Lens(model, K, best[2:], lens.image_size)
