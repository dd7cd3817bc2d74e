"""Lens-model choice by k-fold cross-validation over views.

For each model of :data:`~aicalib_tf.geometry.lens.MODELS`: fit all views (the in-sample RMS),
then split the views into k = min(5, V) folds (view i in fold i mod k); for each fold, fit the
other views (starting from the all-views fit), and with those intrinsics held fixed solve only
each held-out view's pose (on the board as the fold solved it, flexed when it solved the board's
flex) and measure its reprojection error. With ``flex="auto"`` each fit solves the board's seven shape
terms as fitted; the keep rule of :mod:`~aicalib_tf.calib.flex_check` (a refit per view left out) is the
chosen model's alone: in every fit it chose the same models on opencv_left, udacity_lane_cal and
ocam_fisheye (held-out RMS −2% to +8%, every model alike) at 6–14 times the CPU (9–70 s against 1–5 s).
A fold's score is the RMS over its held-out corners, px; a model's ``cv_rms`` is the mean over folds and
``cv_se`` its standard error (sample standard deviation / √k). The choice is the simplest model whose
``cv_rms`` is within one standard error of the best, simplest by :data:`COMPLEXITY`. The standard error is
that of the best model's score, or, when larger, that of the fold-by-fold gain of the best over the
candidate (the two are scored on the same folds): a held-out gain below its own noise does not count. A
candidate whose fold scores vary more than three times as much as the best's is held to the best's error
(erratic folds are no alternative). On the halves (10 views) of mild-lens sequences of
``benchmarks/fisheye_models.py`` the best's error alone let equidistant beat plumb_bob by 1.7 of its
standard errors, a gain within the noise of the comparison.

A gain that one fold carries alone does not count either, when the candidate fits all the views as
well as the best (in-sample RMS no worse than the best's by more than :func:`_chance_rms` px, what
as many parameters as the two models differ by buy on noise alone): the best's gain over the
other folds within the noise, the candidate is as good. A fold holds out one or two boards; when
one of them lies where the other views did not reach, its score measures how each model
extrapolates to that one pose, and which of two models that fit the seen rays alike extrapolates
better there is a draw of the pose (equidistant's free degree-9 polynomial can miss such a pose by
0.07–0.25 px where EUCM misses it by 0.02–0.06). On the halves of KB 150° and EUCM 170° sequences
equidistant lost to EUCM by one such fold (the gain over the other four folds 0.00002 px, or
negative) while fitting the views as well, and the two halves chose different models of the same
lens. A best model that also fits the views better keeps its gain: on a Double Sphere 190° half,
DS (6 parameters) fitted the views to 0.0200 px against equidistant's 0.0205 (8 parameters; chance
allows 0.00004), its held-out edge mostly in the fold holding a view near the rim, where the two
models differ.

Simplest is not the parameter count. plumb_bob (9 parameters) ⊂ rational_polynomial (12) ⊂
thin_prism (16) nest, but equidistant (8) is another family: on a narrow lens its four radial
terms spend themselves on bending θ into tan θ, it has no tangential terms, and it extrapolates
past the boards as a free degree-9 polynomial. Ranked by count it won the one-SE rule on every
mild and barrel sequence of ``benchmarks/fisheye_calibration.py`` (held-out RMS within noise of
plumb_bob's) while its projection error was 1.4–10× plumb_bob's (mild-1: 1.86 against 0.18 px over
the covered area). So plumb_bob, the classic model, ranks first, then equidistant, then the
rational family; a fisheye lens still goes to equidistant because plumb_bob's held-out error is
then many standard errors off (fisheye150: RMS 0.17 against 0.016 px).

Double Sphere and EUCM (6 parameters each) rank after equidistant: every OpenCV and ROS tool reads
an equidistant lens, none reads the unified models, and on DS 190° and EUCM 170° lenses
equidistant's four terms fit within one standard error of the lens's own model
(``benchmarks/fisheye_models.py``); they are chosen when they fit better than that.

Eligibility. A model must image every ray the boards reached: the fisheye models are fitted first,
the first that fits unprojects every observed corner, and a model whose ``MAX_ANGLE`` is not at
least :data:`RAY_MARGIN_DEG` beyond the widest of those rays (a pinhole: rays at 85° or more) gets a
row saying so and is not fitted. With an image circle (a circular fisheye, estimated from the
photos), the rays of the circle's rim count too (that fit unprojects the rim): a lens whose photo
shows rays at 90° is not a pinhole, even where the boards stopped short of the rim. On real photos
of a 185° circular lens whose boards stayed short of 90° (else no pinhole would have been fitted),
rational_polynomial beat equidistant's held-out RMS by 1.5 standard errors (0.168 against
0.171 ± 0.002 px) with k1 = 0.34 ± 0.23, and the two halves of the views chose different families:
beyond the boards its pixels were a pinhole's extrapolation of a lens it cannot image.

Wide lenses. When the boards or the image circle's rim reach :data:`WIDE_REACH_DEG` or more
off-axis (and a pinhole is still eligible, below 85°), a pinhole-family model is chosen only by a
clear held-out margin over the best of the fisheye family and the spline: its gain over that model
at least :data:`PINHOLE_MARGIN_SE` times the gain's noise (:func:`_gain_noise`) and
:data:`PINHOLE_MARGIN_FRACTION` of that model's held-out RMS; short of it, the pinhole rows leave the
choice and their notes say so. The one-SE rule alone handed the 1.5-SE edge of the example above to
rational_polynomial, whose field of view over the image circle was then a pinhole's extrapolation
(147° for a 185° lens).

A model whose fit chooses its layout from the views (the spline, ``START == "layout"``) comes last, and
is fitted only when the best model so far leaves a pattern in its residuals over the image
(:func:`~aicalib_tf.calib.splined_fit.misfit_note`); its row says so otherwise. A spline refused by its
fit (too few views) gets the reason in its row, and the choice moves on.

Determined extras. Among the models within one standard error, one whose ``EXTRA_COEFFS`` (the
coefficients that make it more than a simpler model: rational's k4..k6, DS's ξ, EUCM's β) the
views do not determine (|value − the simpler model's value| < 2σ) gives way to one that is
determined; the simplest determined model wins (the simplest of all when none is).

A model that cannot be fitted (too few corners for its parameters, a rank-deficient or diverging
fit, a held-out view it cannot pose) gets a row whose note says why, and the choice moves on.
With fewer than ``MIN_CV_VIEWS`` views there is no cross-validation: the first model of MODELS that
fits all views is kept (plumb_bob, the classic default, when it fits) and the notes say so.
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.calib.bundle import CalibrationError, solve_pose
from aicalib_tf.calib.splined_fit import misfit_note
from aicalib_tf.calib.starts import widest_angle
from aicalib_tf.geometry.board_shape import shaped_points
from aicalib_tf.geometry.image_circle import circle_fov_deg
from aicalib_tf.geometry.lens import MODELS, N_COEFFS, Lens, get_model
from aicalib_tf.geometry.pattern import board_points

__all__ = ["select_model", "cross_validate", "fold_scores", "held_out_rms",
           "choose", "near_best", "undetermined_extras", "widest_ray_deg", "COMPLEXITY",
           "RAY_MARGIN_DEG", "WIDE_REACH_DEG", "PINHOLE_MARGIN_SE", "PINHOLE_MARGIN_FRACTION", "pinhole_margin_note"]

COMPLEXITY = tuple(sorted(MODELS, key=lambda m: get_model(m).RANK))  # simplest first (each model's RANK), see above
MAX_FOLDS = 5
MIN_CV_VIEWS = 4  # every fold then leaves at least 3 views to fit
# the fewest views with which the choice tries a spline. Tried from 6 (benchmarks/splined_model.py --choice,
# seeds 5, 6; projection error median px against the parametric model it keeps without the spline): on a 130°
# lens with a bump it chose the spline at 8-20 views and truly won each time (0.015-0.028 against 0.29-0.55);
# on a 190° fisheye with a bump it chose it at 12 and 16 views and truly lost (0.077 against 0.058, 0.082
# against 0.062; the other seed kept equidistant), at 20 it won with both seeds (0.037 against 0.048, 0.046 against
# 0.047 with p95 0.080 against 0.148); never on the fisheye without the bump. On the real halves (6-8 photos,
# --halves: opencv_left, ocam_fisheye) it chose the spline in 1 of 16 halves. Below 20 views held-out error
# picks a spline that loses, so the choice tries it from 20
AUTO_SPLINE_VIEWS = 20
RAY_MARGIN_DEG = 5.0  # a model must image rays this far beyond the widest reached (pinholes: below 85°)
WIDE_REACH_DEG = 70.0  # from this reach on, a pinhole needs a clear held-out margin over the wide models
PINHOLE_MARGIN_SE = 2.0  # that margin: this many standard errors of the gain ...
PINHOLE_MARGIN_FRACTION = 0.05  # ... and this fraction of the wide model's held-out RMS



def cross_validate(views, square_size: float, fit, model: str, full, pattern_size=None) -> tuple[float, float]:
    """(cv_rms px, cv_se px) of one model: the mean of :func:`fold_scores` and its standard error."""
    scores = fold_scores(views, square_size, fit, model, full, pattern_size)
    return float(scores.mean()), float(scores.std(ddof=1) / np.sqrt(len(scores)))


def held_out_rms(fit, held, square_size: float, pattern_size=None) -> float:
    """px: the RMS over the ``held`` views' corners, each view's pose solved with ``fit``'s intrinsics (a
    BundleResult) on the board as ``fit`` solved it: flat, or flexed by its ``flex`` (in board units of
    ``square_size`` per square; needs ``pattern_size``). A fold's flex is the board's, so a held-out view
    posed on a flat board would charge the flexed fit with the flex it found. Raises CalibrationError when
    a held-out view cannot be posed, ValueError for a flexed fit without ``pattern_size``."""
    lens = Lens.from_intrinsics(fit.model, fit.intrinsics, (1, 1))
    flex = getattr(fit, "flex", None)
    if flex is not None and pattern_size is None:
        raise ValueError("a fit with a board flex needs pattern_size to pose held-out views")
    sq, n = 0.0, 0
    for v in held:
        obj = board_points(v.ids, square_size)
        if flex is not None:
            obj = shaped_points(obj, pattern_size, np.asarray(flex, np.float64) / square_size, square_size)
        pose = solve_pose(lens, obj, v.corners)
        if pose is None or not np.isfinite(pose[2]):
            raise CalibrationError(f"{fit.model}: held-out view {v.name} cannot be posed with the fold's intrinsics")
        sq, n = sq + pose[2] ** 2 * len(v.ids), n + len(v.ids)
    return float(np.sqrt(sq / n))


def fold_scores(views, square_size: float, fit, model: str, full, pattern_size=None) -> np.ndarray:
    """(k,) px: each fold's held-out RMS for one model; ``full`` is its all-views fit (a BundleResult), the folds' start.

    views : list of View; fit(views, model, start) -> BundleResult; pattern_size : (cols, rows), needed when
    the fits solve the board's flex (:func:`held_out_rms`). Raises CalibrationError when a
    fold cannot be fitted, its fit does not converge within the evaluation cap (its parameters are
    then not the model's estimate from those views, so they say nothing about the model; the model
    has more parameters than the views determine), or a held-out view cannot be posed.
    """
    k = min(MAX_FOLDS, len(views))
    if k < 2:
        raise CalibrationError(f"{model}: cross-validation needs at least 2 views, got {len(views)}")
    model = full.model  # a model whose fit chose its layout (a spline): every fold keeps that layout
    start = Lens.from_intrinsics(model, full.intrinsics, (1, 1))
    scores = []
    for f in range(k):
        train = [v for i, v in enumerate(views) if i % k != f]
        held = [v for i, v in enumerate(views) if i % k == f]
        if len(train) < 3:
            raise CalibrationError(f"{model}: a fold leaves {len(train)} views to fit (need 3)")
        fold = fit(train, model, start)
        if not fold.converged:
            raise CalibrationError(f"{model}: fold {f + 1} of {k} did not converge in {fold.nfev} evaluations "
                                   f"(its {fold.intrinsics.size} parameters are not determined by {len(train)} views)")
        scores.append(held_out_rms(fold, held, square_size, pattern_size))
    return np.array(scores)


def _gain_noise(r: dict, best: dict) -> float:
    """px: the noise of ``best``'s held-out gain over ``r``: the best's standard error, or the standard error
    of the fold-by-fold gain when both rows carry "cv_folds" and ``r`` varies between folds no more than
    three times as much as the best (an erratic model is no alternative)."""
    se = best["cv_se"]
    a, b = r.get("cv_folds"), best.get("cv_folds")
    if a is not None and b is not None and len(a) == len(b) > 1 and r["cv_se"] <= 3.0 * best["cv_se"]:
        gain = np.asarray(a, np.float64) - np.asarray(b, np.float64)
        se = max(se, float(gain.std(ddof=1) / np.sqrt(len(gain))))
    return se


def _chance_rms(r: dict, best: dict) -> float:
    """px: how much lower an in-sample RMS k more parameters reach on noise alone, k the two rows' parameter
    counts' difference (at least 1): RMS·k / (4N) over N corners ("corners"; 0 without it). Each useless
    parameter removes one component's variance σ² = RMS²/2 from the 2N residuals' sum, RMS² = sum / N."""
    n = r.get("corners") or 0
    k = max(1, abs(r["n_params"] - best["n_params"]))
    return best["rms"] * k / (4.0 * n) if n else 0.0


def _gain(r: dict, best: dict) -> float:
    """px: ``best``'s held-out gain over ``r``: the mean over folds, or the mean over all folds but the one
    where the best gains most, when that is smaller, both rows carry three or more "cv_folds" and ``r``
    fits all the views as well as the best ("rms", in-sample, within :func:`_chance_rms`; module docstring)."""
    gain = r["cv_rms"] - best["cv_rms"]
    a, b = r.get("cv_folds"), best.get("cv_folds")
    if a is None or b is None or len(a) != len(b) or len(a) < 3:
        return gain
    if not r.get("rms", np.nan) <= best.get("rms", np.nan) + _chance_rms(r, best):  # the best fits better: a real edge
        return gain
    folds = np.sort(np.asarray(a, np.float64) - np.asarray(b, np.float64))
    return min(gain, float(folds[:-1].mean()))


def near_best(rows: list[dict]) -> list[dict]:
    """The rows (with "cv_rms", "cv_se" and optionally "cv_folds", "rms", "n_params", "corners") whose
    held-out RMS is within the noise of the best's (:func:`_gain` within :func:`_gain_noise`); the best among them."""
    best = min(rows, key=lambda r: r["cv_rms"])
    return [r for r in rows if _gain(r, best) <= _gain_noise(r, best)]


def pinhole_margin_note(rows: list[dict], reach_deg: float) -> dict[str, str]:
    """{pinhole model: why it leaves the choice} for a lens reaching ``reach_deg`` off-axis: every
    cross-validated pinhole-family row whose held-out gain over the best fisheye-family or spline row
    falls short of the clear margin (module docstring, "Wide lenses"); {} below :data:`WIDE_REACH_DEG`
    or without a cross-validated wide row."""
    ok = [r for r in rows if np.isfinite(r["cv_rms"])]
    wide = [r for r in ok if get_model(r["model"]).IS_FISHEYE]
    if not reach_deg >= WIDE_REACH_DEG or not wide:
        return {}
    ref = min(wide, key=lambda r: r["cv_rms"])
    out = {}
    for r in ok:
        if get_model(r["model"]).IS_FISHEYE:
            continue
        gain, noise = ref["cv_rms"] - r["cv_rms"], _gain_noise(ref, r)
        need = max(PINHOLE_MARGIN_SE * noise, PINHOLE_MARGIN_FRACTION * ref["cv_rms"])
        if not gain > need:
            out[r["model"]] = (f"rays reach {reach_deg:.1f}° off-axis: a pinhole model needs a held-out gain of "
                               f"{need:.4f} px over {ref['model']} ({PINHOLE_MARGIN_SE:g} SE and "
                               f"{100 * PINHOLE_MARGIN_FRACTION:g}%), got {gain:+.4f} (not chosen)")
    return out


def choose(rows: list[dict], reach_deg: float = float("nan")) -> str | None:
    """The simplest model whose held-out RMS is within the noise of the best's (:func:`_gain` within
    :func:`_gain_noise`: one standard error) and whose extras are determined (rows as in
    :func:`select_model`; a row without "determined" counts as determined). reach_deg : the widest ray
    the boards or the image circle reach (degrees; NaN: unknown); from :data:`WIDE_REACH_DEG` on, the
    pinholes without a clear margin (:func:`pinhole_margin_note`) leave the choice."""
    ok = [r for r in rows if np.isfinite(r["cv_rms"])]
    out = pinhole_margin_note(ok, reach_deg)
    ok = [r for r in ok if r["model"] not in out] or ok
    if not ok:
        return None
    best = min(ok, key=lambda r: r["cv_rms"])
    near = [r for r in ok if _gain(r, best) <= _gain_noise(r, best)]
    near = [r for r in near if r.get("determined", True)] or near
    return min(near, key=lambda r: COMPLEXITY.index(r["model"]))["model"]


def undetermined_extras(fit) -> list[str]:
    """Names of ``fit``'s ``EXTRA_COEFFS`` within 2σ of the value that makes the model a simpler one
    (a BundleResult with a covariance; [] without one)."""
    spec = get_model(fit.model)
    if fit.covariance is None or not spec.EXTRA_COEFFS:
        return []
    sd = np.sqrt(np.maximum(np.diag(fit.covariance), 0.0))
    out = []
    for name, null in spec.EXTRA_COEFFS.items():
        i = 4 + spec.COEFF_NAMES.index(name)
        if abs(fit.intrinsics[i] - null) < 2.0 * sd[i]:
            out.append(name)
    return out


def widest_ray_deg(fit, views) -> float:
    """Degrees: the widest off-axis angle of the rays ``fit``'s lens gives the views' corners (NaN if none)."""
    lens = Lens.from_intrinsics(fit.model, fit.intrinsics, (1, 1))
    return float(np.degrees(widest_angle(lens, [v.corners for v in views])))


def _fit(fit, views, model, start):
    """``fit`` from ``start``; from scratch when that start fails."""
    if start is not None:
        try:
            return fit(views, model, start)
        except CalibrationError:
            pass
    return fit(views, model, None)


def _row(model: str, corners: int) -> dict:
    return {"model": model, "n_params": 4 + N_COEFFS[model], "rms": float("nan"), "cv_rms": float("nan"),
            "cv_se": float("nan"), "chosen": False, "note": "", "determined": True, "corners": corners}


def _reach(fit, views, circle) -> tuple[float, str]:
    """(degrees, what reached them): the widest ray of the views' corners under ``fit``'s lens, or of
    the image circle's rim when that is wider."""
    widest, what = widest_ray_deg(fit, views), "the boards reach rays"
    if circle is not None:
        rim = 0.5 * circle_fov_deg(Lens.from_intrinsics(fit.model, fit.intrinsics, (1, 1)), circle)
        if not rim <= widest:
            widest, what = rim, "the image circle's rim is at rays"
    return widest, what


def select_model(views, square_size: float, fit, models=MODELS, *, circle=None, pattern_size=None):
    """Cross-validate each model and choose one: returns (table, chosen model, its all-views fit).

    views : list of View (all usable). fit(views, model, start) -> BundleResult, start a Lens or
    None (from scratch). circle : the image circle (an
    :class:`~aicalib_tf.geometry.image_circle.ImageCircle`) or None; its rim counts as reached.
    pattern_size : (cols, rows), needed when ``fit`` solves the board's flex (:func:`held_out_rms`).
    table : tuple of dicts {"model", "n_params", "rms" (in-sample px), "cv_rms",
    "cv_se" (px), "chosen", "note", "determined", "corners"} in ``models`` order. The chosen model is the name its fit carries (a spline's names the
    layout its fit chose; its row has the bare name). Raises CalibrationError when no model can be fitted.
    """
    rows, fits, widest, what = {}, {}, None, ""
    order = sorted(models, key=lambda m: (get_model(m).START == "layout", not get_model(m).IS_FISHEYE))
    for model in order:  # fisheyes first (the widest ray), a model whose views choose its layout (a spline) last
        row = rows[model] = _row(model, sum(len(v.ids) for v in views))
        if get_model(model).START == "layout" and fits:  # a spline only where the best model leaves a pattern
            ranked = sorted((m for m in fits if np.isfinite(rows[m]["cv_rms"])), key=lambda m: rows[m]["cv_rms"])
            note = misfit_note(fits[ranked[0]], views) if ranked else None
            if note is None and len(views) < AUTO_SPLINE_VIEWS and len(models) > 1:
                note = (f"{model}: not tried with {len(views)} views (the choice tries it from {AUTO_SPLINE_VIEWS}; "
                        f"--model {model} fits it)")
            if note is not None:
                row["note"] = note
                continue
        if widest is not None and not widest + RAY_MARGIN_DEG < np.degrees(get_model(model).MAX_ANGLE):
            row["note"] = (f"{what} {widest:.1f}° off-axis; {model} images less than "
                           f"{np.degrees(get_model(model).MAX_ANGLE):.0f}° (not eligible)")
            continue
        warm = get_model(model).WARM_FROM  # e.g. one OpenCV start for the pinhole family
        start = Lens.from_intrinsics(warm, fits[warm].intrinsics, (1, 1)) if warm in fits else None
        try:
            fits[model] = _fit(fit, views, model, start)
            row["rms"], row["n_params"] = fits[model].rms, fits[model].intrinsics.size
            if widest is None and get_model(model).IS_FISHEYE:
                widest, what = _reach(fits[model], views, circle)
            vague = undetermined_extras(fits[model])
            if vague:
                row["determined"] = False
                row["note"] = f"{', '.join(vague)} not determined (within 2σ of a simpler model's value)"
            if len(views) >= MIN_CV_VIEWS:
                folds = fold_scores(views, square_size, fit, model, fits[model], pattern_size)
                row["cv_rms"], row["cv_se"] = float(folds.mean()), float(folds.std(ddof=1) / np.sqrt(len(folds)))
                row["cv_folds"] = folds.tolist()
            else:
                row["note"] = f"{len(views)} views: too few to cross-validate (need {MIN_CV_VIEWS})"
        except CalibrationError as exc:
            row["note"] = str(exc)
    table = [rows[m] for m in models]
    reach = float("nan") if widest is None else widest
    if len(views) >= MIN_CV_VIEWS:
        for m, note in pinhole_margin_note(table, reach).items():
            rows[m]["note"] = "; ".join(n for n in (rows[m]["note"], note) if n)
    chosen = choose(table, reach) if len(views) >= MIN_CV_VIEWS else next((m for m in models if m in fits), None)
    if chosen is None:
        raise CalibrationError("no lens model could be fitted: " + "; ".join(f"{r['note']}" for r in table))
    for r in table:
        r["chosen"] = r["model"] == chosen
    return tuple(table), fits[chosen].model, fits[chosen]
