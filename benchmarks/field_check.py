"""How often the field check (``aicalib_tf.calib.check``) flags a changed and an unchanged camera
when the check footage differs from the calibration footage.

Three modes:

* ``--mode corners`` (default): corner-level simulation. Each trial calibrates a camera from 20
  views with Gaussian corner noise 0.15 px per axis (a 9x6 board, square 40 mm, at 0.4-0.8 m; the
  lens model forced to the truth's), then checks 15 new views under every condition of
  :data:`CONDITIONS` (what light, blur, distance and board size do to the corners: more noise,
  noise stretched along a per-view motion direction, an error field every corner of a view shares,
  boards nearer or farther, a board printed at another size with the same pattern), each seen by the same camera (``same``: a flag is a false
  alarm), by fx × 1.01 (``fx+1%``) and with the principal point moved 3 px in a random direction
  (``pp 3px``).
* ``--mode rendered``: the whole pipeline. ``data_gen.video`` renders a hand-held clip of a new
  camera per trial (the ``mild`` lens, 960x540 by default); 25 frames of its first 20 s go through
  the CNN detector and ``calibrate_camera`` (plumb_bob), 15 frames of the next 20 s are the check
  clip, rendered as filmed (``same``), with read noise 8 grey levels instead of 2 (``noise8``),
  with a 1/30 s shutter instead of 1/60 (``blur``, twice the motion blur), 1.7 stops darker
  (``dark``: the image × 0.3 plus read noise σ 2 again) or overexposed (``bright``: × 1.8, clipped),
  each JPEG-coded (quality 90). The changed cameras are the same frames warped: the image moved
  3 px (a principal-point shift) or stretched 1% in x about the true principal point (fx × 1.01
  with the same distortion).
* ``--mode photos --photos DIR``: real photos, each split calibrating from 7 and checking the rest
  (as detected and with their corners moved as the changed cameras would move them).

Printed per condition: the fraction flagged (either test at --alpha each), by the drift test and
by the lens test; the check footage's corner noise; the median smallest changes the check says it
detects 95% of the time (``det fx%``, ``det pp``); ``reachable``: in how many trials the check said
the change (1% of fx, 3 px) was within what it detects, and the fraction flagged among those.

    .venv/bin/python benchmarks/field_check.py --trials 60
    .venv/bin/python benchmarks/field_check.py --mode rendered --trials 40 --cache /tmp/field_check_corners
    .venv/bin/python benchmarks/field_check.py --mode photos --photos tests/data/opencv_left --splits 100
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aicalib_tf.calib.check import check_calibration  # noqa: E402
from aicalib_tf.calib.fit import CalibrationError, View, calibrate_camera  # noqa: E402
from aicalib_tf.geometry import lens as L  # noqa: E402
from aicalib_tf.geometry.pattern import board_points  # noqa: E402

PATTERN, SQUARE = (9, 6), 0.04
CHANGES = ("same", "fx+1%", "pp 3px")
LENSES = {
    "pinhole 1280x720": L.Lens("plumb_bob", [[1000.0, 0, 641.3], [0, 1000.0, 358.2], [0, 0, 1]],
                               [-0.05, 0.004, 0.0002, 0.0, 0.0], (1280, 720)),
    "fisheye 1280x960": L.Lens("equidistant", [[288.0, 0, 641.5], [0, 287.4, 478.2], [0, 0, 1]],
                               [0.02, -0.01, 0.004, -0.001], (1280, 960)),
}
BASE_DISTANCE = {"plumb_bob": (0.4, 0.8), "equidistant": (0.15, 0.4)}


@dataclass(frozen=True)
class Condition:
    """What the check clip does to the corners, relative to the calibration clip.

    noise : corner σ px per axis. motion : extra σ px along one random direction per view (motion
    blur). shared : RMS px of an error every corner of a view shares: a random quadratic field over
    the board, per view (what blur and lighting leave, which the view's pose does not absorb).
    distance : scale of the calibration's distance range. square : the board's square relative to
    the calibration's (the check still uses the calibration's square size)."""

    noise: float = 0.15
    motion: float = 0.0
    shared: float = 0.0
    distance: float = 1.0
    square: float = 1.0


CONDITIONS = {
    "same footage": Condition(),
    "noise x2": Condition(noise=0.3),
    "noise x4": Condition(noise=0.6),
    "motion blur": Condition(motion=0.5),
    "shared in view": Condition(shared=0.1),
    "dark (noise x3)": Condition(noise=0.45),
    "bright (noise x0.7)": Condition(noise=0.1),
    "near (x0.6)": Condition(distance=0.6),
    "far (x1.8)": Condition(distance=1.8),
    "board x1.5": Condition(square=1.5),
    "board x0.6": Condition(square=0.6),
    "dark + far": Condition(noise=0.45, distance=1.8),
}


# ----------------------------------------------------------------------------- corner-level simulation
def synthetic(lens, n, cond: Condition, rng, names="v") -> list[View]:
    """``n`` views of the board (partial where the image cuts it) under ``cond``."""
    cols, rows = PATTERN
    ids = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), -1).reshape(-1, 2)
    s = SQUARE * cond.square
    X = board_points(ids, s) - [(cols - 1) * s / 2, (rows - 1) * s / 2, 0]
    w, h = lens.image_size
    lo, hi = BASE_DISTANCE[lens.model]
    out = []
    while len(out) < n:
        q = rng.uniform([0.1 * w, 0.1 * h], [0.9 * w, 0.9 * h])
        ray = lens.unproject(q)
        t = ray / ray[2] * rng.uniform(lo * cond.distance, hi * cond.distance)
        R = Rotation.from_euler("xyz", rng.uniform(-40, 40, 3) * [1, 1, 0.5], degrees=True).as_matrix()
        uv = lens.project(X @ R.T + t)
        ok = np.all(np.isfinite(uv), 1) & (uv[:, 0] > 0) & (uv[:, 0] < w - 1) & (uv[:, 1] > 0) & (uv[:, 1] < h - 1)
        if ok.sum() < 20:
            continue
        k = int(ok.sum())
        a = rng.uniform(0, np.pi)
        err = cond.noise * rng.standard_normal((k, 2)) + np.outer(cond.motion * rng.standard_normal(k),
                                                                  [np.cos(a), np.sin(a)])
        if cond.shared:
            u = (ids[ok] - [(cols - 1) / 2, (rows - 1) / 2]) / [(cols - 1) / 2, (rows - 1) / 2]
            basis = np.stack([u[:, 0] ** 2 - 1 / 3, u[:, 0] * u[:, 1], u[:, 1] ** 2 - 1 / 3], 1) * 2.0
            err = err + cond.shared * basis @ rng.standard_normal((3, 2)) / np.sqrt(2)
        out.append(View(f"{names}{len(out):02d}", uv[ok] + err, ids[ok]))
    return out


def changed(lens: L.Lens, change: str, rng) -> L.Lens:
    """The lens after ``change`` (one of :data:`CHANGES`)."""
    K = lens.K.copy()
    if change == "fx+1%":
        K[0, 0] *= 1.01
    elif change == "pp 3px":
        a = rng.uniform(0, 2 * np.pi)
        K[0, 2] += 3 * np.cos(a)
        K[1, 2] += 3 * np.sin(a)
    return L.Lens(lens.model, K, lens.dist, lens.image_size)


def _row(r, alpha) -> tuple:
    return (not r.holds, r.drift_p < alpha, r.lens_p < alpha, r.noise_px, 100 * r.detectable_fx, r.detectable_pp)


def corner_trial(lens, conditions, seed, alpha) -> dict:
    """{(condition, change): row} of one trial (one calibration, every condition and change)."""
    rng = np.random.default_rng(seed)
    cal = calibrate_camera(synthetic(lens, 20, Condition(), rng, "c"), PATTERN, SQUARE, lens.image_size,
                           model=lens.model)
    out = {}
    for name in conditions:
        for change in CHANGES:
            views = synthetic(changed(lens, change, rng), 15, CONDITIONS[name], rng)
            out[name, change] = _row(check_calibration(cal, views, alpha=alpha), alpha)
    return out


# ----------------------------------------------------------------------------- rendered video
RENDERED = ("same", "noise8", "blur", "dark", "bright")


def _expose(gray: np.ndarray, condition: str, rng) -> np.ndarray:
    """The frame as the condition films it (dark, bright), JPEG-coded at quality 90."""
    img = gray.astype(np.float32)
    if condition == "dark":
        img = img * 0.3 + rng.normal(0.0, 2.0, img.shape)
    elif condition == "bright":
        img = img * 1.8
    img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 90])
    return cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)


def _warp(gray, change, K, angle):
    """The frame as the changed camera sees it: moved 3 px towards ``angle`` (rad), or x stretched 1% about cx."""
    if change == "same":
        return gray
    if change == "pp 3px":
        M = np.float64([[1, 0, 3 * np.cos(angle)], [0, 1, 3 * np.sin(angle)]])
    else:
        M = np.float64([[1.01, 0, -0.01 * K[0, 2]], [0, 1, 0]])
    h, w = gray.shape
    return cv2.warpAffine(gray, M, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def _save_views(path: Path, groups: dict) -> None:
    """{group: [View]} into one .npz (corners, ids, per-view counts, names, relative flags)."""
    arrays = {}
    for g, vs in groups.items():
        arrays[f"{g}/corners"] = np.concatenate([v.corners for v in vs]) if vs else np.zeros((0, 2))
        arrays[f"{g}/ids"] = np.concatenate([v.ids for v in vs]) if vs else np.zeros((0, 2), np.int64)
        arrays[f"{g}/counts"] = np.array([len(v.corners) for v in vs], np.int64)
        arrays[f"{g}/names"] = np.array([v.name for v in vs], dtype="U16")
        arrays[f"{g}/relative"] = np.array([v.relative for v in vs], bool)
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, **arrays)
    tmp.replace(path)


def _load_views(path: Path) -> dict:
    """The inverse of :func:`_save_views`."""
    with np.load(path, allow_pickle=False) as z:
        groups = {}
        for g in sorted({k.rsplit("/", 1)[0] for k in z.files}):
            cut = np.cumsum(z[f"{g}/counts"])[:-1]
            groups[g] = [View(str(n), c, i, bool(r)) for n, c, i, r in zip(
                z[f"{g}/names"], np.split(z[f"{g}/corners"], cut), np.split(z[f"{g}/ids"], cut), z[f"{g}/relative"])]
    return groups


def rendered_views(seed, size, detect) -> dict:
    """{"cal": views, "condition|change": views} of one rendered trial (module docstring)."""
    from data_gen.video import VideoConfig, make_scene, render_frame
    from aicalib_tf.io import load_image

    scene = make_scene(VideoConfig(out="-", seconds=40.0, size=size, seed=seed))
    rng = np.random.default_rng([seed, 5])

    def views(frames, prefix):
        out = []
        for k, gray in enumerate(frames):
            hit = detect(load_image(gray))
            if hit is not None:
                out.append(View(f"{prefix}{k:02d}", *hit, relative=detect.relative))
        return out

    cal_frames = [render_frame(scene, i)[0] for i in range(0, 600, 24)]
    out = {"cal": views([_expose(g, "same", rng) for g in cal_frames], "c")}
    K = scene.camera.K
    for cond in RENDERED:
        sc = scene if cond in ("same", "dark", "bright") else replace(
            scene, cfg=replace(scene.cfg, noise=8.0) if cond == "noise8" else replace(scene.cfg, shutter=1 / 30))
        frames = [_expose(render_frame(sc, i)[0], cond, rng) for i in range(600, 1200, 40)]
        for change in CHANGES:
            angle = rng.uniform(0, 2 * np.pi)  # one direction for the whole clip
            out[f"{cond}|{change}"] = views([_warp(g, change, K, angle) for g in frames], "v")
    return out, scene.board.square_size


def rendered_trial(seed, size, detect, alpha, cache: Path | None = None) -> dict:
    """{(condition, change): row} of one rendered trial; with ``cache`` the detected corners are
    stored there and reused (the check alone is measured again)."""
    path = cache / f"rendered_{size[0]}x{size[1]}_{seed}.npz" if cache else None
    if path is not None and path.exists():
        groups = _load_views(path)
        square = float(np.load(path.with_suffix(".square.npy")))
    else:
        groups, square = rendered_views(seed, size, detect)
        if path is not None:
            np.save(path.with_suffix(".square.npy"), np.float64(square))
            _save_views(path, groups)
    cal = calibrate_camera(groups["cal"], PATTERN, square, size, model="plumb_bob")
    out = {}
    for cond in RENDERED:
        for change in CHANGES:
            try:
                r = check_calibration(cal, groups[f"{cond}|{change}"], alpha=alpha)
            except CalibrationError:
                continue
            out[cond, change] = _row(r, alpha)
    return out


# ----------------------------------------------------------------------------- real photos
def _moved_corners(views, change: str, centre, rng) -> list:
    """The views' corners as the changed camera would see them (fx × 1.01 about ``centre``, or 3 px moved)."""
    c = np.asarray(centre, np.float64)
    if change == "same":
        return views
    if change == "pp 3px":
        a = rng.uniform(0, 2 * np.pi)
        return [View(v.name, v.corners + 3 * np.array([np.cos(a), np.sin(a)]), v.ids, v.relative) for v in views]
    return [View(v.name, c + (v.corners - c) * [1.01, 1.0], v.ids, v.relative) for v in views]


def photo_splits(folder: str, splits: int, alpha: float) -> None:
    """Checks on real photos (module docstring)."""
    from aicalib_tf.calib.workflow import make_detector
    from aicalib_tf.io import load_image

    detect = make_detector("cnn", PATTERN)
    files = sorted(Path(folder).glob("*.jpg")) + sorted(Path(folder).glob("*.png"))
    views = [View(f.name, *hit) for f in files if (hit := detect(load_image(f))) is not None]
    size = load_image(files[0]).shape[::-1]
    full = calibrate_camera(views, PATTERN, 25.0, size, model="plumb_bob")
    rows = {c: [] for c in CHANGES}
    for t in range(splits):
        rng = np.random.default_rng(t)
        idx = rng.permutation(len(views))
        a, b = [views[i] for i in idx[:7]], [views[i] for i in idx[7:]]
        cal = calibrate_camera(a, PATTERN, 25.0, size, model="plumb_bob", reject_outliers=False)
        for change in CHANGES:
            r = check_calibration(cal, _moved_corners(b, change, (full.cx, full.cy), rng), alpha=alpha)
            rows[change].append(_row(r, alpha))
    print(f"{folder}: {len(views)} views, {splits} splits 7/{len(views) - 7}, alpha {alpha} per test")
    _print({("photos", c): v for c, v in rows.items()})


# ----------------------------------------------------------------------------- report
def _print(rows: dict) -> None:
    """One line per (condition, change): flagged, drift, lens, noise, detectable, reachable."""
    for (cond, change), a in rows.items():
        if not a:
            continue
        m = np.mean([x[:3] for x in a], axis=0)
        noise, dfx, dpp = (float(np.median([x[k] for x in a])) for k in (3, 4, 5))
        reach = ""
        if change != "same":  # the trials whose check says the change is within reach, and how many of those flag it
            ok = [x for x in a if (x[4] <= 1.0 if change == "fx+1%" else x[5] <= 3.0)]
            reach = f"{len(ok)}/{len(a)}" + (f", flagged {np.mean([x[0] for x in ok]):.3f}" if ok else "")
        print(f"{cond} | {change} | {len(a)} | {m[0]:.3f} | {m[1]:.3f} | {m[2]:.3f} | {noise:.3f} | {dfx:.2f} | "
              f"{dpp:.1f} | {reach}", flush=True)


def run(trial, n: int, keys, label=lambda k: k, every: int = 0) -> dict:
    """{key: rows} over ``n`` trials; every ``every`` trials the table so far is printed."""
    rows = {k: [] for k in keys}
    failed = 0
    for t in range(n):
        try:
            res = trial(t)
        except CalibrationError:
            failed += 1
            continue
        for k, v in res.items():
            rows[k].append(v)
        if every and (t + 1) % every == 0 and t + 1 < n:
            print(f"# after {t + 1} trials", flush=True)
            _print({label(k): v for k, v in rows.items()})
    if failed:
        print(f"# {failed} trials failed to calibrate (the calibration, not the check)")
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--mode", choices=("corners", "rendered", "photos"), default="corners")
    ap.add_argument("--trials", type=int, default=60)
    ap.add_argument("--alpha", type=float, default=0.01)
    ap.add_argument("--lens", nargs="+", default=list(LENSES), choices=list(LENSES))
    ap.add_argument("--conditions", nargs="+", default=list(CONDITIONS), choices=list(CONDITIONS))
    ap.add_argument("--size", default="960x540", help="rendered mode: frame size WxH")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--photos", default=None, help="photos mode: a folder of real 9x6 photos of one camera")
    ap.add_argument("--splits", type=int, default=100)
    ap.add_argument("--cache", default=None, help="rendered mode: a folder where the detected corners are kept and "
                    "reused (the check alone is measured again; empty it when the detector changes)")
    args = ap.parse_args(argv)
    print("condition | change | trials | flagged | drift test | lens test | noise px | det fx% | det pp px | reachable, flagged")
    if args.mode == "photos":
        photo_splits(args.photos, args.splits, args.alpha)
        return 0
    if args.mode == "rendered":
        from aicalib_tf.calib.workflow import make_detector

        size = tuple(int(v) for v in args.size.split("x"))
        detect = make_detector("cnn", PATTERN)
        t0 = time.perf_counter()
        label = lambda k: (f"rendered {args.size} {k[0]}", k[1])  # noqa: E731
        cache = Path(args.cache) if args.cache else None
        if cache:
            cache.mkdir(parents=True, exist_ok=True)
        rows = run(lambda t: rendered_trial(args.seed * 1000 + t, size, detect, args.alpha, cache), args.trials,
                   [(c, ch) for c in RENDERED for ch in CHANGES], label, every=5)
        _print({label(k): v for k, v in rows.items()})
        print(f"# {time.perf_counter() - t0:.0f} s")
        return 0
    for name in args.lens:
        lens = LENSES[name]
        t0 = time.perf_counter()
        rows = run(lambda t: corner_trial(lens, args.conditions, args.seed * 1_000_003 + 7919 * t, args.alpha),
                   args.trials, [(c, ch) for c in args.conditions for ch in CHANGES])
        _print({(f"{name} {c}", ch): v for (c, ch), v in rows.items()})
        print(f"# {name}: {time.perf_counter() - t0:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
