"""Corner refiners against the truth towards a vignetted fisheye's rim, by distance from the circle's centre.

    python benchmarks/fisheye_ramp.py [--images 24] [--look full|falloff|flat] [--size 640x480]

Boards close to circular 150–200° fisheyes (data_gen ``fisheye_closeup``, seed 7, 9×6, no clutter) under
one of three looks: ``full`` (the preset's light fall-off to black at the circle and blur growing towards
it, noise σ 2), ``falloff`` (the fall-off, a constant blur σ 0.7 px and the noise) and ``flat`` (blur and
noise only). Each refiner starts from the true corners moved 0.5 px in a random direction; printed per
band of ρ (distance from the circle's centre over its radius): the share refined, the median and RMS
error (px) and the mean error along the radius (px, outwards positive). Refiners: "windowed" (the
detector's :func:`aicalib_tf.detect.corners.refine.refine_candidates`), "windowed + polish" (then
:func:`aicalib_tf.detect.corners.refine.polish`, which allows for a linear light ramp), "windowed + board
polish" (then :func:`aicalib_tf.detect.corners.refine.polish_board`, as the detector), "ramp" (then
:func:`aicalib_tf.detect.corners.refine.refine_ramp` everywhere) and OpenCV's ``cornerSubPix`` (11×11).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace

import numpy as np

from aicalib_tf.detect.corners.junctions import nearest_spacing
from aicalib_tf.detect.corners.refine import Smoothed, polish, polish_board, refine_candidates, refine_ramp, refine_subpix
from aicalib_tf.io import quantize
from data_gen import make_sample
from data_gen.presets import Rule, get_preset
from data_gen.sample import _circle_px, draw_scene

BANDS = (0.0, 0.3, 0.5, 0.65, 0.8, 1.0)


def _windowed(g, p, ids):
    return refine_candidates(Smoothed(g), p, nearest_spacing(p))


def _polished(g, p, ids):
    smoothed = Smoothed(g)
    out, ok = refine_candidates(smoothed, p, nearest_spacing(p))
    return polish(smoothed, out, nearest_spacing(p)), ok


def _board(g, p, ids):
    smoothed = Smoothed(g)
    out, ok = refine_candidates(smoothed, p, nearest_spacing(p))
    return polish_board(smoothed, out, ids, nearest_spacing(p)), ok


def _ramp(g, p, ids):
    smoothed = Smoothed(g)
    out, ok = refine_candidates(smoothed, p, nearest_spacing(p))
    got, ramp_ok = refine_ramp(smoothed, out, nearest_spacing(p))
    return got, ok & ramp_ok


REFINERS = {"windowed": _windowed, "windowed + polish": _polished, "windowed + board polish": _board, "ramp": _ramp,
            "cornerSubPix hw5": lambda g, p, ids: refine_subpix(g, p, half_window=5)}


def preset(look: str):
    """fisheye_closeup with the look's degradations and no clutter."""
    base = get_preset("fisheye_closeup")
    falloff, _, noise = base.rules
    blur = Rule.of("gaussian_blur", sigma=0.7)
    rules = {"full": base.rules, "falloff": (falloff, blur, noise), "flat": (blur, noise)}[look]
    return replace(base, rules=rules, clutter=(0.0, 0.0))


def measure(look: str, images: int, size: tuple[int, int]) -> dict:
    """{refiner: (N, 4) rows of ρ, error x, error y, error along the radius (px)}."""
    pre, rng = preset(look), np.random.default_rng(0)
    rows = {name: [] for name in REFINERS}
    for i in range(images):
        s = make_sample(pre, 7, i, size=size, pattern=(9, 6))
        gray = (s.image if s.image.dtype == np.uint8 else quantize(s.image)).astype(np.float32) / 255.0
        circle = _circle_px(draw_scene(pre, 7, i, size=size, pattern=(9, 6)).camera)
        gt = s.corners[s.visible].astype(np.float64)
        ids = np.stack(np.divmod(np.flatnonzero(s.visible), 9)[::-1], 1)  # (col, row) on the 9-wide pattern
        if len(gt) < 10:
            continue
        ang = rng.uniform(0, 2 * np.pi, len(gt))
        start = gt + 0.5 * np.stack([np.cos(ang), np.sin(ang)], 1)
        out_dir = gt - [circle["cx"], circle["cy"]]
        rho = np.hypot(out_dir[:, 0], out_dir[:, 1])
        out_dir /= np.maximum(rho, 1e-9)[:, None]
        for name, fn in REFINERS.items():
            q, ok = fn(gray, start, ids)
            err = np.where(ok[:, None], q - gt, np.nan)
            rows[name].append(np.column_stack([rho / circle["radius"], err, np.sum(err * out_dir, axis=1)]))
    return {k: np.concatenate(v) for k, v in rows.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--images", type=int, default=24)
    ap.add_argument("--look", choices=("full", "falloff", "flat"), default="full")
    ap.add_argument("--size", default="640x480", help="WxH px (default: 640x480)")
    args = ap.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))
    res = measure(args.look, args.images, size)
    print(f"fisheye_closeup, look {args.look}, {args.images} images at {size[0]}x{size[1]}")
    print("| ρ | corners | refiner | ok % | median px | RMS px | radial px |\n|---|---|---|---|---|---|---|")
    for lo, hi in zip(BANDS[:-1], BANDS[1:]):
        for name, r in res.items():
            band = r[(r[:, 0] >= lo) & (r[:, 0] < hi)]
            ok = ~np.isnan(band[:, 1])
            e = np.hypot(band[ok, 1], band[ok, 2])
            if len(e):
                print(f"| {lo:.2f}-{hi:.2f} | {len(band)} | {name} | {100 * ok.mean():.0f} | {np.median(e):.3f} | "
                      f"{np.sqrt(np.mean(e * e)):.3f} | {np.mean(band[ok, 3]):+.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
