"""Predicted against measured corner error per condition: the detector's per-corner σ on rendered truth.

    python benchmarks/corner_sigma.py [--images 6] [--seeds own,2031,2032,2033] [--conditions named,sweeps] [--cache DIR]
    python benchmarks/corner_sigma.py --fit [--fit-on sweeps,named] [--leave-out]   # refit COEFFS, LOW, HIGH, FOREIGN
    python benchmarks/corner_sigma.py --calibrate [--views 20] [--repeats 3] [--as-rendered]   # calibration with and without σ

Renders the benchmark's conditions (:mod:`aicalib_tf.bench.conditions`) with each of ``--seeds``
(``own``: the condition's own seed, 21 named and 31 sweeps; the others, ``EVAL_SEEDS``, other scenes,
cameras, poses and noise that the model's fit never saw), ``--images`` renders a seed, detects each
board with the shipped model and matches every detected corner to the nearest visible true corner
(within ``WRONG_PX``; further ones are counted as gross and left out). Per condition it prints the
corners matched, the measured RMS error per axis, the RMS of the predicted σ
(:mod:`aicalib_tf.detect.corners.sigma`), their ratio over all its renders (target 0.8–1.25), the
lowest and highest ratio of one seed's renders, the ratio's spread over the condition's images
(:func:`ratio_interval`) and the rank correlation of |error| with σ among the condition's corners;
then, over all boards, whether σ spreads inside a board as the errors do (:func:`spread`).

``--fit`` renders the conditions of ``--fit-on`` with ``FIT_SEEDS`` (scenes of their own), fits the
model there (:func:`fit_table`) and reports with the fitted table on ``--seeds``' renders, which the fit
never saw, and in one line on the fit's own renders; paste the printed table into the module.
``--fit-on sweeps`` leaves the named conditions (shading, occluders, fisheyes, ...) out of the fit
altogether; ``--leave-out`` refits once per family of conditions (a sweep's levels, or one named
condition) without it and reports that family on ``--seeds``' renders: conditions as well as seeds
held out.

``--calibrate`` degrades the calibration sequences' views (:func:`aicalib_tf.bench.conditions.calibration_sequences`,
cameras 0–3) one by one with a blur and a noise drawn from ``MIXED`` (seeded per view), detects them
and calibrates each camera with its corners weighted by each rule of ``WEIGHTINGS`` (all equal; each
view's median σ; each corner's σ clipped to 0.5-2x the view's median; each corner's own σ; each
corner's σ, or its view's median, with the error the detector does not explain estimated from a first
fit: :mod:`aicalib_tf.calib.weights`), with the lens model the truth has (plumb_bob); it prints the
rotation-free errors against the true camera: fx %, the principal point and the mean projection
error over the area the boards covered.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from aicalib_tf.bench.conditions import PATTERN, condition_samples, select_conditions  # noqa: E402
from aicalib_tf.bench.metrics import WRONG_PX  # noqa: E402
from aicalib_tf.calib import weights  # noqa: E402
from aicalib_tf.detect.corners import sigma as cs  # noqa: E402
from aicalib_tf.detect.pipeline import detect_corners  # noqa: E402
from aicalib_tf.detect.pyramid import Frame  # noqa: E402
from aicalib_tf.io import read_image  # noqa: E402

FIT_SEEDS = (1031, 1032)  # scenes for fitting; the benchmark's own seeds are 21 (named) and 31 (sweeps)
EVAL_SEEDS = ("own", 2031, 2032, 2033)  # scenes reported on: the conditions' own seeds and three more
CLIP_PERCENTILES = (0.1, 99.9)  # the fitted range of each column (LOW, HIGH): the rare corners beside an object's
# edge lie beyond the 99th percentile of their asymmetry, and their σ should follow it there


def board_errors(image: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Detect the board in ``image``; its design columns (K, len(COLUMNS)), errors (K, 2) px and the gross count.

    truth : (M, 2) px, the visible true corners. Each detected corner is matched to the nearest of
    them; errors are detected − true for those within ``WRONG_PX``, the others counted as gross.
    """
    det = detect_corners(image, PATTERN)
    if not det.found or len(truth) == 0:
        return np.zeros((0, len(cs.COLUMNS))), np.zeros((0, 2)), 0
    frame = Frame(read_image(image))
    x = cs.board_design(frame, det.corners, det.ids, det.scores, frame.size)
    d = det.corners[:, None, :].astype(np.float64) - truth[None, :, :]
    near = np.argmin(np.einsum("nmk,nmk->nm", d, d), axis=1)
    err = d[np.arange(len(d)), near]
    ok = np.hypot(err[:, 0], err[:, 1]) <= WRONG_PX
    return x[ok], err[ok], int((~ok).sum())


def collect(conditions, images: int, seeds=("own",)) -> dict[str, dict[str, np.ndarray]]:
    """{condition: {"x": (K, len(COLUMNS)), "err": (K, 2) px, "image": (K,) int, "gross": ()}} over ``images`` renders
    of each of ``seeds`` ("own": the condition's own seed); "image" is 1000 · the seed's place in ``seeds`` + the
    render's index."""
    out = {}
    for cond in conditions:
        if not cond.has_board:
            continue
        xs, es, ims, gross = [np.zeros((0, len(cs.COLUMNS)))], [np.zeros((0, 2))], [np.zeros(0, int)], 0
        for k, seed in enumerate(seeds):
            for index, s in condition_samples(cond if seed == "own" else replace(cond, seed=int(seed)), images):
                x, e, g = board_errors(s.image, s.corners[s.visible] if len(s.corners) else s.corners)
                xs.append(x)
                es.append(e)
                ims.append(np.full(len(x), 1000 * k + index))
                gross += g
        out[cond.name] = {"x": np.concatenate(xs), "err": np.concatenate(es), "image": np.concatenate(ims),
                          "gross": np.array(gross)}
    return out


def fit_board(x: np.ndarray, offset: np.ndarray, errors: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """Coefficients (1 + k,) of log σ = c · [1, x] + offset that make each group's (image's) mean σ² agree
    with its mean squared error per axis, in the least-squares sense on their logarithms.

    x : (K, k) board columns, already clipped. offset : (K,) each corner's own part of log σ (fixed).
    errors : (K, 2) px. groups : (K,) int, the image of each corner.
    """
    from scipy.optimize import minimize

    a = np.c_[np.ones(len(x)), x]
    e2 = 0.5 * np.einsum("nk,nk->n", errors, errors)
    _, g = np.unique(groups, return_inverse=True)
    count = np.bincount(g).astype(np.float64)
    mean_e2 = np.maximum(np.bincount(g, e2) / count, 1e-12)

    def loss(c):
        s2 = np.exp(2 * (a @ c + offset))
        ms2 = np.bincount(g, s2) / count
        r = np.log(mean_e2) - np.log(ms2)
        d_ms2 = np.stack([np.bincount(g, 2 * s2 * a[:, j], len(count)) for j in range(a.shape[1])], axis=1) / count[:, None]
        return float(r @ r), -2 * (r / ms2) @ d_ms2

    c0 = np.zeros(a.shape[1])
    c0[0] = 0.5 * np.log(np.mean(e2))
    return minimize(loss, c0, jac=True, method="BFGS").x


def fit_corner(d: np.ndarray, errors: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """Coefficients (k,) of each corner's part b · d of log σ: the maximum likelihood of the errors (Gaussian,
    σ per axis) with a free scale per group (image), so only the order of σ inside an image is fitted.

    d : (K, k) corner columns (excess over the board's median), clipped. errors : (K, 2) px. groups : (K,).
    """
    from scipy.optimize import minimize

    e2 = 0.5 * np.einsum("nk,nk->n", errors, errors)
    _, g = np.unique(groups, return_inverse=True)
    count = np.bincount(g).astype(np.float64)

    def loss(b):
        t = d @ b
        u = e2 * np.exp(-2 * t)
        s2 = np.maximum(np.bincount(g, u, len(count)) / count, 1e-30)
        grad_s2 = -2 * np.stack([np.bincount(g, u * d[:, j], len(count)) for j in range(d.shape[1])], axis=1) / count[:, None]
        value = float(np.sum(count * np.log(s2)) + 2 * np.sum(t)) / len(t)
        grad = ((count / s2) @ grad_s2 + 2 * d.sum(axis=0)) / len(t)
        return value, grad

    return minimize(loss, np.zeros(d.shape[1]), jac=True, method="BFGS").x


def fit_foreign(s0: np.ndarray, amplitude: np.ndarray, errors: np.ndarray) -> float:
    """σ px per px of foreign edge amplitude: the maximum likelihood of the errors (Gaussian, σ per axis) with
    σ² = s0² + (k · amplitude)². s0 : (K,) px, the model's σ without it. amplitude : (K,) px. errors : (K, 2) px."""
    from scipy.optimize import minimize_scalar

    e2, b2, a2 = 0.5 * np.einsum("nk,nk->n", errors, errors), s0 * s0, amplitude * amplitude

    def loss(log_k):
        s2 = b2 + np.exp(2 * log_k) * a2
        return float(np.sum(np.log(s2) + e2 / s2))

    return float(np.exp(minimize_scalar(loss, bounds=(-12.0, 3.0), method="bounded").x))


def fit_table(train: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(coeffs, low, high, foreign) fitted on the collected conditions ``train`` (clip bounds: the
    ``CLIP_PERCENTILES``): first each corner's columns by :func:`fit_corner`, then the board's by :func:`fit_board`,
    then the foreign edge's σ per px of amplitude by :func:`fit_foreign`."""
    x = np.concatenate([v["x"] for v in train.values()])
    err = np.concatenate([v["err"] for v in train.values()])
    groups = np.concatenate([k * 100000 + v["image"] for k, v in enumerate(train.values())])
    x, amplitude = x[:, :cs.FOREIGN_COLUMN], x[:, cs.FOREIGN_COLUMN]
    low, high = np.percentile(x, CLIP_PERCENTILES[0], axis=0), np.percentile(x, CLIP_PERCENTILES[1], axis=0)
    xc = np.clip(x, low, high)
    nb = cs.BOARD_COLUMNS
    b = fit_corner(xc[:, nb:], err, groups)
    c = fit_board(xc[:, :nb], xc[:, nb:] @ b, err, groups)
    coeffs = np.r_[c, b]
    return coeffs, low, high, fit_foreign(np.exp(coeffs[0] + xc @ coeffs[1:]), amplitude, err)


def ratios_of(data: dict, table) -> dict[str, float]:
    """{condition: measured RMS error per axis / RMS σ over all its corners} (conditions with corners)."""
    out = {}
    for name, v in data.items():
        if len(v["x"]):
            sig = cs.sigma_from_design(v["x"], *table).astype(np.float64)
            out[name] = float(np.sqrt(np.mean(v["err"] ** 2)) / np.sqrt(np.mean(sig ** 2)))
    return out


def summary(ratios) -> str:
    """How many ratios lie in [0.8, 1.25], and the RMS of their logarithms."""
    r = np.asarray(list(ratios), np.float64)
    return (f"{int(np.sum((r >= 0.8) & (r <= 1.25)))} of {len(r)} conditions with the ratio in [0.8, 1.25]; "
            f"RMS of log ratio {float(np.sqrt(np.mean(np.log(r) ** 2))):.3f}")


def report(data: dict, table=None) -> list[float]:
    """Print one line per condition; return the ratios (measured RMS error / RMS σ over all its renders)."""
    from scipy.stats import spearmanr

    table = table or (cs.COEFFS, cs.LOW, cs.HIGH, cs.FOREIGN)
    print(f"{'condition':26s} {'corners':>7s} {'gross':>5s} {'RMS err/axis':>12s} {'RMS σ':>8s} {'ratio':>6s} {'seeds':>11s} "
          f"{'68% over images':>15s} {'rank ρ':>6s}")
    ratios = []
    for name, v in data.items():
        if len(v["x"]) == 0:
            print(f"{name:26s} {0:7d} {int(v['gross']):5d}  no board found")
            continue
        sig = cs.sigma_from_design(v["x"], *table).astype(np.float64)
        rms_e, rms_s = float(np.sqrt(np.mean(v["err"] ** 2))), float(np.sqrt(np.mean(sig ** 2)))
        rho = spearmanr(np.hypot(v["err"][:, 0], v["err"][:, 1]), sig).statistic if np.ptp(sig) > 0 else float("nan")
        ratios.append(rms_e / rms_s)
        lo, hi = ratio_interval(v["err"], sig, v["image"])
        seed = v["image"] // 1000
        per = [float(np.sqrt(np.mean(v["err"][seed == k] ** 2) / np.mean(sig[seed == k] ** 2))) for k in np.unique(seed)]
        print(f"{name:26s} {len(sig):7d} {int(v['gross']):5d} {rms_e:12.4f} {rms_s:8.4f} {rms_e / rms_s:6.2f} "
              f"{min(per):5.2f}–{max(per):<5.2f} {lo:7.2f}–{hi:<7.2f} {rho:6.2f}")
    print(summary(ratios))
    spread(data, table)
    return ratios


def ratio_interval(err: np.ndarray, sig: np.ndarray, image: np.ndarray, draws: int = 1000) -> tuple[float, float]:
    """The 16th and 84th percentiles of the ratio RMS error / RMS σ over the condition's images drawn again with
    replacement (seeded): how far the ratio of a few renders moves from scene to scene, one rare large error
    weighing in. err : (K, 2) px. sig : (K,) px. image : (K,) int, each corner's image."""
    _, g = np.unique(image, return_inverse=True)
    e2 = np.bincount(g, np.einsum("nk,nk->n", err, err))
    s2 = np.bincount(g, 2 * sig * sig)
    pick = np.random.default_rng(0).integers(0, len(e2), (draws, len(e2)))
    r = np.sqrt(e2[pick].sum(axis=1) / np.maximum(s2[pick].sum(axis=1), 1e-30))
    return float(np.percentile(r, 16)), float(np.percentile(r, 84))


def spread(data: dict, table) -> None:
    """Print σ against error inside the boards: per fifth of the corners by σ / their board's median σ, that
    ratio's median and the RMS of error / the board's RMS error (equal when σ spreads as the errors do)."""
    rel, err = [], []
    for k, v in enumerate(data.values()):
        if len(v["x"]) == 0:
            continue
        sig = cs.sigma_from_design(v["x"], *table).astype(np.float64)
        e2 = 0.5 * np.einsum("nk,nk->n", v["err"], v["err"])
        for i in np.unique(v["image"]):
            m = v["image"] == i
            rel.append(sig[m] / np.median(sig[m]))
            err.append(e2[m] / max(float(np.mean(e2[m])), 1e-30))
    rel, err = np.concatenate(rel), np.concatenate(err)
    edges = np.quantile(rel, np.linspace(0, 1, 6))
    cells = [(float(np.median(rel[m])), float(np.sqrt(np.mean(err[m]))))
             for m in ((rel >= a) & (rel <= b) for a, b in zip(edges[:-1], edges[1:]))]
    print("inside boards, σ / board median σ : RMS error / board RMS error, per fifth: "
          + ", ".join(f"{a:.2f} : {b:.2f}" for a, b in cells))


def family(name: str) -> str:
    """A condition's family: a sweep's levels are one (``sweep-noise-10`` -> ``sweep-noise``), a named condition its own."""
    name = name.split("@")[0]
    return name.rsplit("-", 1)[0] if name.startswith("sweep-") else name


def leave_out(train: dict, held: dict) -> None:
    """Print each family's ratios on ``held`` from a table fitted on ``train`` without that family (held-out
    conditions as well as seeds), and the count within 0.8-1.25."""
    ratios = {}
    for fam in dict.fromkeys(family(n) for n in held):
        table = fit_table({n: v for n, v in train.items() if family(n) != fam and len(v["x"])})
        ratios.update(ratios_of({n: v for n, v in held.items() if family(n) == fam}, table))
    print("families held out of the fit, outside [0.8, 1.25]: "
          + (", ".join(f"{n} {r:.2f}" for n, r in ratios.items() if not 0.8 <= r <= 1.25) or "none"))
    print("held-out families: " + summary(ratios.values()))


def _cached(path: Path | None, make) -> dict:
    """``make()``'s collection, kept in (and read back from) the npz ``path`` when given."""
    if path is not None and path.exists():
        z = np.load(path, allow_pickle=False)
        names = [str(n) for n in z["names"]]
        return {n: {f: z[f"{f}{k}"] for f in ("x", "err", "image", "gross")} for k, n in enumerate(names)}
    data = make()
    if path is not None:
        arrays = {"names": np.array(list(data))}
        for k, v in enumerate(data.values()):
            arrays.update({f"{f}{k}": a for f, a in v.items()})
        np.savez(path, **arrays)
    return data


MIXED = ((0.6, 2.0), (0.6, 25.0), (2.5, 2.0), (2.5, 15.0), (1.2, 8.0))  # (blur σ px, noise σ grey levels)


def _degraded(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A rendered view (uint8) blurred and noised by one of ``MIXED``, drawn with ``rng``."""
    import cv2

    blur, noise = MIXED[int(rng.integers(len(MIXED)))]
    out = cv2.GaussianBlur(image.astype(np.float32), (0, 0), blur) + rng.normal(0.0, noise, image.shape)
    return np.clip(np.round(out), 0, 255).astype(np.uint8)


WEIGHTINGS = ("equal",) + weights.WEIGHTINGS  # "equal": the views without σ; the others: aicalib_tf.calib.weights


def calibrate_weighted(views: int, degrade: bool = True, repeats: int = 1) -> None:
    """Print each camera's calibration errors under each of ``WEIGHTINGS`` (``--calibrate``; ``degrade``
    False: the views as rendered, noise σ 2), ``repeats`` draws of the degradations, and their means."""
    from aicalib_tf.bench.conditions import calibration_sequences
    from aicalib_tf.bench.metrics import calibration_errors
    from aicalib_tf.calib.fit import View, calibrate_camera

    print(f"{'camera':>6s} {'draw':>4s} {'weights':>9s} {'fx %':>8s} {'fy %':>8s} {'pp px':>7s} {'proj seen px':>12s} {'rms px':>7s}")
    totals = {w: [] for w in WEIGHTINGS}
    shipped = weights.WEIGHTING
    for cam, samples in calibration_sequences(views):
        lab = samples[0].label
        seen = np.concatenate([s.corners[s.visible] for s in samples])
        for draw in range(repeats if degrade else 1):
            rng = np.random.default_rng(1000 * (draw + 1) + cam)
            found = [(f"view{k:02d}", d) for k, s in enumerate(samples)
                     if (d := detect_corners(_degraded(s.image, rng) if degrade else s.image, PATTERN)).found]
            for label in WEIGHTINGS:
                vs = [View(n, d.corners, d.ids, sigmas=None if label == "equal" else d.sigmas) for n, d in found]
                weights.WEIGHTING = weights.WEIGHTING if label == "equal" else label
                try:
                    cal = calibrate_camera(vs, PATTERN, float(lab["square_size"]), tuple(lab["image_size"]),
                                           model="plumb_bob")
                finally:
                    weights.WEIGHTING = shipped
                err = calibration_errors(cal.K, cal.dist, np.asarray(lab["K"]), np.asarray(lab["dist"]), tuple(lab["image_size"]),
                                         model=cal.model, model_true=lab["distortion_model"], seen=seen)
                totals[label].append((abs(err["fx_pct"]), err["pp_px"], err["proj_err_seen_mean_px"]))
                print(f"{cam:6d} {draw:4d} {label:>9s} {err['fx_pct']:8.3f} {err['fy_pct']:8.3f} {err['pp_px']:7.3f} "
                      f"{err['proj_err_seen_mean_px']:12.4f} {cal.rms:7.3f}")
    for label, rows in totals.items():
        m = np.mean(rows, axis=0)
        print(f"mean over {len(rows)} calibrations, {label:>9s}: |fx| {m[0]:.3f} %, pp {m[1]:.3f} px, proj seen {m[2]:.4f} px")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--images", type=int, default=6, help="renders per condition and seed")
    ap.add_argument("--seeds", default=",".join(map(str, EVAL_SEEDS)), help="data_gen seeds reported on (own: the condition's)")
    ap.add_argument("--conditions", default="named,sweeps", help="conditions reported (aicalib_tf.bench.conditions names)")
    ap.add_argument("--fit", action="store_true", help="refit the table on --fit-on rendered with FIT_SEEDS")
    ap.add_argument("--fit-on", default="sweeps,named", help="conditions fitted on (with other seeds)")
    ap.add_argument("--leave-out", action="store_true", help="with --fit: each family's ratios fitted without it")
    ap.add_argument("--cache", type=Path, help="folder for the collected corners (read when present, else written)")
    ap.add_argument("--calibrate", action="store_true", help="calibrate mixed-degradation sequences with and without σ")
    ap.add_argument("--views", type=int, default=20, help="views per calibration sequence (--calibrate)")
    ap.add_argument("--as-rendered", action="store_true", help="--calibrate on the views as rendered, not degraded")
    ap.add_argument("--repeats", type=int, default=1, help="draws of the degradations per camera (--calibrate)")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    if a.calibrate:
        calibrate_weighted(a.views, degrade=not a.as_rendered, repeats=a.repeats)
        print(f"{time.perf_counter() - t0:.0f} s")
        return 0
    if a.cache:
        a.cache.mkdir(parents=True, exist_ok=True)
    seeds = tuple(s.strip() for s in a.seeds.split(",") if s.strip())
    name = f"{a.conditions.replace(',', '+')}_{a.images}_{'+'.join(seeds)}.npz"
    held = _cached(a.cache and a.cache / name, lambda: collect(select_conditions(a.conditions), a.images, seeds))
    table = None
    if a.fit:
        train = _cached(a.cache and a.cache / f"fit_{a.fit_on.replace(',', '+')}_{a.images}_{'+'.join(map(str, FIT_SEEDS))}.npz",
                        lambda: collect(select_conditions(a.fit_on), a.images, FIT_SEEDS))
        table = fit_table(train)
        print(f"fitted on {sum(len(v['x']) for v in train.values())} corners, {len(train)} conditions "
              f"({', '.join(select_conditions(a.fit_on)[k].name for k in range(2))}, ...) with seeds {FIT_SEEDS}")
        print("on the fit's own renders: " + summary(ratios_of(train, table).values()))
        if a.leave_out:
            leave_out(train, held)
        for label, arr in zip(("COEFFS", "LOW", "HIGH"), table):
            print(f"{label} = np.array([{', '.join(f'{v:.3f}' for v in arr)}])")
        print(f"FOREIGN = {table[3]:.3f}")
    report(held, table)
    print(f"{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
