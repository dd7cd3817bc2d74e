"""The splined lens model against the parametric ones: held-out error on lenses no parametric model holds.

    .venv/bin/python benchmarks/splined_model.py [--views 20] [--noise 0.02] [--auto-from N] [--scenes ...]
        [--halves SET ...] [--splits 2] [--real ...] [--timing 20 30 40] [--choice 8 12 16 20 --seeds 5 6]
        [--flex 12 20 --seeds 5 6]

Synthetic scenes: a lens that none of the parametric models holds exactly (a wide rational lens or a
~190° Kannala-Brandt fisheye, each with a local bump of 0.6 px in the image: a lens element's flaw), and
the fisheye without its bump (equidistant holds it: ``auto`` should not choose the spline),
``--views`` boards of 9x6 corners with ``--noise`` px (1σ per axis). Each model is fitted to the even
views; the odd views are posed with those intrinsics held fixed and their RMS is the held-out error.
The projection error is against the true lens over the corners of every view (a rotation fitted
out), px. Then ``calibrate_camera(model="auto")`` on all views shows what the model choice keeps.

``--auto-from N``: that ``auto`` run tries the spline from N views (the library's threshold otherwise).

``--timing N ...``: the spline's fit alone (the family's own layout and smoothness) on N views of the first
``--scenes`` scene: CPU seconds, those spent building the normal equations (:func:`aicalib_tf.calib.lm.reduce_blocks`),
the layout chosen and the projection error.

``--choice N ...``: ``auto`` with the spline tried from 6 views (``--auto-from``, default 6) on N views of each
``--scenes`` scene per ``--seeds`` seed: what it chose, that model's projection error, and, when it chose the
spline, the parametric model the choice keeps without it with its projection error: whether the held-out error
picks the spline only where it truly wins.

``--flex N ...``: the spline forced on N views of each ``--scenes`` scene per ``--seeds`` seed, the board flat
and bent by ``benchmarks/board_shape.py``'s ``full`` shape (all seven terms), each fitted with the board's shape
solved (``flex="auto"``: the keep rule of :mod:`aicalib_tf.calib.flex_check`) and taken flat: the shape
recovered (RMS out of the board's plane, worst term's error in its standard errors), the projection error
of each, their CPU seconds and the fit's note on the shape.

``--halves SET ...``: real photos (``opencv_left``, ``udacity_lane_cal``, ``ocam_fisheye`` in
``../shared/data``; ocam has no licence: read in place) detected once each as ``real_split_noise.py`` does
(the calibrate command's detector), split into halves (even/odd, first/second and ``--splits`` random
splits), each half calibrated three ways: the parametric model ``auto`` chooses on all the photos, the
spline forced, and ``auto`` with the spline tried from :data:`~aicalib_tf.calib.splined_fit.MIN_VIEWS`
views. Printed per split: the halves' projection difference (median px over the covered cells, rotation
fitted) of each, what the third chose in each half, and its time.

``--real``: the calibration workflow with ``--model auto`` on ``tests/data/opencv_left`` (13 photos,
9x6) and ``../shared/data/ocam_fisheye`` (15 photos of a ~185° fisheye, 8x6; no licence: read in
place, never copied), printing the model-choice table (the spline's row included) and the choice.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from aicalib_tf.calib.bundle import CalibrationError, solve_pose  # noqa: E402
from aicalib_tf.calib.fit import View, calibrate_camera, fit_views  # noqa: E402
from aicalib_tf.calib.splined_fit import MIN_VIEWS  # noqa: E402
from aicalib_tf.geometry import lens as L  # noqa: E402
from aicalib_tf.geometry.board_shape import SHAPE_TERMS, out_of_plane_rms, shaped_points  # noqa: E402
from aicalib_tf.geometry.pattern import board_points  # noqa: E402
from aicalib_tf.geometry.pose import best_rotation  # noqa: E402

PATTERN, SQUARE = (9, 6), 0.04
REAL = {"opencv_left": (ROOT / "tests/data/opencv_left", "9x6", "25mm"),
        "ocam_fisheye": (ROOT.parent / "shared/data/ocam_fisheye", "8x6", "32.5mm")}


class BumpLens:
    """A lens plus a smooth local displacement: ``amp`` px times a Gaussian of width ``sigma`` px at ``at``."""

    def __init__(self, lens: L.Lens, at, amp=(0.6, -0.4), sigma=60.0):
        self.lens, self.at, self.amp, self.sigma = lens, np.asarray(at, float), np.asarray(amp, float), sigma
        self.image_size = lens.image_size

    def project(self, P):
        q = self.lens.project(P)
        g = np.exp(-np.sum((q - self.at) ** 2, axis=-1) / (2 * self.sigma ** 2))
        return q + g[..., None] * self.amp

    def unproject(self, q):  # only places boards: the base lens's rays are close enough
        return self.lens.unproject(q)


SCENES = {
    "rational 130° + bump": BumpLens(L.Lens("rational_polynomial", [[330.0, 0, 322.0], [0, 331.0, 243.0], [0, 0, 1]],
                                            [0.35, 0.05, 1e-3, -8e-4, 0.0, 0.72, 0.14, 0.01], (640, 480)), (470, 150)),
    "KB 190° + bump": BumpLens(L.Lens("equidistant", [[300.0, 0, 641.0], [0, 300.5, 479.0], [0, 0, 1]],
                                      [0.03, -0.012, 0.004, -0.0008], (1280, 960)), (900, 330)),
    "KB 190°": BumpLens(L.Lens("equidistant", [[300.0, 0, 641.0], [0, 300.5, 479.0], [0, 0, 1]],
                               [0.03, -0.012, 0.004, -0.0008], (1280, 960)), (900, 330), amp=(0.0, 0.0)),
}


def render(truth, n, noise, rng, shape=None):
    """``n`` views of a 9x6 board seen by ``truth`` (corners inside the image, at least 20); shape : the board's
    (7,) shape terms, squares (:mod:`aicalib_tf.geometry.board_shape`), or None (flat)."""
    cols, rows = PATTERN
    ids = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), -1).reshape(-1, 2)
    X = board_points(ids, SQUARE) if shape is None else shaped_points(board_points(ids, SQUARE), PATTERN, shape, SQUARE)
    X = X - [(cols - 1) * SQUARE / 2, (rows - 1) * SQUARE / 2, 0]
    w, h = truth.image_size
    views = []
    while len(views) < n:
        ray = truth.unproject(rng.uniform([0.08 * w, 0.08 * h], [0.92 * w, 0.92 * h]))
        if not np.isfinite(ray).all() or ray[2] < 0.2:
            continue
        t = ray / np.linalg.norm(ray) * rng.uniform(0.25, 0.45)
        R = Rotation.from_euler("xyz", rng.uniform(-40, 40, 3) * [1, 1, 0.5], degrees=True).as_matrix()
        uv = truth.project(X @ R.T + t)
        ok = np.isfinite(uv).all(1) & (uv[:, 0] > 0) & (uv[:, 0] < w - 1) & (uv[:, 1] > 0) & (uv[:, 1] < h - 1)
        if ok.sum() >= 20:
            views.append(View(f"v{len(views):02d}", uv[ok] + noise * rng.standard_normal((int(ok.sum()), 2)), ids[ok]))
    return views


def held_out(lens, views) -> float:
    """px: RMS of the views posed with ``lens`` held fixed."""
    sq, n = 0.0, 0
    for v in views:
        pose = solve_pose(lens, board_points(v.ids, SQUARE), v.corners)
        if pose is None:
            return float("nan")
        sq, n = sq + pose[2] ** 2 * len(v.ids), n + len(v.ids)
    return float(np.sqrt(sq / n))


def projection_error(lens, truth, views) -> tuple[float, float]:
    """(median, p95) px: ``lens`` against the truth over every view's corners' rays, a rotation fitted out."""
    px = np.concatenate([v.corners for v in views])
    rays = truth.unproject(px)
    rays = rays[np.isfinite(rays).all(axis=1)]
    want = truth.project(rays)
    R = best_rotation(lens, rays, want)
    err = np.linalg.norm(lens.project(rays @ R.T) - want, axis=1)
    return float(np.nanmedian(err)), float(np.nanpercentile(err, 95))


def run_scene(name, truth, n, noise, seed, auto_from=None) -> list[str]:
    views = render(truth, n, noise, np.random.default_rng(seed))
    train, test = views[0::2], views[1::2]
    out = [f"## {name}: {n} views, noise {noise} px; fit on {len(train)}, held out {len(test)}",
           "| model | params | in-sample RMS px | held-out RMS px | projection error median / p95 px | s |",
           "|---|---|---|---|---|---|"]
    for model in ("plumb_bob", "rational_polynomial", "thin_prism", "equidistant", "ds", "eucm", "splined_equidistant"):
        t = time.time()
        try:
            cal = fit_views(train, PATTERN, SQUARE, truth.image_size, model)
        except (CalibrationError, ValueError) as exc:
            out.append(f"| {model} | - | - | - | {str(exc)[:70]} | {time.time() - t:.0f} |")
            continue
        med, p95 = projection_error(cal.lens, truth, views)
        label = model if model == cal.model else f"{model} ({cal.model.split('_', 2)[2]})"
        out.append(f"| {label} | {4 + cal.dist.size} | {cal.rms:.4f} | {held_out(cal.lens, test):.4f} | "
                   f"{med:.3f} / {p95:.3f} | {time.time() - t:.0f} |")
    t = time.time()
    with auto_spline_from(auto_from):
        cal = calibrate_camera(views, PATTERN, SQUARE, truth.image_size)
    rows = ", ".join(f"{r['model']} {r['cv_rms']:.4f}" for r in cal.model_table if np.isfinite(r["cv_rms"]))
    med, p95 = projection_error(cal.lens, truth, views)
    out.append(f"\nauto on all {n} views: **{cal.model}** ({time.time() - t:.0f} s; projection error {med:.3f} / "
               f"{p95:.3f} px); held-out RMS by model: {rows}")
    return out


def run_timing(name, truth, counts, noise, seed) -> list[str]:
    """The spline fit's CPU time on ``counts`` views each (module docstring, ``--timing``)."""
    from aicalib_tf.calib import lm

    spent, keep = [0.0], lm.reduce_blocks

    def counted(*args):
        t = time.process_time()
        try:
            return keep(*args)
        finally:
            spent[0] += time.process_time() - t

    out = [f"## {name}: the spline's fit, noise {noise} px", "| views | layout | CPU s | reduce_blocks CPU s (share) "
           "| projection error median / p95 px |", "|---|---|---|---|---|"]
    lm.reduce_blocks = counted
    try:
        for n in counts:
            views = render(truth, n, noise, np.random.default_rng(seed))
            spent[0], t = 0.0, time.process_time()
            cal = fit_views(views, PATTERN, SQUARE, truth.image_size, "splined_equidistant")
            cpu = time.process_time() - t
            med, p95 = projection_error(cal.lens, truth, views)
            out.append(f"| {n} | {cal.model.split('_', 2)[2]} | {cpu:.1f} | {spent[0]:.1f} ({100 * spent[0] / cpu:.0f}%) "
                       f"| {med:.3f} / {p95:.3f} |")
            print(out[-1], flush=True)
    finally:
        lm.reduce_blocks = keep
    return out


def run_choice(name, truth, counts, noise, seeds, auto_from) -> list[str]:
    """``auto`` from ``auto_from`` views against the truth (module docstring, ``--choice``)."""
    from aicalib_tf.calib.select import choose

    out = [f"## {name}: auto with the spline tried from {auto_from} views, noise {noise} px",
           "| views | seed | chosen | projection error median / p95 px | without the spline | its error | CPU s |",
           "|---|---|---|---|---|---|---|"]
    for n in counts:
        for seed in seeds:
            views = render(truth, n, noise, np.random.default_rng(seed))
            t = time.process_time()
            with auto_spline_from(auto_from):
                cal = calibrate_camera(views, PATTERN, SQUARE, truth.image_size)
            cpu = time.process_time() - t
            med, p95 = projection_error(cal.lens, truth, views)
            alt, alt_err = "-", "-"
            if cal.model.startswith("splined"):
                rows = [dict(r) for r in cal.model_table if not r["model"].startswith("splined")]
                alt = choose(rows)
                other = fit_views(views, PATTERN, SQUARE, truth.image_size, alt)
                alt_err = "{:.3f} / {:.3f}".format(*projection_error(other.lens, truth, views))
            out.append(f"| {n} | {seed} | {cal.model.split('_nx')[0]} | {med:.3f} / {p95:.3f} | {alt} | {alt_err} "
                       f"| {cpu:.0f} |")
            print(out[-1], flush=True)
    return out


def run_flex(name, truth, counts, noise, seeds) -> list[str]:
    """The spline forced on a bent board (module docstring, ``--flex``): per board, view count and seed the
    board flat (``flex="off"``) and solved (``flex="auto"``)."""
    from board_shape import SHAPES

    out = [f"## {name}: the spline forced, board shape solved (flex auto) or taken flat, noise {noise} px",
           "| board | views | seed | out of plane true / solved (squares) | worst term error / SE | projection error "
           "median / p95 px, auto | flat | CPU s auto / flat | note |", "|---|---|---|---|---|---|---|---|---|"]
    for board in ("flat", "full"):
        true = np.asarray(SHAPES[board], np.float64)
        for n in counts:
            for seed in seeds:
                views = render(truth, n, noise, np.random.default_rng(seed), true)
                cals, cpu = {}, {}
                for mode in ("auto", "off"):
                    t = time.process_time()
                    cals[mode] = fit_views(views, PATTERN, SQUARE, truth.image_size, "splined_equidistant", flex=mode)
                    cpu[mode] = time.process_time() - t
                cal = cals["auto"]
                w = np.zeros(len(SHAPE_TERMS)) if cal.flex is None else np.pad(cal.flex, (0, len(SHAPE_TERMS) - len(cal.flex)))
                se = (np.full(len(w), np.nan) if cal.flex is None
                      else np.sqrt(np.diag(cal.flex_covariance))[:len(w)])
                worst = "-" if cal.flex is None else f"{np.nanmax(np.abs(w - true) / se):.2f}"
                oop = [out_of_plane_rms(x, np.zeros((len(x), len(x))), PATTERN)[0] for x in (true, w)]
                errs = ["{:.3f} / {:.3f}".format(*projection_error(cals[m].lens, truth, views)) for m in ("auto", "off")]
                out.append(f"| {board} | {n} | {seed} | {oop[0]:.4f} / {oop[1]:.4f} | {worst} | {errs[0]} | {errs[1]} | "
                           f"{cpu['auto']:.0f} / {cpu['off']:.0f} | {cal.flex_note[:70] or 'every term kept'} |")
                print(out[-1], flush=True)
    return out


def run_real(name) -> list[str]:
    folder, pattern, square = REAL[name]
    with tempfile.TemporaryDirectory() as tmp:
        t = time.time()
        cmd = [sys.executable, "-m", "aicalib_tf.calibrate", str(folder / "*.jpg"), "--pattern", pattern,
               "--square", square, "--out", str(Path(tmp) / "cal")]
        proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
        if proc.returncode not in (0, 1):
            return [f"## {name}: calibrate exited {proc.returncode}: {proc.stderr.strip()[-300:]}"]
        data = json.loads((Path(tmp) / "cal" / "camera.json").read_text())
    out = [f"## {name} (real photos, calibrate --model auto, {time.time() - t:.0f} s): chosen **{data['model']}**",
           "| model | params | in-sample RMS px | held-out RMS px (± se) | note |", "|---|---|---|---|---|"]
    for r in data["model_table"]:
        cv = "-" if r.get("cv_rms") is None else f"{r['cv_rms']:.4f} ± {r['cv_se']:.4f}"
        rms = "-" if r.get("rms") is None else f"{r['rms']:.4f}"
        out.append(f"| {r['model']} | {r['n_params']} | {rms} | {cv} | {r.get('note', '')[:90]} |")
    return out


@contextlib.contextmanager
def auto_spline_from(n_views):
    """``auto`` tries the spline from ``n_views`` views (None: the library's threshold) inside the block."""
    from aicalib_tf.calib import select

    keep = select.AUTO_SPLINE_VIEWS
    select.AUTO_SPLINE_VIEWS = keep if n_views is None else n_views
    try:
        yield
    finally:
        select.AUTO_SPLINE_VIEWS = keep


def half_splits(n: int, n_random: int) -> dict:
    """{name: (first indices, second indices)}: even/odd, first/second and ``n_random`` random splits."""
    import real_split_noise as rsn

    out = {"evenodd": (list(range(0, n, 2)), list(range(1, n, 2))),
           "halves": (list(range((n + 1) // 2)), list(range((n + 1) // 2, n)))}
    out.update({f"random{s}": rsn.random_split(n, s) for s in range(n_random)})
    return out


def _half_cal(vs, cfg, size, circle, model):
    from aicalib_tf.calib import select

    if model != "auto_min":
        return calibrate_camera(vs, cfg[0], 1.0, size, model=model, image_circle=circle)
    with auto_spline_from(MIN_VIEWS):
        return calibrate_camera(vs, cfg[0], 1.0, size, image_circle=circle)


def _halves_diff(cals, grid) -> tuple[np.ndarray, np.ndarray]:
    """(diff (cells,) px, NaN where a half has no ray or projection; covered (cells,) bool): the halves'
    projection difference over the cells both halves' boards cover, rotation fitted there."""
    from aicalib_tf.calib.diff import board_coverage, projection_diff

    covered = np.zeros(grid[0] * grid[1], bool)
    for c in cals:
        covered |= board_coverage(c.lens, c.pattern_size, c.square_size, c.rvecs, c.tvecs, grid)
    d = projection_diff(cals[0].lens, cals[1].lens, grid=grid, covered=covered)
    return d["diff"], covered


def run_halves(name, n_random) -> list[str]:
    """The halves' differences of one real set (module docstring, ``--halves``): per column the median px over
    the covered cells where both halves image, with those cells' count; the last column the parametric
    model's median over the spline's cells (a spline has no ray beyond its knots)."""
    import real_repeatability as rr
    import real_split_noise as rsn

    cfg = rr.SETS[name]
    files, size, _ = rr.photos(ROOT.parent / "shared" / "data" / name)
    views, circle = rsn.detections(files, cfg[0])
    model = calibrate_camera([v for v in views if v is not None], cfg[0], 1.0, size, image_circle=circle).model
    out = [f"## {name}: {len(files)} photos, {sum(v is not None for v in views)} detected; auto on all: {model}",
           f"| split | views | {model} | splined_equidistant | auto from {MIN_VIEWS} views (choice) | {model} on the "
           "spline's cells | s |", "|---|---|---|---|---|---|---|"]
    for split, halves in half_splits(len(files), n_random).items():
        cells, diffs, t = [], {}, time.time()
        for m in (model, "splined_equidistant", "auto_min"):
            try:
                cals = [_half_cal([views[i] for i in h if views[i] is not None], cfg, size, circle, m) for h in halves]
                diffs[m] = _halves_diff(cals, rr.GRID)
            except (CalibrationError, ValueError) as exc:
                cells.append(f"refused: {str(exc)[:60]}")
                continue
            d, cov = diffs[m]
            chose = "" if m != "auto_min" else " (" + ", ".join(c.model.split("_nx")[0] for c in cals) + ")"
            cells.append(f"{np.nanmedian(d[cov]):.3f} ({np.isfinite(d[cov]).sum()}/{cov.sum()}){chose}")
        same = "-"
        if model in diffs and "splined_equidistant" in diffs:
            (dp, _), (ds, cov) = diffs[model], diffs["splined_equidistant"]
            same = f"{np.nanmedian(dp[cov & np.isfinite(ds)]):.3f}"
        n = "/".join(str(sum(views[i] is not None for i in h)) for h in halves)
        out.append(f"| {split} | {n} | " + " | ".join(cells) + f" | {same} | {time.time() - t:.0f} |")
        print(out[-1], flush=True)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--views", type=int, default=20)
    ap.add_argument("--noise", type=float, default=0.02)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--scenes", nargs="*", default=list(SCENES), help="synthetic scenes (bare: none)")
    ap.add_argument("--real", nargs="*", default=None, help="real sets to run (default none; bare: all)")
    ap.add_argument("--auto-from", type=int, default=None, help="views from which auto tries the spline "
                    "(default: the library's AUTO_SPLINE_VIEWS)")
    ap.add_argument("--halves", nargs="*", default=(), help="real sets whose halves to compare (default none)")
    ap.add_argument("--splits", type=int, default=2, help="random half-splits per --halves set")
    ap.add_argument("--timing", type=int, nargs="*", default=(), help="view counts of the spline fit's timing")
    ap.add_argument("--choice", type=int, nargs="*", default=(), help="view counts of the auto-choice check")
    ap.add_argument("--seeds", type=int, nargs="*", default=(5,), help="seeds of --choice and --flex")
    ap.add_argument("--flex", type=int, nargs="*", default=(), help="view counts of the bent-board check")
    args = ap.parse_args(argv)
    if args.choice:
        for name in args.scenes:
            print("\n".join(run_choice(name, SCENES[name], args.choice, args.noise, args.seeds, args.auto_from or MIN_VIEWS)),
                  "\n", flush=True)
        return 0
    if args.flex:
        for name in args.scenes:
            print("\n".join(run_flex(name, SCENES[name], args.flex, args.noise, args.seeds)), "\n", flush=True)
        return 0
    if args.timing:
        name = args.scenes[0]
        print("\n".join(run_timing(name, SCENES[name], args.timing, args.noise, args.seed)), "\n", flush=True)
        return 0
    for name in args.scenes:
        print("\n".join(run_scene(name, SCENES[name], args.views, args.noise, args.seed, args.auto_from)), "\n",
              flush=True)
    for name in args.halves:
        print("\n".join(run_halves(name, args.splits)), "\n", flush=True)
    for name in (REAL if args.real == [] else args.real or ()):
        print("\n".join(run_real(name)), "\n", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
