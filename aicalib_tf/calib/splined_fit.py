"""The splined lens model's fit: its knot layout and smoothness chosen from the views, then one bundle fit.

A fit of ``splined_equidistant`` (the bare name; :mod:`aicalib_tf.geometry._splined`) goes:

1. **Base lens.** The start lens (under ``auto``: the equidistant fit), or an equidistant fit from
   scratch (:func:`~aicalib_tf.calib.starts.fisheye_start`). The spline's base projection is that lens
   when it is equidistant and monotonic well beyond the corners; else two candidates, a fit of its radial
   profile with fewer terms and the plain θ_d = θ (:func:`_bases`), which step 4 scores.
2. **Refusal.** Fewer than :data:`MIN_VIEWS` views, or fewer than :data:`CORNERS_PER_KNOT` corners per
   knot (half the target density below) of the coarsest grid over the area the boards cover, do not determine a spline: a
   :class:`~aicalib_tf.calib.bundle.CalibrationError` says so ("splined_equidistant: needs at least 6
   views covering ..., got 4") and the model choice moves on. So do boards that leave much of the image
   unseen: the layout is centred on the principal point, and when more than :data:`MAX_EMPTY_KNOTS` of the
   knots under the image (step 3's layout; a knot reaches the 4×4 cells around it) reach no corner, the
   regularization alone would set most of the spline. Boards over the whole image leave 7–29% (``opencv_left``
   and ``ocam_fisheye``, all photos and 8 halves each), 7–41% on the benchmark's lenses (6–20 views: 6 views of
   the 190° fisheye reach 40%); boards kept to one half of the image 40–55%: the rule stops gross cases only.
   Six views are enough for the fold choice of
   step 4: on the 130° lens with a bump, 6 views gave a projection error median of 0.03 and 0.16 px (two
   draws; equidistant 0.47 and 0.20), 8 views 0.06 and 0.11 (0.67 and 0.29); on the 190° fisheye with a
   bump, where equidistant holds the lens but the bump, 6 views 0.09 and 0.05 (0.05, 0.05), 8 views 0.11 and 0.05
   (0.10, 0.06).
3. **Layout.** The knot spacing h gives the area the corners cover (their convex hull in the (u, v)
   plane of the base projection) :data:`CORNERS_PER_KNOT` corners per knot:
   h = √(CORNERS_PER_KNOT · area / corners). The spline's rectangle, centred on the principal point,
   reaches 2% and half a spacing beyond the farthest corner (rays up to :data:`MAX_HALF_FOV_DEG`) along
   each axis, and nx, ny follow (at least 6 each). Pixels beyond it have no ray: the spline describes
   the lens where the boards were, and the undistortion maps leave the rest black.
4. **Smoothness.** ``smooth`` = s·f px per normalized unit, for s in :data:`SMOOTH_REL` from the smoothest
   down, each base of step 1: each is scored by :data:`SMOOTH_FOLDS`-fold held-out RMS (each fold fitted on
   the other views, its held-out views posed with the fitted intrinsics; with the board's shape solved, each
   fold solves it too and poses its held-out views on it); the search along s stops once a score exceeds the
   base's best by :data:`SMOOTH_STOP`, the lowest mean wins, the smoother on a tie within 1%. On 10 views of
   a 130° lens with a bump (``benchmarks/splined_model.py``'s scene, seed 5; projection error median / p95
   over the covered area): one even/odd split on θ_d = θ chose s = 0.01, 0.22 / 1.08 px; the folds on
   θ_d = θ 0.3, 0.19 / 0.69; the folds with the fitted base 0.1, 0.07 / 0.19. One fold can decide the mean
   (8 views of a 190° fisheye: one view held out alone at 0.36 px, the others 0.06–0.08, rose to 0.52 at
   s = 0.3 and stopped the search), but the scores that keep it from doing so chose worse: the mean without
   the largest fold and the geometric mean of each view's held-out RMS both chose s = 0.03 on 30 views of
   the bump lens, 0.047 / 0.126 px, where the mean chose 0.3, 0.013 / 0.068 (the same choice as the mean on
   nine scenes of 12–20 views): the worst fold holds the extrapolation a bendier spline pays for.
Under ``auto`` (:mod:`aicalib_tf.calib.select`) a spline is fitted only when the best parametric model
leaves a pattern in its residuals over the image (:func:`misfit_note`): it has nothing to earn otherwise.

5. **Start and fit.** K from the base lens; the knots by linear least squares so that the spline matches
   the base lens's projection of the corners' rays and of a grid over the rectangle (with the
   regularization); poses by PnP on rays; then the bundle fit with the regularization.

6. **Corners and board.** The fit is a solve like every model's (:func:`~aicalib_tf.calib.robust.solve`):
   corners weighted by their σ, single outlying corners rejected by the same rule and reported the same way
   (``rejected_corners`` in camera.json), the board's shape solved as the options ask; the caller's keep rule
   (:func:`~aicalib_tf.calib.flex_check.confirm_flex`: each term shrunk by its leave-one-view-out noise, with
   ``flex="auto"`` the shape kept only when it moves the lens beyond that noise) refits from the spline, each
   refit at its layout and smoothness. A bent board biases a spline as it does any model: 12 views of the
   130° lens with a bump on a board 0.0058 squares out of plane (all seven terms, 0.02 px): projection error
   median / p95 0.21 / 0.70 px flat, 0.032 / 0.127 with the shape (0.0052 solved, 89% kept; a flat board
   0.029 / 0.080).
   Before step 4, one solve of the layout at ``smooth`` = :data:`CLEAN_SMOOTH_REL`·f on a flat board
   (bendy enough to follow a lens's bump, too stiff to follow one corner; each fit capped at
   :data:`HELD_OUT_NFEV` evaluations; a concrete layout: at its own smoothness) finds the corners the folds
   leave out and the final solve starts without: each would otherwise weigh on every held-out score, and a
   fit that starts with them wanders along the knots' weak directions (10 views, 4 corners moved 3–10 px: 500
   evaluations without converging). The final solve tests every corner again. A start that is a fitted
   spline of the layout (a fold, a refit) flags them at its own smoothness.

A concrete layout (``splined_equidistant_nx=.._ny=.._fov=.._smooth=..``) keeps its layout and smoothness (with two
candidate bases, the fit that ends with the lower cost is kept); a start that is already a spline of that layout starts the bundle as it is.
"""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np

from aicalib_tf.calib.bundle import BundleResult, CalibrationError, bundle_adjust, poses_from_rays, solve_pose
from aicalib_tf.calib.flex import basis_of_views, mode_terms
from aicalib_tf.calib.robust import SolveOptions, solve
from aicalib_tf.calib.starts import fisheye_start
from aicalib_tf.geometry._equidistant import monotonic_limit as kb_monotonic
from aicalib_tf.geometry._equidistant import project as kb_project
from aicalib_tf.geometry._equidistant import unproject as _unproject_kb
from aicalib_tf.geometry._splined import FAMILY_NAME, MAX_KNOTS, MIN_KNOTS, N_BASE, splined_name
from aicalib_tf.geometry.lens import Lens, get_model

__all__ = ["fit_splined", "choose_layout", "empty_knots", "spline_start", "misfit_note", "MIN_VIEWS", "CORNERS_PER_KNOT",
           "SMOOTH_REL", "MAX_EMPTY_KNOTS"]

MIN_VIEWS = 6  # the fewest views a spline is fitted to (module docstring, step 2)
CORNERS_PER_KNOT = 20.0  # corners per knot over the covered area (each knot holds 2 values)
SMOOTH_REL = (1.0, 0.3, 0.1, 0.03, 0.01, 0.003)  # smooth / f candidates, the smoothest first
SMOOTH_FOLDS = 5  # folds of the held-out score that chooses among them
SMOOTH_STOP = 1.1  # the search stops at a score this much above the best so far
MAX_NFEV = 500  # a spline fit's evaluations (its weakly regularized directions converge slowly)
HELD_OUT_NFEV = 100  # each smoothness candidate's fit on half the views
CLEAN_SMOOTH_REL = 0.03  # smooth / f of the fit whose rejected corners the folds leave out (step 6)
MAX_HALF_FOV_DEG = 100.0  # the widest border ray the rectangle is stretched to cover
_MARGIN = 1.02
RANGE_MARGIN_DEG = 15.0
BASE_ORDERS = (4, 3, 2, 1)  # the base's k1..k4 terms tried, most first
MISFIT_GRID = 6  # cells per axis of the residual-pattern test
MAX_EMPTY_KNOTS = 0.5  # the largest fraction of the knots under the image that reach no corner (step 2)
MISFIT_Z = 3.0


def _bases(base: Lens, px) -> list[Lens]:
    """The spline's candidate base lenses for ``base`` (the start lens): equidistant lenses with its K.

    ``base`` itself when it is equidistant and θ -> θ_d increases :data:`RANGE_MARGIN_DEG` beyond the
    corners' widest ray (corners past that range would be outside the spline's base, with no gradient to
    bring them back). Else two: the least-squares fit of ``base``'s radial profile up to that ray with
    the most of k1..k4 (:data:`BASE_ORDERS`) that keeps that margin, and the plain θ_d = θ. The fitted one
    carries the lens's radial bulk, which the knots' smoothness penalty would otherwise fight (10 views of
    a 130° lens with a bump: projection error 0.07–0.10 px against 0.19–1.5 px on θ_d = θ); the plain one
    does not inherit a bent profile (an equidistant fit of a wide pinhole lens that turns back just past the
    corners: 0.012 px in-sample against 0.03). :func:`_choose_smooth` scores both."""
    corners = np.concatenate([np.asarray(p, np.float64).reshape(-1, 2) for p in px])
    rays = base.unproject(corners)
    rays = rays[np.isfinite(rays).all(axis=1)]
    plain = Lens("equidistant", base.K, np.zeros(N_BASE), base.image_size)
    if len(rays) == 0:
        return [plain]
    widest = min(float(np.max(np.arctan2(np.hypot(rays[:, 0], rays[:, 1]), rays[:, 2]))),
                 math.radians(MAX_HALF_FOV_DEG))
    margin = widest + math.radians(RANGE_MARGIN_DEG)
    if base.spec.FAMILY == "equidistant" and base.max_angle() >= margin:
        return [Lens("equidistant", base.K, base.dist[:N_BASE], base.image_size)]
    theta, target = _radial_profile(base, widest)
    for order in BASE_ORDERS:
        if len(theta) < 2 * order:
            continue
        A = np.stack([theta ** (2 * i + 3) for i in range(order)], axis=1)
        k = np.zeros(N_BASE)
        k[:order] = np.linalg.lstsq(A, target - theta, rcond=None)[0]
        if kb_monotonic(tuple(k)) >= margin:
            return [Lens("equidistant", base.K, k, base.image_size), plain]
    return [plain]


def _radial_profile(base: Lens, widest: float, n: int = 48, azimuths: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """(θ (M,) rad, θ_d (M,)): ``base``'s normalized image radius |((x − cx)/fx, (y − cy)/fy)| of rays at
    θ ∈ (0, widest], the median over ``azimuths`` directions (θ where some direction has no image dropped)."""
    theta = np.linspace(widest / n, widest, n)
    phi = np.linspace(0.0, 2 * math.pi, azimuths, endpoint=False)
    T, F = np.meshgrid(theta, phi, indexing="ij")
    rays = np.stack([np.sin(T) * np.cos(F), np.sin(T) * np.sin(F), np.cos(T)], axis=-1).reshape(-1, 3)
    q = base.project(rays)
    r = np.hypot((q[:, 0] - base.cx) / base.fx, (q[:, 1] - base.cy) / base.fy).reshape(n, azimuths)
    ok = np.isfinite(r).all(axis=1)
    return theta[ok], np.median(r[ok], axis=1)


def _uv(lens: Lens, px: np.ndarray) -> np.ndarray:
    """(N, 2) px -> (M, 2) base-plane (u, v) of their rays under ``lens`` (rays with none dropped)."""
    rays = lens.unproject(px)
    rays = rays[np.isfinite(rays).all(axis=1)]
    ang = np.arctan2(np.hypot(rays[:, 0], rays[:, 1]), rays[:, 2])
    rays = rays[ang <= math.radians(MAX_HALF_FOV_DEG)]
    u, v, ok = kb_project(rays, _bases(lens, [px])[0].dist)
    return np.stack([u[ok], v[ok]], axis=1)


def choose_layout(base: Lens, px, image_size, n_views: int) -> tuple[int, int, float]:
    """(nx, ny, fov deg) of the spline for these corners (module docstring, steps 2–3).

    base : the base lens. px : list of (N_v, 2) corners. Raises CalibrationError when the views do not
    determine a spline."""
    corners = np.concatenate([np.asarray(p, np.float64).reshape(-1, 2) for p in px])
    uv = _uv(base, corners)
    if n_views < MIN_VIEWS or len(uv) < 3:
        raise CalibrationError(f"{FAMILY_NAME}: needs at least {MIN_VIEWS} views covering the image, got {n_views}")
    area = float(cv2.contourArea(cv2.convexHull(uv.astype(np.float32))))
    h = math.sqrt(CORNERS_PER_KNOT * area / len(uv))
    U, V = (float(np.max(np.abs(uv[:, k]))) * _MARGIN + 0.5 * h for k in (0, 1))
    nx = int(min(max(math.ceil(2 * U / h) + 3, MIN_KNOTS), MAX_KNOTS))
    h = 2 * U / (nx - 3)
    ny = int(min(max(math.ceil(2 * V / h) + 3, MIN_KNOTS), MAX_KNOTS))
    knots_covered = area / (h * h)
    if len(uv) < 0.5 * CORNERS_PER_KNOT * knots_covered:  # even the coarsest grid is finer than the corners allow
        raise CalibrationError(f"{FAMILY_NAME}: needs at least {math.ceil(0.5 * CORNERS_PER_KNOT * knots_covered)} "
                               f"corners covering the image for a {nx}x{ny} knot grid, got {len(uv)} in {n_views} views")
    gx, gy = np.meshgrid(np.linspace(0, image_size[0] - 1, 48), np.linspace(0, image_size[1] - 1, 36))
    pixels = _uv(base, np.stack([gx.ravel(), gy.ravel()], axis=1))
    empty = empty_knots(uv, pixels, nx, ny, math.degrees(2 * U))
    if empty > MAX_EMPTY_KNOTS:
        raise CalibrationError(f"{FAMILY_NAME}: {100 * empty:.0f}% of the {nx}x{ny} knots under the image reach no "
                               f"corner (at most {100 * MAX_EMPTY_KNOTS:.0f}%): the boards leave part of the image unseen")
    return nx, ny, math.degrees(2 * U)


def empty_knots(uv: np.ndarray, pixels: np.ndarray, nx: int, ny: int, fov_deg: float) -> float:
    """The fraction of an ``nx × ny`` layout's knots (``fov_deg`` wide) under the image whose 4×4-cell reach
    holds none of the corners: knots only the regularization sets. uv, pixels : (N, 2), (M, 2) base-plane
    points of the corners and of a grid over the image (a knot is under the image when one reaches it)."""
    spec = get_model(splined_name(nx, ny, fov_deg, 1.0))

    def reached(p):
        inside, idx, _, _, _ = spec.locate(p[:, 0], p[:, 1])
        return np.bincount(idx[inside].ravel(), minlength=nx * ny) > 0

    under = reached(pixels)
    return float(np.mean(~reached(uv)[under])) if under.any() else 0.0


def spline_start(base: Lens, model: str, px, k=None) -> np.ndarray:
    """(4 + n,) start [fx, fy, cx, cy, k1..k4, *knots] of the spline ``model`` that matches ``base`` over the
    corners' rays and a grid over its rectangle (linear least squares with its regularization); k : (4,)
    the base projection's k1..k4 (default: the first of :func:`_bases`)."""
    spec = get_model(model)
    corners = np.concatenate([np.asarray(p, np.float64).reshape(-1, 2) for p in px])
    rays = base.unproject(corners)
    g = np.linspace(-1.0, 1.0, 25)
    gu, gv = np.meshgrid(g * spec.U, g * spec.V)
    k = np.asarray(_bases(base, px)[0].dist if k is None else k, np.float64)
    grid = _unproject_kb(gu.ravel(), gv.ravel(), k)
    rays = np.concatenate([rays, grid])
    target = base.project(rays)
    u, v, ok = kb_project(rays, k)
    keep = ok & np.isfinite(target).all(axis=1) & (np.abs(u) <= spec.U) & (np.abs(v) <= spec.V)
    u, v, target = u[keep], v[keep], target[keep]
    _, _, _, _, idx, w = spec.correction(u, v, np.zeros(spec.n_coeffs))  # the weights alone
    m = spec.nx * spec.ny
    B = np.zeros((len(u), m))
    B[np.repeat(np.arange(len(u)), 16), idx.reshape(-1)] = w.reshape(-1)
    P = spec._prior_matrix()  # its rows per grid: the x grid's first
    half = P[: P.shape[0] // 2, N_BASE:N_BASE + m]
    knots = []
    for axis, (f, c, s) in enumerate(((base.fx, base.cx, u), (base.fy, base.cy, v))):  # px rows and the prior's
        A = f * B
        knots.append(np.linalg.solve(A.T @ A + half.T @ half, A.T @ (target[:, axis] - c - f * s)))
    return np.concatenate([[base.fx, base.fy, base.cx, base.cy], k, *knots])


def misfit_note(fit, views) -> str | None:
    """Why the model choice need not fit a spline after ``fit`` (the best parametric BundleResult), or None.

    The views' corners are binned on a :data:`MISFIT_GRID` grid over their bounding box; a cell with at
    least 8 corners contributes n·|mean residual|²/σ² (σ²: the residuals' variance per axis), which is
    χ² with 2 degrees of freedom per cell when the residuals are noise alone. The Wilson–Hilferty z of
    the sum below :data:`MISFIT_Z` says the parametric model leaves no pattern a spline could take up."""
    r = [np.asarray(x, np.float64).reshape(-1, 2) for x in getattr(fit, "residuals", None) or []]
    q = [np.asarray(v.corners, np.float64).reshape(-1, 2) for v in views]
    if len(r) != len(q) or any(len(a) != len(b) for a, b in zip(r, q)):
        return None
    r, q = np.concatenate(r), np.concatenate(q)
    ok = np.isfinite(r).all(axis=1)
    r, q = r[ok], q[ok]
    lo, hi = q.min(axis=0), q.max(axis=0) + 1e-9
    cell = np.floor((q - lo) / (hi - lo) * MISFIT_GRID).astype(np.int64)
    key = cell[:, 1] * MISFIT_GRID + cell[:, 0]
    var = float(np.mean(r * r))
    stat, k = 0.0, 0
    for c in np.unique(key):
        sel = key == c
        if sel.sum() >= 8:
            m = r[sel].mean(axis=0)
            stat, k = stat + sel.sum() * float(m @ m) / max(var, 1e-300), k + 2
    if k == 0:
        return None
    z = ((stat / k) ** (1 / 3) - (1 - 2 / (9 * k))) / math.sqrt(2 / (9 * k))
    if z >= MISFIT_Z:
        return None
    return (f"{FAMILY_NAME}: not fitted: the best model's residuals show no pattern over the image "
            f"(z = {z:.1f} < {MISFIT_Z:g} over {k // 2} cells)")


def _held_out_rms(model: str, obj, px, warm, train: np.ndarray, basis=None) -> tuple[np.ndarray, BundleResult]:
    """((V,) px, the fit): fit on the views ``train`` (bool (V,)) from ``warm`` = (intrinsics, the train views'
    rvecs, tvecs (T, 3) each, the board shape (K,) or None); each held-out view's RMS posed with those
    intrinsics (inf when it cannot be posed; NaN for the train views). basis : per-view (N_v, K) board-shape
    rows (the shape solved with the fold, its held-out views posed on the board as the fold shaped it), or
    None (a flat board)."""
    pick = lambda seq: [s for s, t in zip(seq, train) if t]  # noqa: E731
    intr, rvecs, tvecs, flex = warm
    fit = bundle_adjust(model, pick(obj), pick(px), intr, rvecs, tvecs, covariance=False, strict=False,
                        max_nfev=HELD_OUT_NFEV, flex_basis=None if basis is None else pick(basis), flex=flex)
    lens = Lens.from_intrinsics(model, fit.intrinsics, (1, 1))
    out = np.full(len(px), np.nan)
    for k, (o, p, t) in enumerate(zip(obj, px, train)):
        if not t:
            if fit.flex is not None:
                o = o + np.outer(basis[k] @ fit.flex, [0.0, 0.0, 1.0])
            pose = solve_pose(lens, o, p)
            out[k] = pose[2] if pose is not None and np.isfinite(pose[2]) else math.inf
    return out, fit


def _choose_smooth(base: Lens, layout, obj, px, basis, poses) -> tuple[float, np.ndarray]:
    """(smoothness weight px per normalized unit, base k1..k4) with the lowest mean of the k folds' held-out
    RMS over :data:`SMOOTH_REL` and :func:`_bases` (module docstring). Each fold's fit starts
    from its fit at the previous, smoother, weight (a continuation: on 20 views of the 130° bump lens 571
    evaluations in place of 665 from the base, 10 s CPU in place of 12, the same choice). A second base is
    first scored at the first's best weight and searched only when it beats it there (on opencv_left's 13
    photos both bases reach the same fits: 20 fold fits in place of 40). basis : per-view board-shape rows
    (each fold solves the board's shape, :func:`_held_out_rms`) or None (a flat board)."""
    k = min(SMOOTH_FOLDS, len(px))
    folds = [np.arange(len(px)) % k != f for f in range(k)]
    n = np.array([len(p) for p in px], np.float64)

    def score(model, cand, warm):
        if warm is None:
            intr = spline_start(base, model, px, cand.dist)
            warm = [(intr, np.asarray(poses[0])[t], np.asarray(poses[1])[t], None) for t in folds]
        scored = [_held_out_rms(model, obj, px, w, t, basis) for w, t in zip(warm, folds)]
        rms = [math.sqrt(np.sum(n[~t] * r[~t] ** 2) / np.sum(n[~t])) for (r, _), t in zip(scored, folds)]
        return float(np.mean(rms)), [(f.intrinsics, f.rvecs, f.tvecs, f.flex) for _, f in scored]

    best = None
    for cand in _bases(base, px):
        if best is not None and not score(splined_name(*layout, best[1]), cand, None)[0] < 0.99 * best[0]:
            continue
        mine, warm = None, None
        for s in SMOOTH_REL:  # the smoothest first: it keeps a tie
            value, warm = score(splined_name(*layout, s * base.fx), cand, warm)
            if mine is None or value < 0.99 * mine:
                mine = value
                if best is None or value < 0.99 * best[0]:
                    best = (value, s * base.fx, cand.dist)
            elif value > SMOOTH_STOP * mine:  # past the minimum: less smoothing only fits the noise more
                break
    return best[1], best[2]


def fit_splined(model: str, obj, px, image_size, start: Lens | None, rank_strict: bool = True, views=None,
                options: SolveOptions | None = None) -> BundleResult:
    """One fit of a splined model (module docstring): a BundleResult whose ``model`` names the layout.

    obj, px : lists of V (N_v, 3) board points and (N_v, 2) corners px. start : a Lens (any model) or None.
    views, options : the View list and the solve's options (None: the default); with views, the fit weights and
    rejects single corners as every solve does (step 6), else it is one bundle fit. Raises CalibrationError
    when the views do not determine a spline or the fit fails."""
    spec = get_model(model)
    solve_opts = None if views is None else (options or SolveOptions())
    rejecting = solve_opts is not None and solve_opts.reject_corners
    basis = None  # the board-shape rows the smoothness folds solve with (step 4), when the solve solves a shape
    if solve_opts is not None and solve_opts.flex != "off":
        basis = basis_of_views(views, solve_opts.pattern_size, mode_terms(solve_opts.flex))[0]

    def fit(name, intr, poses, keep):
        if solve_opts is None:
            return bundle_adjust(name, obj, px, intr, *poses, rank_strict=rank_strict, max_nfev=MAX_NFEV)
        return solve(name, views, obj, px, intr, poses, free=np.ones(len(intr), bool), rank_strict=rank_strict,
                     options=solve_opts, max_nfev=MAX_NFEV, inliers=keep)

    def flagged(name, intr, poses):  # the corners a capped solve keeps (None: all)
        if not rejecting:
            return None
        return solve(name, views, obj, px, intr, poses, free=np.ones(len(intr), bool), rank_strict=False,
                     options=dataclasses.replace(solve_opts, flex="off"), max_nfev=HELD_OUT_NFEV).inliers

    if start is not None and start.spec.FAMILY == spec.FAMILY and (model == FAMILY_NAME or start.model == model):
        poses = poses_from_rays(start, obj, px)
        if poses is None:
            raise CalibrationError(f"{start.model}: the start lens sees no board in front of it in some view")
        intr = start.intrinsics()
        return fit(start.model, intr, poses, flagged(start.model, intr, poses))
    if start is None or start.spec.FAMILY == spec.FAMILY:
        if model == FAMILY_NAME and len(px) < MIN_VIEWS:  # refuse before the equidistant fit
            raise CalibrationError(f"{FAMILY_NAME}: needs at least {MIN_VIEWS} views covering the image, got {len(px)}")
        every = np.ones(4 + get_model("equidistant").n_coeffs, bool)
        intr, poses = fisheye_start(obj, px, image_size, every, "equidistant")
        warm = bundle_adjust("equidistant", obj, px, intr, *poses, covariance=False, strict=False)
        start = Lens.from_intrinsics("equidistant", warm.intrinsics, image_size)
    base = Lens(start.model, start.K, start.dist, image_size)
    poses = poses_from_rays(base, obj, px)
    if poses is None:
        raise CalibrationError(f"{model}: the start lens sees no board in front of it in some view")
    layout = choose_layout(base, px, image_size, len(px)) if model == FAMILY_NAME else (spec.nx, spec.ny, spec.fov_deg)
    clean = splined_name(*layout, CLEAN_SMOOTH_REL * base.fx) if model == FAMILY_NAME else model
    keep = flagged(clean, spline_start(base, clean, px), poses)
    if model == FAMILY_NAME:
        smooth, k = _choose_smooth(base, layout, *_kept(keep, obj, px, basis), poses)
        model = splined_name(*layout, smooth)
        return fit(model, spline_start(base, model, px, k), poses, keep)
    bases = _bases(base, px)
    if len(bases) == 1:
        return fit(model, spline_start(base, model, px, bases[0].dist), poses, keep)
    # a concrete layout: the candidate base whose fit ends lower (each capped as a fold's), then its solve
    fits = [bundle_adjust(model, obj, px, spline_start(base, model, px, b.dist), *poses, covariance=False,
                          strict=False, max_nfev=HELD_OUT_NFEV, inliers=keep) for b in bases]
    best = min(fits, key=lambda f: f.cost)
    return fit(model, best.intrinsics, (best.rvecs, best.tvecs), keep)


def _kept(keep, obj, px, basis=None) -> tuple[list, list, list | None]:
    """(obj, px, basis) of each view without the corners ``keep`` ((N,) bool over all views' corners, or None)
    drops; basis: per-view (N_v, K) board-shape rows or None."""
    if keep is None:
        return obj, px, basis
    masks = np.split(np.asarray(keep, bool), np.cumsum([len(p) for p in px])[:-1])
    drop = lambda seq: [np.asarray(a)[m] for a, m in zip(seq, masks)]  # noqa: E731
    return drop(obj), drop(px), None if basis is None else drop(basis)
