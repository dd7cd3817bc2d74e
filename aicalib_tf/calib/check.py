"""Field check: does an existing calibration still hold for new views of the board?

The intrinsics stay as calibrated and only the new views' poses are fitted; two tests then ask
whether the new corners agree with the calibration within its own uncertainty, each at level α:

* **Drift.** fx, fy, cx, cy are fitted to the new views with the distortion held at the
  calibration's (or, ``hold_distortion=False``, every intrinsic fitted). The difference d from the
  calibration has covariance C = κ·(Σ_new + M·Σ·Mᵀ): Σ the calibration's covariance, M = [−I, B]
  with B = −S_ff⁻¹·S_fd saying how the held distortion's own error moves the new fit (S: the new
  views' JᵀJ over the intrinsics with their poses eliminated, the Schur complement). dᵀC⁻¹d is
  compared with χ²(4)'s (1 − α) quantile.
* **Residuals.** With the calibration's intrinsics fixed, the mean squared residual per corner is
  about 2σ²·(2N − 6V)/(2N) + tr(S·κΣ)/N under "nothing changed": σ the corner noise per axis that
  the calibration's RMS implies (:func:`corner_noise`), N corners in V views. Its spread is the
  scatter of the calibration's per-view RMS (views differ more than pure noise says: blur,
  lighting), over the new views and the calibration's own; a one-sided t test.

κ >= 1 (:func:`_view_inflation`) is what the scatter between the new views asks for beyond the
formal σ²·(JᵀJ)⁻¹: 1 for independent corner noise (the synthetic trials of
``benchmarks/field_check.py``), a median of 5 on real photos, where the formal covariance alone failed
unchanged subsets of OpenCV's left photos in 68% of splits (docs/benchmark.md, "Field check").

The calibration holds when neither test rejects (α = 0.01 each: an unchanged camera fails at most
about 2% of checks). Poses come from rays (:func:`~aicalib_tf.calib.bundle.poses_from_rays`), so
every lens model works, fisheye included. Views without a pose and outlier views
(:func:`~aicalib_tf.calib.fit.outlier_threshold` of the fixed-intrinsics RMS; a misread board sits
tens of px off) are skipped with the reason. Pure numpy/OpenCV.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from aicalib_tf.calib.bundle import CalibrationError, _Problem, bundle_adjust, poses_from_rays, schur_complement
from aicalib_tf.calib.fit import _sort_views, outlier_threshold
from aicalib_tf.calib.quality import lens_of
from aicalib_tf.calib.significance import chi2_quantile, chi2_sf, t_quantile, t_sf
from aicalib_tf.geometry.pattern import board_points

__all__ = ["CheckResult", "check_calibration", "format_check", "corner_noise", "calibration_covariance", "ALPHA",
           "MIN_CHECK_VIEWS", "PARAMS"]

ALPHA = 0.01  # each test's false-alarm rate for an unchanged camera
MIN_CHECK_VIEWS = 3
MIN_NOISE_PX = 0.01  # floor of the corner noise per axis (a noise-free calibration would make any change significant)
PARAMS = ("fx", "fy", "cx", "cy")


@dataclass(frozen=True)
class CheckResult:
    """The field check of one calibration against new views.

    holds : neither test rejects at level ``alpha``. model : the lens model. views : names of the
    used views; per_view_rms (V,) px with the calibration's intrinsics. skipped : {name: why}.
    rms, expected_rms, limit_rms : residual RMS over the used corners, px, what the calibration
    predicts, and the (1 − alpha) limit; residual_p : its p-value. noise_px : corner noise per axis.
    calibrated, calibrated_std, measured, measured_std, drift, drift_std : (4,) float64 px for
    fx, fy, cx, cy (measured: fitted to the new views; drift = measured − calibrated, its σ with
    both uncertainties). drift_chi2, drift_limit, drift_p : the drift test. inflation : κ >= 1, the
    factor on both covariances that the scatter between the new views asks for. notes : caveats.
    """

    holds: bool
    model: str
    views: tuple
    per_view_rms: np.ndarray
    skipped: dict
    rms: float
    expected_rms: float
    limit_rms: float
    residual_p: float
    noise_px: float
    calibrated: np.ndarray
    calibrated_std: np.ndarray
    measured: np.ndarray
    measured_std: np.ndarray
    drift: np.ndarray
    drift_std: np.ndarray
    drift_chi2: float
    drift_limit: float
    drift_p: float
    alpha: float
    hold_distortion: bool = True
    inflation: float = 1.0
    notes: tuple = field(default=())

    @property
    def failures(self) -> list[str]:
        """Why the calibration does not hold, one line per failed test ([] when it holds)."""
        out = []
        if self.residual_p < self.alpha:
            out.append(f"residual RMS {self.rms:.3f} px is above the limit {self.limit_rms:.3f} px "
                       f"(expected {self.expected_rms:.3f} px)")
        if self.drift_p < self.alpha:
            z = self.drift / self.drift_std
            k = int(np.argmax(np.abs(z)))
            out.append(f"the intrinsics drifted (chi2 {self.drift_chi2:.1f} > {self.drift_limit:.1f}; largest: "
                       f"{PARAMS[k]} {self.drift[k]:+.2f} ± {self.drift_std[k]:.2f} px)")
        return out

    def to_dict(self) -> dict:
        """A JSON-able dict (finite floats only; a non-finite value becomes None)."""
        def num(x):
            return float(x) if np.isfinite(x) else None

        def per_param(a):
            return {p: num(v) for p, v in zip(PARAMS, a)}

        return {
            "holds": bool(self.holds), "model": self.model, "alpha": self.alpha,
            "hold_distortion": self.hold_distortion, "inflation": num(self.inflation), "failures": self.failures, "notes": list(self.notes),
            "views": [{"name": n, "rms": num(e)} for n, e in zip(self.views, self.per_view_rms)],
            "skipped": dict(self.skipped),
            "residuals": {"rms": num(self.rms), "expected_rms": num(self.expected_rms),
                          "limit_rms": num(self.limit_rms), "p": num(self.residual_p), "noise_px": num(self.noise_px)},
            "calibrated": per_param(self.calibrated), "calibrated_std": per_param(self.calibrated_std),
            "measured": per_param(self.measured), "measured_std": per_param(self.measured_std),
            "drift": per_param(self.drift), "drift_std": per_param(self.drift_std),
            "drift_test": {"chi2": num(self.drift_chi2), "limit": num(self.drift_limit), "p": num(self.drift_p),
                           "dof": len(PARAMS)},
        }


# ----------------------------------------------------------------------------- statistics
def corner_noise(cal) -> tuple[float, float]:
    """(σ px per axis, degrees of freedom) of the corner noise the calibration's RMS implies.

    σ² = rms²·N / (2N − 6V − n): N corners of V views (``cal.corner_counts``, or full boards of
    ``cal.pattern_size`` when a file does not say, as an OpenCV camera.yaml), n free intrinsics.
    Floored at :data:`MIN_NOISE_PX`.
    """
    V = len(cal.views)
    counts = np.asarray(cal.corner_counts, np.float64)
    N = float(counts.sum()) if counts.size and counts.sum() > 0 else float(V * cal.pattern_size[0] * cal.pattern_size[1])
    n = 4 + np.asarray(cal.dist).size
    dof = 2 * N - 6 * V - n
    if not (dof > 0 and N > 0 and np.isfinite(cal.rms)):
        return max(float(cal.rms) / math.sqrt(2), MIN_NOISE_PX), math.inf
    return max(float(cal.rms) * math.sqrt(N / dof), MIN_NOISE_PX), dof


def calibration_covariance(cal) -> tuple[np.ndarray, str]:
    """((4+n, 4+n) covariance of [fx, fy, cx, cy, *dist], note): ``cal.covariance``, else the diagonal
    of ``cal.std``, else zeros; the note says when the file did not carry the full covariance."""
    lens = lens_of(cal)
    n = 4 + lens.dist.size
    cov = getattr(cal, "covariance", None)
    if cov is not None and np.asarray(cov).shape == (n, n) and np.all(np.isfinite(cov)):
        return np.asarray(cov, np.float64), ""
    names = ("fx", "fy", "cx", "cy") + tuple(f"d{k}" for k in range(n - 4))
    std = getattr(cal, "std", {}) or {}
    if all(k in std for k in PARAMS):
        from aicalib_tf.geometry.lens import COEFF_NAMES

        names = PARAMS + COEFF_NAMES[lens.model]
        return np.diag([float(std.get(k, 0.0)) ** 2 for k in names]), (
            "the calibration file carries σ but no covariance: correlations ignored")
    return np.zeros((n, n)), ("the calibration file carries no uncertainty (e.g. an OpenCV camera.yaml): its "
                              "intrinsics are taken as exact, which flags changes more readily; check against camera.json")


# ----------------------------------------------------------------------------- the check
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


def _schur(model, obj, px, intrinsics, rvecs, tvecs) -> np.ndarray:
    """(4+n, 4+n) JᵀJ of the views over the intrinsics with their poses eliminated, at the given parameters."""
    prob = _Problem(model, obj, px, intrinsics, np.ones(len(intrinsics), bool))
    x = np.concatenate([intrinsics, np.hstack([rvecs, tvecs]).ravel()])
    U, W, Vb, _, _ = prob.normal_blocks(x)
    return schur_complement(U, W, Vb)[0]


def _view_scatter(cal) -> tuple[float, float]:
    """(relative variance of one view's mean squared residual, its degrees of freedom) from the
    calibration's per-view RMS; never below what pure corner noise gives (2 / (2·54 − 6) for a 9x6 board)."""
    per_view = np.asarray(cal.per_view_rms, np.float64) ** 2
    per_view = per_view[np.isfinite(per_view) & (per_view > 0)]
    floor = 2.0 / max(2 * cal.pattern_size[0] * cal.pattern_size[1] - 6, 1)
    if per_view.size < 3:
        return floor, math.inf
    return max(float(np.var(per_view, ddof=1) / np.mean(per_view) ** 2), floor), per_view.size - 1.0


def _residual_test(fit, S, cov, sigma, scatter, alpha):
    """(rms, expected rms, limit rms, p) of the fixed-intrinsics residuals (module docstring).

    The mean squared residual per corner M is compared with its expectation E; its variance is the
    views' scatter (``scatter``: (relative variance of one view's mean square, dof), :func:`_view_scatter`)
    over the new views and over the calibration's, plus what the intrinsics' uncertainty adds; a
    one-sided t test with the calibration's views' dof."""
    counts = np.array([len(r) for r in fit.residuals], np.float64)
    N, V = counts.sum(), len(counts)
    ss = float(sum(np.sum(r * r) for r in fit.residuals))
    SC = S @ cov
    noise = 2 * sigma * sigma * (2 * N - 6 * V) / (2 * N)  # per corner, after the poses took their share
    mean = noise + float(np.trace(SC)) / N
    rel, nu = scatter
    var = (noise ** 2 * rel * (float(np.sum(counts ** 2)) / N ** 2 + 1.0 / max(nu + 1, 1))
           + (2 * float(np.trace(SC @ SC)) + 4 * sigma * sigma * float(np.trace(SC))) / N ** 2)
    sd = math.sqrt(var)
    z = (ss / N - mean) / sd
    limit = mean + t_quantile(1 - alpha, nu) * sd
    return math.sqrt(ss / N), math.sqrt(mean), math.sqrt(limit), t_sf(z, nu)


def _view_inflation(model, obj, px, new, free) -> float:
    """κ >= 1: the views-as-clusters (sandwich) covariance of fx, fy, cx, cy over the formal one
    (mean of the eigenvalue ratios; 1 with fewer than 5 views).

    With each view's pose eliminated, view v adds S_v to JᵀJ and g_v to the gradient; the robust
    covariance is S⁻¹·(Σ g_v g_vᵀ)·S⁻¹·V/(V − 1), the linearised leave-one-view-out jackknife. Real
    corners carry errors shared within a view (blur, lighting, the lens model's misfit) that the
    formal σ²·S⁻¹ misses; with independent corner noise κ stays near 1."""
    V = len(obj)
    if V < 5:
        return 1.0
    x = np.concatenate([new.intrinsics[free], np.hstack([new.rvecs, new.tvecs]).ravel()])
    r, Ji, Jp, _ = _Problem(model, obj, px, new.intrinsics, free)._evaluate(x)
    r = r.reshape(-1, 2)
    nf = int(np.sum(free))
    S, G = np.zeros((nf, nf)), np.zeros((nf, nf))
    start = 0
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
    formal = new.sigma2 * Sinv[:4, :4]
    return max(1.0, float(np.trace(np.linalg.solve(formal, robust))) / 4)


def _drift_test(lens, obj, px, fit, S, cov, hold_distortion):
    """(measured (4,), its covariance (4, 4), drift covariance (4, 4), κ) from a fit of fx, fy, cx, cy
    (module docstring); both covariances are scaled by κ (:func:`_view_inflation`)."""
    n = 4 + lens.dist.size
    free = np.zeros(n, bool)
    free[:4 if hold_distortion else n] = True
    new = bundle_adjust(lens.model, obj, px, lens.intrinsics(), fit.rvecs, fit.tvecs, free=free, rank_strict=False)
    M = np.zeros((4, n))
    M[:, :4] = -np.eye(4)
    if hold_distortion and n > 4:
        M[:, 4:] = -np.linalg.solve(S[:4, :4], S[:4, 4:])
    kappa = _view_inflation(lens.model, obj, px, new, free)
    cnew = kappa * new.covariance[:4, :4]
    return new.intrinsics[:4], cnew, cnew + kappa * (M @ cov @ M.T), kappa


def check_calibration(cal, views, *, alpha: float = ALPHA, hold_distortion: bool = True) -> CheckResult:
    """Test new views of the board against a calibration (module docstring).

    cal : a :class:`~aicalib_tf.calib.fit.Calibration` (any lens model; its covariance is used when
    it has one). views : sequence of :class:`~aicalib_tf.calib.fit.View` seen by the same camera,
    of ``cal.pattern_size`` boards (full or partial). alpha : each test's level in (0, 0.5).
    hold_distortion : fit fx, fy, cx, cy with the distortion held (default) or every intrinsic.
    Raises ValueError for bad arguments and CalibrationError with fewer than
    :data:`MIN_CHECK_VIEWS` usable views.
    """
    if not 0.0 < float(alpha) < 0.5:
        raise ValueError(f"alpha must be in (0, 0.5), got {alpha!r}")
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
    cov, note = calibration_covariance(cal)
    S = _schur(lens.model, obj, px, lens.intrinsics(), fit.rvecs, fit.tvecs)
    measured, cnew, cdrift, kappa = _drift_test(lens, obj, px, fit, S, cov, hold_distortion)
    sigma, _ = corner_noise(cal)
    rms, expected, limit, p_res = _residual_test(fit, S, kappa * cov, sigma, _view_scatter(cal), alpha)
    calibrated = lens.intrinsics()[:4]
    drift = measured - calibrated
    chi2 = float(drift @ np.linalg.solve(cdrift, drift))
    p_drift = chi2_sf(chi2, 4)
    return CheckResult(
        holds=bool(p_res >= alpha and p_drift >= alpha), model=lens.model, views=tuple(names[k] for k in kept),
        per_view_rms=fit.per_view_rms, skipped=skipped, rms=rms, expected_rms=expected, limit_rms=limit,
        residual_p=p_res, noise_px=sigma, calibrated=calibrated, calibrated_std=np.sqrt(np.diag(cov)[:4]),
        measured=measured, measured_std=np.sqrt(np.diag(cnew)), drift=drift, drift_std=np.sqrt(np.diag(cdrift)),
        drift_chi2=chi2, drift_limit=chi2_quantile(1 - alpha, 4), drift_p=p_drift, alpha=float(alpha),
        hold_distortion=hold_distortion, inflation=kappa, notes=(note,) if note else ())


def format_check(result: CheckResult, *, source: str = "", total: int | None = None) -> str:
    """The printed report: the verdict, views used and skipped with reasons, the residual RMS
    against the expected and its limit, and the drift of fx, fy, cx, cy (±1σ of the difference)."""
    used, skipped = len(result.views), len(result.skipped)
    given = total if total is not None else used + skipped
    head = "HOLDS" if result.holds else "DOES NOT HOLD"
    lines = [f"field check{f' of {source}' if source else ''} ({result.model}): the calibration {head}",
             f"  {given} views: {used} used, {given - used} skipped"]
    lines += [f"  skipped  {name}: {why}" for name, why in result.skipped.items()]
    ok = lambda p: "ok" if p >= result.alpha else "FAIL"  # noqa: E731
    q = 100 * (1 - result.alpha)
    lines.append(f"  residual RMS {result.rms:.3f} px with the calibrated intrinsics (expected {result.expected_rms:.3f}, "
                 f"limit {result.limit_rms:.3f} at {q:g}%): {ok(result.residual_p)}")
    what = "distortion held" if result.hold_distortion else "every intrinsic refitted"
    lines.append(f"  drift, new views − calibration ({what}; ±1σ of the difference):")
    for k, p in enumerate(PARAMS):
        rel = f" ({100 * result.drift[k] / result.calibrated[k]:+.2f}%)" if k < 2 else ""
        lines.append(f"    {p} {result.measured[k]:9.2f} − {result.calibrated[k]:9.2f} = {result.drift[k]:+7.2f} "
                     f"± {result.drift_std[k]:.2f} px{rel}")
    lines.append(f"  drift test: chi2 {result.drift_chi2:.1f} for 4 parameters (limit {result.drift_limit:.1f} at "
                 f"{q:g}%): {ok(result.drift_p)}")
    if result.inflation > 1.05:
        lines.append(f"  (σ × {np.sqrt(result.inflation):.2f}: the new views scatter more than independent corner noise)")
    lines += [f"  note: {n}" for n in result.notes]
    lines += [f"  why: {f}" for f in result.failures]
    return "\n".join(lines)
