"""Board shape: is a board's shape beyond the sag recovered, and does solving it keep the focal length unbiased?

    python benchmarks/board_shape.py [--shapes flat sag twist full] [--seeds 10] [--noise 0.2] [--views 20]
        [--rendered 0]

Corner sequences as in ``benchmarks/board_flex.py``: a 640x480 plumb_bob lens (fx 500 px, k1 -0.25) sees a
9x6 board of 40 mm squares in --views poses (default 20) 0.35-0.6 m away tilted up to 40°, corners with
Gaussian noise (--noise px per axis). The board is shaped by one of :data:`SHAPES` (the terms of
:mod:`aicalib_tf.geometry.board_shape`, squares): flat, the sag alone, a twist, and all seven terms.
Each sequence is calibrated four ways, plumb_bob forced: the board flat (``flex="off"``), the sag
(``flex="sag"``), the shape (``flex="shape"``, each term shrunk by its leave-one-view-out noise,
:mod:`aicalib_tf.calib.board_shape`) and the default ``flex="auto"`` (the shape where it moves the lens by
more than its leave-one-view-out noise, else flat: :mod:`aicalib_tf.calib.flex_check`).

Rendered sequences (--rendered N per shape, N >= 3): cameras 0..N-1 of data_gen's ``calib`` preset with
the preset's ``shape`` (the label's truth), the images through the project's CNN detector, then
:func:`~aicalib_tf.calib.fit.calibrate_camera` with model choice, the shape solved and flat.

Per shape and fit: the focal-length bias (mean fx error over the sequences ± its standard error) against
the median σ_fx of one fit (target: |bias| < σ_fx, ``benchmarks/board_flex.py``'s :func:`fx_bias`); for the
shape fit, the recovered shape's RMS out of the board's plane against the truth's, and the worst term's
mean error in units of its mean standard error (a recovered shape: every term within 2 of them); for
auto, how many sequences kept the shape and the geometric mean over them of its lens's projection
error to the truth (median over the image, rotation fitted) ÷ the flat fit's.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from board_flex import LENS, MIN_SEQUENCES, SIZE, fx_bias  # noqa: E402

from aicalib_tf.calib.fit import View, calibrate_camera  # noqa: E402
from aicalib_tf.geometry.board_shape import SHAPE_TERMS, out_of_plane_rms  # noqa: E402
from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views  # noqa: E402

# squares, in SHAPE_TERMS' order: sag_x, sag_y, twist, cubic_x, cubic_y, sag_x_by_y, sag_y_by_x
SHAPES = {"flat": (0.0,) * 7, "sag": (0.006, 0.004, 0.0, 0.0, 0.0, 0.0, 0.0),
          "twist": (0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.0), "full": (0.006, 0.004, 0.01, 0.004, -0.003, 0.002, 0.003)}
FITS = (("off", "flat board"), ("sag", "sag"), ("shape", "shape"), ("auto", "auto (the default)"))
HEADER = ["| shape | out-of-plane RMS, truth (squares) | solved (mean ± sd) | worst term error / SE | "
          "fx bias flat (px ± s.e.) | fx bias sag | fx bias shape | median σ_fx (shape) | shape bias / σ_fx | "
          "auto: kept | fx bias | error ÷ flat's |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]


def shape_of(cal) -> np.ndarray:
    """(7,) squares: a calibration's shape terms (the flex's two, zeros beyond; zeros for a flat board)."""
    out = np.zeros(len(SHAPE_TERMS))
    if cal.flex is not None:
        out[:len(cal.flex)] = cal.flex
    return out


def term_errors(fits, truth) -> np.ndarray:
    """(7,) each term's mean error over the shape fits in units of its mean standard error (0 where a term's
    SE is 0 and so is its error): fits, a list of shape-fit Calibrations; truth (7,) squares."""
    err = np.array([shape_of(c) - truth for c in fits])
    se = np.array([np.zeros(7) if c.flex is None else np.pad(np.sqrt(np.diag(c.flex_covariance)), (0, 7 - len(c.flex)))
                   for c in fits])
    m, s = err.mean(axis=0), se.mean(axis=0)
    return np.divide(m, s, out=np.where(np.abs(m) > 0, np.inf, 0.0), where=s > 0)


def shape_row(name: str, truth, fits, lens=LENS) -> str:
    """One table row: fits is a list of ({flex mode: Calibration}, true fx); lens, the true lens (None: no
    projection error, "-")."""
    rms_true = out_of_plane_rms(truth, np.zeros((7, 7)), PATTERN)[0]
    shaped = [f["shape"] for f, _ in fits]
    solved = [out_of_plane_rms(shape_of(c), np.zeros((7, 7)), PATTERN)[0] for c in shaped]
    worst = np.max(np.abs(term_errors(shaped, np.asarray(truth))))
    bias = {m: fx_bias([f[m].fx - fx for f, fx in fits], [f[m].std["fx"] for f, fx in fits]) for m, _ in FITS}
    b = lambda m: f"{bias[m]['mean']:+.3f} ± {bias[m]['se']:.3f}"  # noqa: E731
    kept = sum(f["auto"].flex is not None for f, _ in fits)
    ratio = "-" if lens is None else \
        f"{np.exp(np.mean([np.log(truth_error(f['auto'], lens) / truth_error(f['off'], lens)) for f, _ in fits])):.2f}"
    return (f"| {name} | {rms_true:.4f} | {np.mean(solved):.4f} ± {np.std(solved):.4f} | {worst:.2f} | {b('off')} | "
            f"{b('sag')} | {b('shape')} | {bias['shape']['sigma']:.3f} | {bias['shape']['ratio']:+.2f} | "
            f"{kept}/{len(fits)} | {b('auto')} | {ratio} |")


def truth_error(cal, lens) -> float:
    """px: the median over a 32 × 24 grid of a calibration's projection difference to the true ``lens``
    (:func:`aicalib_tf.calib.diff.projection_diff`, rotation fitted)."""
    from aicalib_tf.calib.diff import projection_diff

    return projection_diff(cal.lens, lens)["all_stats"]["median"]


def corner_rows(names, seeds: int, noise: float, n_views: int = 20) -> list[str]:
    lines = list(HEADER)
    for name in names:
        fits = []
        for seed in range(seeds):
            views = synthetic_views(LENS, n_views, noise, seed=np.random.default_rng([seed, 47]), flex=SHAPES[name])
            fits.append(({m: calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", square_unit="m", flex=m)
                          for m, _ in FITS}, 500.0))
        lines.append(shape_row(name, SHAPES[name], fits))
        print(lines[-1], flush=True)
    return lines


def rendered_rows(names, n: int) -> list[str]:
    from data_gen.presets import get_preset
    from data_gen.sample import make_sequence

    from aicalib_tf.calib.workflow import make_detector

    detect = make_detector("cnn", PATTERN)
    lines = list(HEADER)
    for name in names:
        fits = []
        preset = replace(get_preset("calib"), name=f"calib_{name}", shape=SHAPES[name])
        for cam in range(n):
            samples = make_sequence(preset, 0, cam)
            views = [View(f"img{k:02d}", *hit, relative=detect.relative, sigmas=detect.sigmas)
                     for k, hit in enumerate(detect(s.image) for s in samples) if hit is not None]
            label = samples[0].label
            sq, size, fx = label["square_size"], tuple(label["image_size"]), label["K"][0][0]
            shape = calibrate_camera(views, PATTERN, sq, size, square_unit="mm", flex="shape")
            cals = {m: calibrate_camera(views, PATTERN, sq, size, model=shape.model, flex=m) for m in ("off", "sag", "auto")}
            fits.append(({**cals, "shape": shape}, fx))
            print(f"  {name} camera {cam}: {shape.model}, fx {shape.fx - fx:+.3f} ± {shape.std['fx']:.3f} px shape, "
                  f"{cals['off'].fx - fx:+.3f} flat; {shape.flex_note or 'every term kept'}", flush=True)
        lines.append(shape_row(name, SHAPES[name], fits, None))
        print(lines[-1], flush=True)
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--shapes", nargs="+", default=list(SHAPES), choices=list(SHAPES))
    ap.add_argument("--seeds", type=int, default=10, help="corner sequences per shape")
    ap.add_argument("--noise", type=float, default=0.2, help="corner noise, px per axis")
    ap.add_argument("--views", type=int, default=20, help="views per corner sequence (default: 20)")
    ap.add_argument("--rendered", type=int, default=0,
                    help=f"rendered data_gen sequences per shape (CNN detector), 0 or at least {MIN_SEQUENCES}")
    args = ap.parse_args(argv)
    if args.seeds < MIN_SEQUENCES or 0 < args.rendered < MIN_SEQUENCES:
        ap.error(f"--seeds and --rendered: a bias needs at least {MIN_SEQUENCES} sequences per shape")
    print(f"corner sequences: {args.seeds} per shape, noise {args.noise} px, {args.views} views, plumb_bob 640x480 "
          "fx 500")
    corner_rows(args.shapes, args.seeds, args.noise, args.views)
    if args.rendered:
        print(f"rendered sequences (data_gen calib preset + shape, CNN detector, model auto): {args.rendered} "
              "per shape")
        rendered_rows(args.shapes, args.rendered)
    return 0


if __name__ == "__main__":
    sys.exit(main())
