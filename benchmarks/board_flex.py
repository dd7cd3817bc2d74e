"""Board flex: is a board's sag recovered, and does solving it keep the focal length unbiased?

    python benchmarks/board_flex.py [--sags 0 0.005 0.01 0.02] [--seeds 10] [--noise 0.2] [--rendered 1]

Corner sequences: a 640x480 plumb_bob lens (fx 500 px, k1 -0.25) sees a 9x6 board of 40 mm squares,
flexed by w = (0.6·sag, 0.4·sag) squares (:mod:`aicalib_tf.geometry.board_flex`; sag = w_x + w_y, the
centre against the grid's corners), in 20 poses 0.35-0.6 m away tilted up to 40°; corners get Gaussian
noise (--noise px per axis). Each sequence is calibrated with the flex solved (``flex="auto"``) and with
the board taken as flat (``flex="off"``), plumb_bob forced. Per sag: how many fits kept the flex (its σ
and the held-out check of :mod:`aicalib_tf.calib.flex_check`; a dropped flex counts as sag 0), the worst
|sag error| and whether every sequence met the target (within 10% or 0.002 squares), the kept flexes'
median σ, and the focal-length bias
(mean fx − 500 over the seeds, with its standard error) against the median σ_fx of one fit.

Rendered sequences (--rendered N per sag): data_gen's ``calib`` preset with the preset's ``flex``, the
images through the project's CNN detector, then :func:`~aicalib_tf.calib.fit.calibrate_camera` with
model choice (``auto``): the flex against the label's truth and fx against the label's K.
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


def corner_sequence(flex, noise: float, rng: np.random.Generator, n: int = 20) -> list[View]:
    """``n`` views of the flexed board through :data:`LENS`, corners with ``noise`` px."""
    return synthetic_views(LENS, n, noise, seed=rng, flex=flex)


def _sag(cal) -> tuple[float, float]:
    """(sag, σ) squares of a calibration's flex (0, 0 when it is off)."""
    if cal.flex is None:
        return 0.0, 0.0
    c = cal.flex_covariance
    return float(np.sum(cal.flex)), float(np.sqrt(c[0, 0] + c[1, 1] + 2 * c[0, 1]))


def corner_rows(sags, seeds: int, noise: float) -> list[str]:
    lines = ["| sag (squares) | flex kept | worst sag error | all within target | flex σ (squares) | fx bias, flex "
             "solved (px, ± s.e.) | fx bias, flat board | median σ_fx |", "|---|---|---|---|---|---|---|---|"]
    for sag in sags:
        flex = (SPLIT[0] * sag, SPLIT[1] * sag)
        err, sd, fx_on, fx_off, sfx, ok, kept = [], [], [], [], [], True, 0
        for seed in range(seeds):
            views = corner_sequence(flex, noise, np.random.default_rng([seed, 47]))
            on = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", square_unit="m", flex="auto")
            off = calibrate_camera(views, PATTERN, SQUARE, SIZE, model="plumb_bob", flex="off")
            s, s_sd = _sag(on)
            kept += on.flex is not None
            err.append(s - sag)
            sd += [s_sd] if on.flex is not None else []
            ok &= abs(s - sag) <= max(0.1 * sag, 0.002)
            fx_on.append(on.fx - 500.0)
            fx_off.append(off.fx - 500.0)
            sfx.append(on.std["fx"])
        se = lambda a: np.std(a, ddof=1) / np.sqrt(len(a))  # noqa: E731
        lines.append(f"| {sag:g} | {kept}/{seeds} | {np.max(np.abs(err)):.4f} | {'yes' if ok else 'NO'} | "
                     f"{np.median(sd) if sd else float('nan'):.4f} | "
                     f"{np.mean(fx_on):+.3f} ± {se(fx_on):.3f} | {np.mean(fx_off):+.3f} ± {se(fx_off):.3f} | "
                     f"{np.median(sfx):.3f} |")
        print(lines[-1], flush=True)
    return lines


def rendered_rows(sags, n: int) -> list[str]:
    from data_gen.presets import get_preset
    from data_gen.sample import make_sequence
    from aicalib_tf.calib.workflow import make_detector

    detect = make_detector("cnn", PATTERN)
    lines = ["| sag (squares) | camera | solved sag (squares) | fx error, flex solved (px) | fx error, flat (px) | "
             "σ_fx | model | flex note |", "|---|---|---|---|---|---|---|---|"]
    for sag in sags:
        preset = replace(get_preset("calib"), name="calib_flexed", flex=(SPLIT[0] * sag, SPLIT[1] * sag))
        for cam in range(n):
            samples = make_sequence(preset, 0, cam)
            label = samples[0].label
            views = []
            for k, s in enumerate(samples):
                found = detect(s.image)
                if found is not None:
                    views.append(View(f"img{k:02d}", found[0], found[1], relative=detect.relative))
            sq, size, fx = label["square_size"], tuple(label["image_size"]), label["K"][0][0]
            on = calibrate_camera(views, PATTERN, sq, size, square_unit="mm", flex="auto")
            off = calibrate_camera(views, PATTERN, sq, size, model=on.model, flex="off")
            s, s_sd = _sag(on)
            lines.append(f"| {sag:g} | {cam} | {s:.4f} ± {s_sd:.4f} | {on.fx - fx:+.3f} | {off.fx - fx:+.3f} | "
                         f"{on.std['fx']:.3f} | {on.model} | {on.flex_note or '-'} |")
            print(lines[-1], flush=True)
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sags", type=float, nargs="+", default=[0.0, 0.005, 0.01, 0.02], help="squares")
    ap.add_argument("--seeds", type=int, default=10, help="corner sequences per sag")
    ap.add_argument("--noise", type=float, default=0.2, help="corner noise, px per axis")
    ap.add_argument("--rendered", type=int, default=0, help="rendered data_gen sequences per sag (CNN detector)")
    args = ap.parse_args(argv)
    print(f"corner sequences: {args.seeds} per sag, noise {args.noise} px, 20 views, plumb_bob 640x480 fx 500")
    corner_rows(args.sags, args.seeds, args.noise)
    if args.rendered:
        print(f"rendered sequences (data_gen calib preset + flex, CNN detector, model auto): {args.rendered} per sag")
        rendered_rows(args.sags, args.rendered)
    return 0


if __name__ == "__main__":
    sys.exit(main())
