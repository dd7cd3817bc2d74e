"""Starts for the bundle fit (:mod:`aicalib_tf.calib.bundle`) of any lens model.

* :func:`fisheye_start`: a fisheye lens without a guess: a grid of focal lengths, poses by PnP on
  rays, a few evaluations of the fit each; models that start from another one (``WARM_FROM``,
  e.g. DS and EUCM from equidistant) start from that model's start converted to them;
* :func:`convert_start`: a start for one model from a lens of another: coefficients kept within a
  family, a fisheye converted to another fisheye model by :func:`~aicalib_tf.geometry.lens_convert.fit_lens`
  (the projections of its rays matched), else the model's ``FIT_START``.
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.calib.bundle import CalibrationError, bundle_adjust, poses_from_rays
from aicalib_tf.geometry.lens import N_COEFFS, Lens, get_model
from aicalib_tf.geometry.lens_convert import fit_lens

__all__ = ["convert_start", "fisheye_start", "widest_angle", "FISHEYE_FOVS"]

FISHEYE_FOVS = (60.0, 90.0, 120.0, 150.0, 180.0, 200.0, 220.0, 260.0, 300.0)  # "diagonal fields of view" tried, degrees
# (past 220°: a circular fisheye whose circle lies inside the frame, the image corners beyond it)


def widest_angle(lens: Lens, px) -> float:
    """Radians: the widest off-axis angle of the rays ``lens`` gives the corners ``px`` (list of (N_v, 2)
    px, or one array); NaN when none has a ray."""
    rays = lens.unproject(np.concatenate([np.asarray(p, np.float64).reshape(-1, 2) for p in px]))
    ang = np.arctan2(np.hypot(rays[:, 0], rays[:, 1]), rays[:, 2])
    return float(np.nanmax(ang)) if np.isfinite(ang).any() else float("nan")


def convert_start(lens: Lens, model: str, max_angle: float | None = None) -> np.ndarray:
    """A start [fx, fy, cx, cy, *dist] for ``model`` from a lens of any model: K kept, the coefficients
    kept within a ``FAMILY`` (padded or cut), a fisheye fitted to another fisheye model over the rays
    up to ``max_angle`` radians (:func:`~aicalib_tf.geometry.lens_convert.fit_lens`; e.g. the widest
    ray the views reach), else the model's ``FIT_START``."""
    spec = get_model(model)
    d = np.array(spec.FIT_START, dtype=np.float64)
    if spec.FAMILY == lens.spec.FAMILY:
        d, m = np.zeros(N_COEFFS[model]), min(N_COEFFS[model], lens.dist.size)
        d[:m] = lens.dist[:m]
    elif spec.IS_FISHEYE and lens.spec.IS_FISHEYE:
        try:
            top = max_angle if max_angle is not None and np.isfinite(max_angle) else None
            return fit_lens(lens, model, top).intrinsics()
        except ValueError:
            pass
    return np.concatenate([[lens.fx, lens.fy, lens.cx, lens.cy], d])


def fisheye_start(obj, px, image_size, free, model: str = "equidistant"):
    """A start for a fisheye model without a guess: (intrinsics (4 + n,), (rvecs (V, 3), tvecs (V, 3))).

    obj, px : lists of (N_v, 3) board points and (N_v, 2) px. image_size : (width, height). free : (4 + n,)
    bool as :func:`bundle_adjust`. model : one with ``START == "rays"``. Coefficients at its ``FIT_START``,
    principal point at the centre, f such that the half diagonal sees half of each of :data:`FISHEYE_FOVS`,
    poses by PnP on rays (:func:`poses_from_rays`), 8 evaluations of the fit; the lowest cost wins.
    A model with a fisheye ``WARM_FROM`` starts from that model's start, converted (:func:`convert_start`)."""
    spec, best = get_model(model), None
    if spec.WARM_FROM is not None and get_model(spec.WARM_FROM).START == "rays":
        every = np.ones(4 + N_COEFFS[spec.WARM_FROM], bool)
        intr, poses = fisheye_start(obj, px, image_size, every, spec.WARM_FROM)
        warm = bundle_adjust(spec.WARM_FROM, obj, px, intr, *poses, covariance=False, strict=False)
        lens = Lens.from_intrinsics(spec.WARM_FROM, warm.intrinsics, image_size)
        return np.where(free, convert_start(lens, model, widest_angle(lens, px)), 0.0), (warm.rvecs, warm.tvecs)
    d0, (w, h) = np.array(spec.FIT_START, dtype=np.float64), (float(s) for s in image_size)
    for fov in FISHEYE_FOVS:
        f = 0.5 * np.hypot(w, h) / spec.radius(np.radians(fov / 2), d0)
        if not np.isfinite(f) or f <= 0:
            continue
        lens = Lens(model, [[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]], d0, image_size)
        poses = poses_from_rays(lens, obj, px)
        if poses is None:
            continue
        fit = bundle_adjust(model, obj, px, lens.intrinsics(), *poses, free=free, max_nfev=8,
                            covariance=False, strict=False)
        if np.isfinite(fit.cost) and (best is None or fit.cost < best.cost):
            best = fit
    if best is None:
        raise CalibrationError(f"{model}: no start focal length (diagonal field of view 60-220 deg) "
                               "gives a pose for every view")
    return best.intrinsics, (best.rvecs, best.tvecs)
