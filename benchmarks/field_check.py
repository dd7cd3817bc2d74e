"""How often the field check (``aicalib_tf.calib.check``) flags a changed and an unchanged camera.

Each trial calibrates a camera from 20 synthetic views with Gaussian corner noise σ px per axis
(``tests/calib/synthetic.py``: a 9x6 board at random poses, partial boards allowed; the lens
model forced to the truth's), then checks 15 new views (new poses, new noise) seen by

* the same camera (``same``: a flag is a false alarm),
* fx × 1.01 (``fx+1%``), fx and fy × 1.01 (``f+1%``, a refocus),
* the principal point moved 3 px in a random direction (``pp 3px``).

It prints, per lens and σ, the fraction flagged by the check (both tests at level α each), by
its drift test alone, by its residual test alone, and by a max-|z| drift test (Bonferroni over
fx, fy, cx, cy at the same α) for comparison, with the median drift σ of fx and cx.

    .venv/bin/python benchmarks/field_check.py [--trials 200] [--noise 0.1 0.2 0.3] [--alpha 0.01]
    .venv/bin/python benchmarks/field_check.py --photos tests/data/opencv_left --splits 100

``--photos``: real photos instead. The CNN detects a 9x6 board in each; each split calibrates
(plumb_bob) from a random 7 and checks the other 6, as detected (``same``; also with κ forced to 1,
the formal covariance alone) and with their corners moved as the changed cameras above would
move them (fx scaled about the principal point, or every corner shifted 3 px). It prints how
often each is flagged and the median κ.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from statistics import NormalDist

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aicalib_tf.calib.check import check_calibration  # noqa: E402
from aicalib_tf.calib.fit import CalibrationError, calibrate_camera  # noqa: E402
from aicalib_tf.geometry import lens as L  # noqa: E402
from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views  # noqa: E402

LENSES = {
    "pinhole 640x480": (L.Lens("plumb_bob", [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]],
                               [-0.25, 0.08, 0.001, -0.0005, 0.0], (640, 480)), (0.35, 0.6)),
    "fisheye185 1280x960": (L.Lens("equidistant", [[288.0, 0, 641.5], [0, 287.4, 478.2], [0, 0, 1]],
                                   [0.02, -0.01, 0.004, -0.001], (1280, 960)), (0.15, 0.4)),
}
CHANGES = ("same", "fx+1%", "f+1%", "pp 3px")


def changed(lens: L.Lens, change: str, rng: np.random.Generator) -> L.Lens:
    """The lens after ``change`` (one of :data:`CHANGES`)."""
    K = lens.K.copy()
    if change == "fx+1%":
        K[0, 0] *= 1.01
    elif change == "f+1%":
        K[0, 0] *= 1.01
        K[1, 1] *= 1.01
    elif change == "pp 3px":
        a = rng.uniform(0, 2 * np.pi)
        K[0, 2] += 3 * np.cos(a)
        K[1, 2] += 3 * np.sin(a)
    return L.Lens(lens.model, K, lens.dist, lens.image_size)


def trial(lens, distance, noise, seed, alpha, z_limit):
    """{change: (flagged, drift flagged, residual flagged, max-|z| flagged, drift σ (4,))} of one trial."""
    rng = np.random.default_rng(seed)
    views = synthetic_views(lens, 20, noise, seed=int(rng.integers(1 << 31)), distance=distance)
    cal = calibrate_camera(views, PATTERN, SQUARE, lens.image_size, model=lens.model)
    out = {}
    for change in CHANGES:
        new = synthetic_views(changed(lens, change, rng), 15, noise, seed=int(rng.integers(1 << 31)),
                              distance=distance)
        r = check_calibration(cal, new, alpha=alpha)
        zmax = float(np.max(np.abs(r.drift / r.drift_std)))
        out[change] = (not r.holds, r.drift_p < alpha, r.residual_p < alpha, zmax > z_limit, r.drift_std)
    return out


def _moved_corners(views, change: str, centre, rng) -> list:
    """The views' corners as the changed camera would see them: fx (and fy) scaled by 1.01 about
    ``centre`` (x, y) px, or every corner moved 3 px in a random direction (a principal-point shift)."""
    from aicalib_tf.calib.fit import View

    c = np.asarray(centre, np.float64)
    if change == "same":
        return views
    if change == "pp 3px":
        a = rng.uniform(0, 2 * np.pi)
        move = lambda p: p + 3 * np.array([np.cos(a), np.sin(a)])  # noqa: E731
    else:
        s = np.array([1.01, 1.01 if change == "f+1%" else 1.0])
        move = lambda p: c + (p - c) * s  # noqa: E731
    return [View(v.name, move(v.corners), v.ids, v.relative) for v in views]


def photo_splits(folder: str, splits: int, alpha: float) -> None:
    """Checks on real photos (module docstring)."""
    from aicalib_tf.calib import check as C
    from aicalib_tf.calib.fit import View
    from aicalib_tf.calib.workflow import make_detector
    from aicalib_tf.io import load_image

    detect = make_detector("cnn", PATTERN)
    files = sorted(Path(folder).glob("*.jpg")) + sorted(Path(folder).glob("*.png"))
    views = [View(f.name, *hit) for f in files if (hit := detect(load_image(f))) is not None]
    size = load_image(files[0]).shape[::-1]
    full = calibrate_camera(views, PATTERN, 25.0, size, model="plumb_bob")
    inflation = C._view_inflation
    rows = {c: [] for c in CHANGES}
    formal, kappas = [], []
    for t in range(splits):
        rng = np.random.default_rng(t)
        idx = rng.permutation(len(views))
        a, b = [views[i] for i in idx[:7]], [views[i] for i in idx[7:]]
        cal = calibrate_camera(a, PATTERN, 25.0, size, model="plumb_bob", reject_outliers=False)
        for change in CHANGES:
            r = check_calibration(cal, _moved_corners(b, change, (full.cx, full.cy), rng), alpha=alpha)
            rows[change].append((not r.holds, r.drift_p < alpha, r.residual_p < alpha))
            if change == "same":
                kappas.append(r.inflation)
        C._view_inflation = lambda *args: 1.0
        try:
            r = check_calibration(cal, b, alpha=alpha)
        finally:
            C._view_inflation = inflation
        formal.append((not r.holds, r.drift_p < alpha, r.residual_p < alpha))
    print(f"{folder}: {len(views)} views, {splits} splits 7/{len(views) - 7}, alpha {alpha} per test; "
          f"median κ {np.median(kappas):.2f} (10-90%: {np.percentile(kappas, 10):.2f}-{np.percentile(kappas, 90):.2f})")
    for change in CHANGES:
        f = np.mean(rows[change], axis=0)
        print(f"  {change}: flagged {f[0]:.3f} (drift {f[1]:.3f}, residual {f[2]:.3f})")
    g = np.mean(formal, axis=0)
    print(f"  same, κ = 1 (formal covariance): flagged {g[0]:.3f} (drift {g[1]:.3f}, residual {g[2]:.3f})")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trials", type=int, default=200)
    ap.add_argument("--noise", type=float, nargs="+", default=[0.1, 0.2, 0.3], help="corner noise σ px per axis")
    ap.add_argument("--alpha", type=float, default=0.01)
    ap.add_argument("--lens", nargs="+", default=list(LENSES), choices=list(LENSES))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--photos", default=None, help="a folder of real 9x6 photos of one camera (unchanged-camera splits)")
    ap.add_argument("--splits", type=int, default=100)
    args = ap.parse_args(argv)
    if args.photos:
        photo_splits(args.photos, args.splits, args.alpha)
        return 0
    z_limit = NormalDist().inv_cdf(1 - args.alpha / 8)  # two-sided, 4 parameters
    print(f"alpha {args.alpha} per test; max-|z| limit {z_limit:.3f}; {args.trials} trials per row")
    print("lens | σ px | change | flagged | drift test | residual test | max-|z| | median σ(Δfx) | median σ(Δcx)")
    for name in args.lens:
        lens, distance = LENSES[name]
        for noise in args.noise:
            t0 = time.perf_counter()
            rows = {c: [] for c in CHANGES}
            failed = 0
            for t in range(args.trials):
                try:
                    res = trial(lens, distance, noise, args.seed * 1_000_003 + 7919 * t + int(noise * 1000), args.alpha,
                                z_limit)
                except CalibrationError:
                    failed += 1
                    continue
                for c in CHANGES:
                    rows[c].append(res[c])
            for c in CHANGES:
                a = rows[c]
                frac = [np.mean([x[k] for x in a]) for k in range(4)]
                sd = np.median([x[4] for x in a], axis=0)
                print(f"{name} | {noise} | {c} | {frac[0]:.3f} | {frac[1]:.3f} | {frac[2]:.3f} | {frac[3]:.3f} | "
                      f"{sd[0]:.2f} | {sd[2]:.2f}")
            print(f"# {name} σ {noise}: {len(rows['same'])} trials ({failed} failed to calibrate), "
                  f"{time.perf_counter() - t0:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
