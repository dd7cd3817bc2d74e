"""Field check: does an existing calibration still hold for new views of the board?

Every view's pose is fitted in three fits of the new views:

* **held**: the calibration's intrinsics θ₀ kept (its residual RMS is reported; outlier views are
  found here);
* **free**: every intrinsic refitted. Its residual variance σ̂² = RSS/(2N − 6V − p) (N corners in V
  views, p intrinsics) is the corner noise per axis of the *check footage*, with its degrees of
  freedom: light, blur and the detector of the new views are measured, not assumed;
* **drift**: fx, fy, cx, cy refitted with the distortion held at the calibration's
  (``hold_distortion=False``: taken from the free fit).

Two tests at level α each, both scaled by σ̂ (never by the calibration's footage noise):

* **Drift.** d = (fx, fy, cx, cy) − calibrated, T = dᵀC⁻¹d with C = κ·(σ̂²·P + M·Σ·Mᵀ): S the new views'
  JᵀJ over the intrinsics with their poses eliminated (the Schur complement), P = S₄⁻¹ (its fx..cy
  block) or [S⁻¹]₄ (every intrinsic free), Σ the calibration's covariance, M = [−I, B] with
  B = −S₄⁻¹·S_fd saying how the held distortion's own error moves the fit (B = 0 when it is refitted).
  T/4 against F(4, ν).
* **Lens** (structured residuals). The likelihood ratio of the held and the free fit: linearised,
  RSS_held − RSS_free = dᵀS·d for d = θ_free − θ₀, and (RSS_held − RSS_free)/(p·σ̂²) is the F test of
  the p freed intrinsics when θ₀ is exact (reported as ``lr_f``). With the calibration's own
  uncertainty the statistic is T = dᵀ(σ̂²S⁻¹ + Σ)⁻¹d/κ = dᵀS(σ̂²I + ΣS)⁻¹d/κ (no inverse of S:
  directions the views do not determine drop out); T/p against F(p, ν). A changed distortion
  leaves a radial pattern that the free fit removes; blur and noise raise σ̂ and both sums alike.

Both covariances assume a corner error of at least :data:`SYSTEMATIC_PX` per axis beyond the
measured noise (σ̂² + 0.04², the calibration's Σ scaled by 1 + 0.04²/σ_cal²): below that, a
detector's errors repeat between views instead of averaging out. On rendered video (σ̂ 0.01–0.03 px)
the calibration's intrinsics sat a median 1.8 and up to 19 times their formal variance (T/p) from the
truth, and unchanged cameras failed the lens test without it.

κ >= 1 (:func:`_view_inflation`) is what the scatter between the new views asks for beyond the
formal σ̂²·S⁻¹: about 1 for independent corner noise, a median of 5 on real photos, where the
formal covariance alone failed unchanged subsets of OpenCV's left photos in 68% of splits
(docs/benchmark.md, "Field check"). Errors shared within a view (motion blur along the view's
motion, lighting) make the views, not the corners, the independent units: the share (κ − 1)/κ of
C then rests on V − 1 degrees of freedom, and both tests use F with the Satterthwaite degrees of
freedom of the two shares (:func:`_test_dof`) instead of the corners' 2N − 6V − p.

Beside the verdict: the corner noise of both footages (the calibration's from its RMS,
:func:`corner_noise`) and what the drift test detects 95% of the time: a relative change of fx and
a principal-point shift in its worst direction (the noncentral F(4, ν) at C, ν the test's degrees
of freedom). When the check footage
is much noisier than the calibration's, a note says so with those figures.

The calibration must be one the check can use (:func:`check_fields`): focal lengths and principal
point of a camera of its image size, a symmetric positive semi-definite covariance, and an
uncertainty small enough to detect a change; otherwise a :class:`~aicalib_tf.calib.schema.FieldError`
names the field. Poses come from rays (:func:`~aicalib_tf.calib.bundle.poses_from_rays`), so every
lens model works, fisheye included. Views without a pose and outlier views
(:func:`~aicalib_tf.calib.fit.outlier_threshold` of the held RMS; a misread board sits tens of px
off) are skipped with the reason. Pure numpy/OpenCV.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from aicalib_tf.calib.bundle import CalibrationError, _Problem, bundle_adjust, poses_from_rays, schur_complement
from aicalib_tf.calib.fit import _sort_views, outlier_threshold
from aicalib_tf.calib.check_prior import PARAMS, calibration_covariance, check_fields, corner_noise
from aicalib_tf.calib.quality import lens_of
from aicalib_tf.calib.robust import view_sigmas, with_floor
from aicalib_tf.calib.weights import corner_weights
from aicalib_tf.calib.significance import f_noncentrality, f_quantile, f_sf
from aicalib_tf.geometry.pattern import board_points

__all__ = ["CheckResult", "check_calibration", "check_fields", "format_check", "corner_noise", "calibration_covariance",
           "ALPHA", "MIN_CHECK_VIEWS", "PARAMS", "POWER", "NOISIER", "SYSTEMATIC_PX"]

ALPHA = 0.01  # each test's false-alarm rate for an unchanged camera
POWER = 0.95  # the detection probability of the reported smallest detectable changes
NOISIER = 1.5  # check footage noisier than the calibration's by this factor (with the floor) gets a note
MIN_CHECK_VIEWS = 3
SYSTEMATIC_PX = 0.04  # corner error per axis that repeats between views (detector, rendering); both covariances assume it


@dataclass(frozen=True)
class CheckResult:
    """The field check of one calibration against new views.

    holds : neither test rejects at level ``alpha``. model : the lens model. views : names of the
    used views; per_view_rms (V,) px with the calibration's intrinsics. skipped : {name: why}.
    rms : residual RMS px over the used corners with the calibration's intrinsics; free_rms : with
    every intrinsic refitted. noise_px, noise_dof : the check footage's corner noise per axis (px,
    from the free fit) and its degrees of freedom; calibration_noise_px : the calibration's.
    calibrated, calibrated_std, measured, measured_std, drift, drift_std : (4,) float64 px for
    fx, fy, cx, cy (measured: fitted to the new views; drift = measured − calibrated, its σ with
    both uncertainties). drift_chi2, drift_limit, drift_p : the drift test (T, its limit, p).
    lens_chi2, lens_limit, lens_p, lens_dof : the lens test; lr_f : the held-vs-free F statistic
    as if the calibration were exact. detectable_fx, detectable_pp : the fx change (fraction of fx)
    and principal-point shift (px, worst direction) the drift test detects with probability
    :data:`POWER`. inflation : κ >= 1. test_dof : ν, the denominator degrees of freedom of both
    tests' F (:func:`_test_dof`). notes : caveats.
    """

    holds: bool
    model: str
    views: tuple
    per_view_rms: np.ndarray
    skipped: dict
    rms: float
    free_rms: float
    noise_px: float
    noise_dof: float
    calibration_noise_px: float
    calibrated: np.ndarray
    calibrated_std: np.ndarray
    measured: np.ndarray
    measured_std: np.ndarray
    drift: np.ndarray
    drift_std: np.ndarray
    drift_chi2: float
    drift_limit: float
    drift_p: float
    lens_chi2: float
    lens_limit: float
    lens_p: float
    lens_dof: int
    lr_f: float
    detectable_fx: float
    detectable_pp: float
    alpha: float
    hold_distortion: bool = True
    inflation: float = 1.0
    test_dof: float = math.inf
    notes: tuple = field(default=())

    @property
    def failures(self) -> list[str]:
        """Why the calibration does not hold, one line per failed test ([] when it holds)."""
        out = []
        if self.drift_p < self.alpha:
            z = self.drift / self.drift_std
            k = int(np.argmax(np.abs(z)))
            out.append(f"the intrinsics drifted (chi2 {self.drift_chi2:.1f} > {self.drift_limit:.1f}; largest: "
                       f"{PARAMS[k]} {self.drift[k]:+.2f} ± {self.drift_std[k]:.2f} px)")
        if self.lens_p < self.alpha:
            out.append(f"the lens no longer fits its calibration: refitting all {self.lens_dof} intrinsics lowers the "
                       f"residuals by chi2 {self.lens_chi2:.1f} > {self.lens_limit:.1f} at the new views' noise "
                       f"{self.noise_px:.3f} px, beyond the calibration's uncertainty")
        return out

    def to_dict(self) -> dict:
        """A JSON-able dict (finite floats only; a non-finite value becomes None)."""
        def num(x):
            return float(x) if np.isfinite(x) else None

        def per_param(a):
            return {p: num(v) for p, v in zip(PARAMS, a)}

        return {
            "holds": bool(self.holds), "model": self.model, "alpha": self.alpha,
            "hold_distortion": self.hold_distortion, "inflation": num(self.inflation), "failures": self.failures,
            "notes": list(self.notes),
            "views": [{"name": n, "rms": num(e)} for n, e in zip(self.views, self.per_view_rms)],
            "skipped": dict(self.skipped),
            "noise": {"check_px": num(self.noise_px), "check_dof": num(self.noise_dof),
                      "calibration_px": num(self.calibration_noise_px)},
            "residuals": {"rms": num(self.rms), "free_rms": num(self.free_rms)},
            "calibrated": per_param(self.calibrated), "calibrated_std": per_param(self.calibrated_std),
            "measured": per_param(self.measured), "measured_std": per_param(self.measured_std),
            "drift": per_param(self.drift), "drift_std": per_param(self.drift_std),
            "drift_test": {"chi2": num(self.drift_chi2), "limit": num(self.drift_limit), "p": num(self.drift_p),
                           "dof": len(PARAMS), "scale_dof": num(self.test_dof)},
            "lens_test": {"chi2": num(self.lens_chi2), "limit": num(self.lens_limit), "p": num(self.lens_p),
                          "dof": int(self.lens_dof), "scale_dof": num(self.test_dof), "lr_f": num(self.lr_f)},
            "detectable": {"power": POWER, "fx_fraction": num(self.detectable_fx),
                           "principal_point_px": num(self.detectable_pp)},
        }


# ----------------------------------------------------------------------------- the fits
def _poses(lens, obj, px, names, skipped):
    """Start poses per view from rays; views without one go to ``skipped``. Returns kept indices and poses."""
    keep, rv, tv = [], [], []
    for k, (o, p) in enumerate(zip(obj, px)):
        pose = poses_from_rays(lens, [o], [p])
        if pose is None:
            skipped[names[k]] = "no pose: the calibrated lens sees the board behind it"
            continue
        keep.append(k)
        rv.append(pose[0][0])
        tv.append(pose[1][0])
    return keep, np.array(rv).reshape(-1, 3), np.array(tv).reshape(-1, 3)


def _fixed_fit(lens, obj, px, names, skipped):
    """Poses of every view with the intrinsics fixed, outlier views skipped; returns (kept indices, BundleResult)."""
    keep, rv, tv = _poses(lens, obj, px, names, skipped)
    if len(keep) < MIN_CHECK_VIEWS:
        raise CalibrationError(f"{len(keep)} views with a pose; the check needs at least {MIN_CHECK_VIEWS}")
    fit = bundle_adjust(lens.model, [obj[k] for k in keep], [px[k] for k in keep], lens.intrinsics(), rv, tv,
                        free=np.zeros(4 + lens.dist.size, bool), covariance=False, strict=False)
    rms = np.where(np.isfinite(fit.per_view_rms), fit.per_view_rms, np.inf)
    thr = outlier_threshold(rms[np.isfinite(rms)]) if np.isfinite(rms).any() else 0.0
    order = [int(i) for i in np.argsort(-rms) if rms[i] > thr][: max(len(keep) // 3, 0)]
    order += [int(i) for i in np.flatnonzero(~np.isfinite(rms)) if int(i) not in order]
    for i in order:
        skipped[names[keep[i]]] = (f"outlier: RMS {rms[i]:.2f} px > {thr:.2f} px" if np.isfinite(rms[i])
                                   else "a corner cannot be projected by the calibrated lens")
    kept = [i for i in range(len(keep)) if i not in order]
    if len(kept) < MIN_CHECK_VIEWS:
        raise CalibrationError(f"{len(kept)} usable views after outliers; the check needs at least {MIN_CHECK_VIEWS}")
    if len(kept) < len(keep):
        fit = bundle_adjust(lens.model, [obj[keep[i]] for i in kept], [px[keep[i]] for i in kept], lens.intrinsics(),
                            fit.rvecs[kept], fit.tvecs[kept], free=np.zeros(4 + lens.dist.size, bool),
                            covariance=False, strict=False)
    return [keep[i] for i in kept], fit


def _schur(model, obj, px, intrinsics, rvecs, tvecs, sigmas=None) -> np.ndarray:
    """(4+n, 4+n) JᵀJ of the views over the intrinsics with their poses eliminated, at the given parameters
    (weighted by the views' σ, :func:`_fit_sigmas`)."""
    prob = _Problem(model, obj, px, intrinsics, np.ones(len(intrinsics), bool), _weights(sigmas, px))
    x = np.concatenate([intrinsics, np.hstack([rvecs, tvecs]).ravel()])
    U, W, Vb, _, _ = prob.normal_blocks(x)
    return schur_complement(U, W, Vb)[0]


def _weights(sigmas, px):
    """Per-corner weights σ_ref / σ over all views' corners (None: all 1)."""
    return corner_weights(sigmas, None, sum(len(p) for p in px)) if sigmas is not None else None


def _fit_sigmas(views, fit) -> list | None:
    """The views' corners' σ by the rule every calibration fit shares (:func:`aicalib_tf.calib.robust.view_sigmas`,
    :func:`~aicalib_tf.calib.robust.with_floor` from the held fit ``fit``); None when no view has any."""
    sigmas = view_sigmas(views)
    return None if sigmas is None else with_floor(sigmas, fit)


def _view_inflation(model, obj, px, new, free, sigmas=None) -> float:
    """κ >= 1: the views-as-clusters (sandwich) covariance of fx, fy, cx, cy over the formal one
    (mean of the eigenvalue ratios; 1 with fewer than 5 views or a singular fit).

    With each view's pose eliminated, view v adds S_v to JᵀJ and g_v to the gradient; the robust
    covariance is S⁻¹·(Σ g_v g_vᵀ)·S⁻¹·V/(V − 1), the linearised leave-one-view-out jackknife. Real
    corners carry errors shared within a view (blur, lighting, the lens model's misfit) that the
    formal σ²·S⁻¹ misses; with independent corner noise κ stays near 1."""
    V = len(obj)
    if V < 5:
        return 1.0
    x = np.concatenate([new.intrinsics[free], np.hstack([new.rvecs, new.tvecs]).ravel()])
    r, Ji, Jp, _ = _Problem(model, obj, px, new.intrinsics, free, _weights(sigmas, px))._evaluate(x)
    r = r.reshape(-1, 2)
    nf = int(np.sum(free))
    S, G = np.zeros((nf, nf)), np.zeros((nf, nf))
    start = 0
    try:
        for o in obj:
            sl = slice(start, start + len(o))
            start += len(o)
            ji, jp, rv = Ji[sl].reshape(-1, nf), Jp[sl].reshape(-1, 6), r[sl].ravel()
            WVinv = (ji.T @ jp) @ np.linalg.inv(jp.T @ jp)
            S += ji.T @ ji - WVinv @ (jp.T @ ji)
            g = ji.T @ rv - WVinv @ (jp.T @ rv)
            G += np.outer(g, g)
        Sinv = np.linalg.inv(S)
        robust = (Sinv @ G @ Sinv * V / (V - 1))[:4, :4]
        kappa = float(np.trace(np.linalg.solve(new.sigma2 * Sinv[:4, :4], robust))) / 4
    except np.linalg.LinAlgError:
        return 1.0
    return max(1.0, kappa) if np.isfinite(kappa) else 1.0


def _precision(S, A, sigma2, kappa) -> np.ndarray:
    """(σ²·S⁻¹ + A)⁻¹ / κ = S·(σ²·I + A·S)⁻¹ / κ, symmetrised: the inverse covariance of a difference
    whose two parts are the new views' (σ², JᵀJ-like S) and a known covariance A (no inverse of S)."""
    P = S @ np.linalg.inv(sigma2 * np.eye(len(S)) + A @ S) / kappa
    return 0.5 * (P + P.T)


def _test_dof(dof: float, kappa: float, views: int) -> float:
    """The degrees of freedom of C = κ·(formal): its share 1/κ rests on σ̂² (``dof``), the excess
    (κ − 1)/κ on the scatter between the ``views`` (V − 1); Satterthwaite's 1 / Σ share²/dof."""
    if not kappa > 1.0 or views < 2:
        return dof
    excess = (kappa - 1.0) / kappa
    return 1.0 / ((1.0 - excess) ** 2 / dof + excess ** 2 / (views - 1))


def _smallest_changes(precision, alpha, dof=math.inf) -> tuple[float, float]:
    """(fx change in px, principal-point shift in px in its worst direction) that the drift test
    (F(4, ``dof``) at ``alpha``, inverse covariance ``precision`` (4, 4)) detects with probability :data:`POWER`."""
    lam = f_noncentrality(len(PARAMS), dof, alpha, POWER)
    fx = math.sqrt(lam / precision[0, 0]) if precision[0, 0] > 0 else math.inf
    w = float(np.linalg.eigvalsh(precision[2:4, 2:4])[0])
    return fx, (math.sqrt(lam / w) if w > 0 else math.inf)


def _free_fit(lens, obj, px, fit, sigmas=None):
    """(every-intrinsic fit or None, σ̂² px², dof) of the new views: the check footage's noise."""
    n = 4 + lens.dist.size
    N, V = sum(len(p) for p in px), len(px)
    try:
        free = bundle_adjust(lens.model, obj, px, lens.intrinsics(), fit.rvecs, fit.tvecs, rank_strict=False,
                             sigmas=sigmas)
    except CalibrationError:
        return None, float(2 * fit.cost / max(2 * N - 6 * V, 1)), float(max(2 * N - 6 * V, 1))
    dof = max(2 * N - 6 * V - n, 1)
    return free, float(2 * free.cost / dof), float(dof)


def _drift(lens, obj, px, fit, free, S, cov, sigma2, hold_distortion, sigmas=None):
    """(measured (4,), the new views' covariance of it at σ̂² (4, 4), M·Σ·Mᵀ (4, 4), κ) (module docstring)."""
    n = 4 + lens.dist.size
    M = np.hstack([-np.eye(4), np.zeros((4, n - 4))])
    if hold_distortion or free is None:
        mask = np.arange(n) < 4
        new = bundle_adjust(lens.model, obj, px, lens.intrinsics(), fit.rvecs, fit.tvecs, free=mask, rank_strict=False,
                            sigmas=sigmas)
        cnew = new.covariance[:4, :4] * (sigma2 / max(new.sigma2, 1e-300))
        if n > 4:
            M[:, 4:] = -np.linalg.solve(S[:4, :4], S[:4, 4:])
    else:
        mask, new = np.ones(n, bool), free
        cnew = free.covariance[:4, :4] * (sigma2 / max(free.sigma2, 1e-300))
    return new.intrinsics[:4], cnew, M @ cov @ M.T, _view_inflation(lens.model, obj, px, new, mask, sigmas)


def _lens_test(lens, free, fit, S, cov, sigma2, kappa, measured2):
    """(T, dof, held-vs-free F at the measured noise as if the calibration were exact) of the lens test
    (module docstring)."""
    if free is None:
        return 0.0, 1, 0.0
    d = free.intrinsics - lens.intrinsics()
    T = float(d @ _precision(S, cov, sigma2, kappa) @ d)
    g = np.sqrt(np.maximum(np.diag(S), 1e-300))
    w = np.linalg.eigvalsh(S / np.outer(g, g))
    dof = int(np.sum(w > 1e-10 * w[-1]))
    return T, dof, float(2 * (fit.cost - free.cost) / (len(d) * max(measured2, 1e-12)))


def check_calibration(cal, views, *, alpha: float = ALPHA, hold_distortion: bool = True) -> CheckResult:
    """Test new views of the board against a calibration (module docstring).

    cal : a :class:`~aicalib_tf.calib.fit.Calibration` (any lens model; its covariance is used when
    it has one). views : sequence of :class:`~aicalib_tf.calib.fit.View` seen by the same camera,
    of ``cal.pattern_size`` boards (full or partial). alpha : each test's level in (0, 0.5).
    hold_distortion : fit fx, fy, cx, cy with the distortion held (default) or every intrinsic.
    Raises ValueError for bad arguments, :class:`~aicalib_tf.calib.schema.FieldError` for a
    calibration the check cannot use (:func:`check_fields`) and CalibrationError with fewer than
    :data:`MIN_CHECK_VIEWS` usable views.
    """
    if not 0.0 < float(alpha) < 0.5:
        raise ValueError(f"alpha must be in (0, 0.5), got {alpha!r}")
    cov = check_fields(cal)
    _, note = calibration_covariance(cal)
    lens = lens_of(cal)
    usable, skipped = _sort_views(views, tuple(cal.pattern_size))
    if len(usable) < MIN_CHECK_VIEWS:
        raise CalibrationError(f"{len(usable)} usable views; the check needs at least {MIN_CHECK_VIEWS}"
                               + "".join(f"; {k}: {v}" for k, v in list(skipped.items())[:5]))
    names = [v.name for v in usable]
    obj = [board_points(v.ids, cal.square_size) for v in usable]
    px = [v.corners for v in usable]
    kept, fit = _fixed_fit(lens, obj, px, names, skipped)
    obj, px = [obj[k] for k in kept], [px[k] for k in kept]
    sig = _fit_sigmas([usable[k] for k in kept], fit)  # each view's corners weighed as a calibration weighs them
    free, measured2, dof = _free_fit(lens, obj, px, fit, sig)
    cal_noise = corner_noise(cal)[0]
    sigma2 = measured2 + SYSTEMATIC_PX ** 2
    file_std = np.sqrt(np.diag(cov)[:4])
    cov = cov * (1.0 + (SYSTEMATIC_PX / cal_noise) ** 2)
    S = _schur(lens.model, obj, px, lens.intrinsics(), fit.rvecs, fit.tvecs, sig)
    measured, cnew, carried, kappa = _drift(lens, obj, px, fit, free, S, cov, sigma2, hold_distortion, sig)
    C = kappa * (cnew + carried)
    precision = np.linalg.pinv(C, hermitian=True)  # the inverse when C is regular (it is, with 3+ views)
    calibrated = lens.intrinsics()[:4]
    chi2 = float((drift := measured - calibrated) @ precision @ drift)
    T, lens_dof, lr_f = _lens_test(lens, free, fit, S, cov, sigma2, kappa, measured2)
    nu = _test_dof(dof, kappa, len(obj))  # the views, not the corners, are the units when κ > 1
    small_fx, small_pp = _smallest_changes(0.5 * (precision + precision.T), alpha, nu)
    noise = math.sqrt(measured2)
    notes = [note] if note else []
    if free is None:
        notes.append("every intrinsic could not be refitted to these views: the lens test was not run")
    if sigma2 > NOISIER ** 2 * (cal_noise ** 2 + SYSTEMATIC_PX ** 2):  # noisier beyond the floor both have
        notes.append(f"the check footage is {noise / cal_noise:.1f}x noisier than the calibration's (corner noise "
                     f"{noise:.3f} against {cal_noise:.3f} px per axis); it still detects fx changed by "
                     f"{100 * small_fx / calibrated[0]:.2f}% or the principal point moved {small_pp:.1f} px "
                     f"({100 * POWER:g}% of the time)")
    p_drift = f_sf(chi2 / 4, 4, nu)
    p_lens = f_sf(T / lens_dof, lens_dof, nu) if free is not None else 1.0
    return CheckResult(
        holds=bool(p_drift >= alpha and p_lens >= alpha), model=lens.model, views=tuple(names[k] for k in kept),
        per_view_rms=fit.per_view_rms, skipped=skipped, rms=fit.rms, free_rms=free.rms if free else fit.rms,
        noise_px=noise, noise_dof=dof, calibration_noise_px=cal_noise, calibrated=calibrated,
        calibrated_std=file_std, measured=measured, measured_std=np.sqrt(kappa * np.diag(cnew)),
        drift=drift, drift_std=np.sqrt(np.diag(C)), drift_chi2=chi2, drift_limit=4 * f_quantile(1 - alpha, 4, nu),
        drift_p=p_drift, lens_chi2=T, lens_limit=lens_dof * f_quantile(1 - alpha, lens_dof, nu), lens_p=p_lens,
        lens_dof=lens_dof, lr_f=lr_f, detectable_fx=small_fx / calibrated[0], detectable_pp=small_pp,
        alpha=float(alpha), hold_distortion=hold_distortion, inflation=kappa, test_dof=nu, notes=tuple(notes))


def format_check(result: CheckResult, *, source: str = "", total: int | None = None) -> str:
    """The printed report: the verdict, views used and skipped with reasons, both footages' corner
    noise, the residual RMS, the drift of fx, fy, cx, cy (±1σ of the difference), both tests, and
    the smallest changes the check detects."""
    used, skipped = len(result.views), len(result.skipped)
    given = total if total is not None else used + skipped
    head = "HOLDS" if result.holds else "DOES NOT HOLD"
    lines = [f"field check{f' of {source}' if source else ''} ({result.model}): the calibration {head}",
             f"  {given} views: {used} used, {given - used} skipped"]
    lines += [f"  skipped  {name}: {why}" for name, why in result.skipped.items()]
    ok = lambda p: "ok" if p >= result.alpha else "FAIL"  # noqa: E731
    q = 100 * (1 - result.alpha)
    lines.append(f"  corner noise per axis: these views {result.noise_px:.3f} px, the calibration's "
                 f"{result.calibration_noise_px:.3f} px")
    lines.append(f"  residual RMS {result.rms:.3f} px with the calibrated intrinsics, {result.free_rms:.3f} px with "
                 "every intrinsic refitted")
    what = "distortion held" if result.hold_distortion else "every intrinsic refitted"
    lines.append(f"  drift, new views − calibration ({what}; ±1σ of the difference):")
    for k, p in enumerate(PARAMS):
        rel = f" ({100 * result.drift[k] / result.calibrated[k]:+.2f}%)" if k < 2 else ""
        lines.append(f"    {p} {result.measured[k]:9.2f} − {result.calibrated[k]:9.2f} = {result.drift[k]:+7.2f} "
                     f"± {result.drift_std[k]:.2f} px{rel}")
    lines.append(f"  drift test: chi2 {result.drift_chi2:.1f} for 4 parameters (limit {result.drift_limit:.1f} at "
                 f"{q:g}%): {ok(result.drift_p)}")
    lines.append(f"  lens test: chi2 {result.lens_chi2:.1f} for {result.lens_dof} intrinsics refitted (limit "
                 f"{result.lens_limit:.1f} at {q:g}%): {ok(result.lens_p)}")
    lines.append(f"  detects ({100 * POWER:g}% of the time): fx changed by {100 * result.detectable_fx:.2f}%, the "
                 f"principal point moved {result.detectable_pp:.1f} px")
    if result.inflation > 1.05:
        lines.append(f"  (σ × {np.sqrt(result.inflation):.2f}: the new views scatter more than independent corner "
                     f"noise; the tests take it from {len(result.views)} views, F with {result.test_dof:.0f} "
                     "degrees of freedom)")
    lines += [f"  note: {n}" for n in result.notes]
    lines += [f"  why: {f}" for f in result.failures]
    return "\n".join(lines)
