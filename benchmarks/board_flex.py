"""Board flex: is a board's sag recovered, and does solving it keep the focal length unbiased?

    python benchmarks/board_flex.py [--sags 0 0.005 0.01 0.02] [--seeds 10] [--noise 0.2] [--rendered 10]

Corner sequences: a 640x480 plumb_bob lens (fx 500 px, k1 -0.25) sees a 9x6 board of 40 mm squares,
flexed by w = (0.6·sag, 0.4·sag) squares (:mod:`aicalib_tf.geometry.board_flex`; sag = w_x + w_y, the
centre against the grid's corners), in 20 poses 0.35-0.6 m away tilted up to 40°; corners get Gaussian
noise (--noise px per axis). Each sequence is calibrated with the flex solved (``flex="sag"``) and with
the board taken as flat (``flex="off"``), plumb_bob forced.

Rendered sequences (--rendered N per sag, N >= 3): cameras 0..N-1 of data_gen's ``calib`` preset (a
pinhole of 50-110° with mild or strong barrel, 20 views, blur and noise) with the preset's ``flex``, the
images through the project's CNN detector (its corners' σ as weights, as ``calibrate`` does), then
:func:`~aicalib_tf.calib.fit.calibrate_camera` with model choice (``auto``); the truth is the label's
flex and K. Camera k renders the same poses and noise at every sag, so the sags' rows share their draws.

Per sag: how many fits kept a flex (its σ rule, :mod:`aicalib_tf.calib.flex`, and the sag's shrinkage
by its leave-one-view-out noise, :mod:`aicalib_tf.calib.flex_check`; a flat result counts as sag 0),
the worst |sag error| and whether every sequence met the target (within
10% or 0.002 squares), and the focal-length bias: the mean fx error over the sequences with its standard
error, against the median σ_fx of one fit (target: |bias| < σ_fx). One sequence's fx error is one draw
of about σ_fx, not a bias, so a bias needs several sequences (:func:`fx_bias`).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aicalib_tf.calib.fit import View, calibrate_camera  # noqa: E402
from aicalib_tf.geometry import lens as L  # noqa: E402
from tests.calib.synthetic import PATTERN, SQUARE, synthetic_views  # noqa: E402

SIZE = (640, 480)
LENS = L.Lens("plumb_bob", [[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]], [-0.25, 0.08, 0.001, -0.0005, 0.0], SIZE)
SPLIT = (0.6, 0.4)  # the sag's share along x and y
MIN_SEQUENCES = 3  # the fewest sequences whose fx errors make a bias (mean ± standard error)
HEADER = ["| sag (squares) | flex kept | worst sag error | all within target | fx bias, flex solved (px, ± s.e.) | "
          "fx bias, flat board | median σ_fx | bias / σ_fx |", "|---|---|---|---|---|---|---|---|"]


def corner_sequence(flex, noise: float, rng: np.random.Generator, n: int = 20) -> list[View]:
    """``n`` views of the flexed board through :data:`LENS`, corners with ``noise`` px."""
    return synthetic_views(LENS, n, noise, seed=rng, flex=flex)


def fx_bias(errors, sigmas) -> dict:
    """The focal-length bias over independent sequences: {"mean", "se" (px), "sigma" (median σ_fx, px),
    "ratio" (mean / sigma)}. errors, sigmas : (n,) px, each sequence's fx − truth and its fit's σ_fx.
    Raises ValueError for fewer than :data:`MIN_SEQUENCES` sequences: one error is a draw, not a bias."""
    e, s = np.asarray(errors, np.float64).ravel(), np.asarray(sigmas, np.float64).ravel()
    if len(e) != len(s):
        raise ValueError(f"{len(e)} fx errors but {len(s)} σ_fx")
    if len(e) < MIN_SEQUENCES:
        raise ValueError(f"a bias needs at least {MIN_SEQUENCES} sequences, got {len(e)}")
    mean, sigma = float(e.mean()), float(np.median(s))
    return {"mean": mean, "se": float(e.std(ddof=1) / np.sqrt(len(e))), "sigma": sigma, "ratio": mean / sigma}


def within_target(solved: float, sag: float) -> bool:
    """Is a solved sag (squares) within 10% or 0.002 squares of the true ``sag``?"""
    return abs(solved - sag) <= max(0.1 * abs(sag), 0.002)


def _sag(cal) -> float:
    """squares: a calibration's sag w_x + w_y (0 when the flex is off)."""
    return 0.0 if cal.flex is None else float(np.sum(cal.flex))


def sag_row(sag: float, fits) -> str:
    """The table row of one sag: fits is a list of (flex-solved Calibration, flat Calibration, true fx)."""
    err = [_sag(on) - sag for on, _, _ in fits]
    on = fx_bias([c.fx - fx for c, _, fx in fits], [c.std["fx"] for c, _, _ in fits])
    off = fx_bias([c.fx - fx for _, c, fx in fits], [c.std["fx"] for _, c, _ in fits])
    ok = all(within_target(_sag(c), sag) for c, _, _ in fits)
    return (f"| {sag:g} | {sum(c.flex is not None for c, _, _ in fits)}/{len(fits)} | {np.max(np.abs(err)):.4f} | "
            f"{'yes' if ok else 'NO'} | {on['mean']:+.3f} ± {on['se']:.3f} | {off['mean']:+.3f} ± {off['se']:.3f} | "
            f"{on['sigma']:.3f} | {on['ratio']:+.2f} |")


def corner_rows(sags, seeds: int, noise: float) -> list[str]:
    lines = list(HEADER)
    for sag in sags:
        fits = []
        for seed in range(seeds):
            views = corner_sequence((SPLIT[0] * sag, SPLIT[1] * sag), noise, np.random.default_rng([seed, 47]))
            on = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", square_unit="m", flex="sag")
            fits.append((on, calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", flex="off"), 500.0))
        lines.append(sag_row(sag, fits))
        print(lines[-1], flush=True)
    return lines


def rendered_views(sag: float, camera: int, detect) -> tuple[list[View], dict]:
    """(views, the first label) of camera ``camera`` of the ``calib`` preset flexed by ``sag`` squares:
    each image's corners from ``detect`` (:func:`~aicalib_tf.calib.workflow.make_detector`) with their σ."""
    from data_gen.presets import get_preset
    from data_gen.sample import make_sequence

    preset = replace(get_preset("calib"), name="calib_flexed", flex=(SPLIT[0] * sag, SPLIT[1] * sag))
    samples = make_sequence(preset, 0, camera)
    views = []
    for k, s in enumerate(samples):
        found = detect(s.image)
        if found is not None:
            views.append(View(f"img{k:02d}", found[0], found[1], relative=detect.relative, sigmas=detect.sigmas))
    return views, samples[0].label


def rendered_rows(sags, n: int) -> list[str]:
    from aicalib_tf.calib.workflow import make_detector

    detect = make_detector("cnn", PATTERN)
    lines = list(HEADER)
    for sag in sags:
        fits = []
        for cam in range(n):
            views, label = rendered_views(sag, cam, detect)
            sq, size, fx = label["square_size"], tuple(label["image_size"]), label["K"][0][0]
            on = calibrate_camera(views, PATTERN, sq, size, square_unit="mm", flex="sag")
            off = calibrate_camera(views, PATTERN, sq, size, model=on.model, flex="off")
            fits.append((on, off, fx))
            print(f"  sag {sag:g} camera {cam}: {on.model}, sag {_sag(on):.4f}, fx {on.fx - fx:+.3f} ± "
                  f"{on.std['fx']:.3f} px solved, {off.fx - fx:+.3f} flat; {on.flex_note or 'flex kept'}", flush=True)
        lines.append(sag_row(sag, fits))
        print(lines[-1], flush=True)
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sags", type=float, nargs="+", default=[0.0, 0.005, 0.01, 0.02], help="squares")
    ap.add_argument("--seeds", type=int, default=10, help="corner sequences per sag")
    ap.add_argument("--noise", type=float, default=0.2, help="corner noise, px per axis")
    ap.add_argument("--rendered", type=int, default=0,
                    help=f"rendered data_gen sequences per sag (CNN detector), 0 or at least {MIN_SEQUENCES}")
    args = ap.parse_args(argv)
    if args.seeds < MIN_SEQUENCES or 0 < args.rendered < MIN_SEQUENCES:
        ap.error(f"--seeds and --rendered: a bias needs at least {MIN_SEQUENCES} sequences per sag")
    print(f"corner sequences: {args.seeds} per sag, noise {args.noise} px, 20 views, plumb_bob 640x480 fx 500")
    corner_rows(args.sags, args.seeds, args.noise)
    if args.rendered:
        print(f"rendered sequences (data_gen calib preset + flex, CNN detector, model auto): {args.rendered} per sag")
        rendered_rows(args.sags, args.rendered)
    return 0


if __name__ == "__main__":
    sys.exit(main())
