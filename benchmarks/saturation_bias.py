"""Corner refiners against the truth on over-exposed boards: does clipping bias the corners smoothly over a board?

    python benchmarks/saturation_bias.py [--images 16] [--gains 1 1.5 2.5 4] [--size 640x480] [--psf gauss|coma|ca]

Boards close to circular 150–200° fisheyes (data_gen ``fisheye_closeup``, seed 7, 9×6, no clutter), lit by
the preset's fall-off to black at the circle, then (as a sensor) an exposure gain, the optical blur and
noise σ 2 before the 8-bit clipping: at gain g the paper's white reaches 255 where the light is over 1/g of
its peak, so the clipped share of a board grows with g. ``--psf gauss`` blurs with a Gaussian σ 1 px
(point-symmetric); ``coma`` adds a weaker copy of the image shifted 1.5 px towards the circle's rim before
the Gaussian (an asymmetric point-spread function, as a lens's coma or a camera's sharpening can leave),
the truth then moved by that kernel's centroid (where a point's light lands); ``ca`` (lateral colour) magnifies
red and blue by ±0.3% about the circle's centre, blurs, adds noise and clips each colour on its own and mixes them
to grey (JPEG's Y weights), the truth magnified by the weights' mean. Each refiner starts from the
true corners moved 0.5 px in a random direction. Printed per gain: the share of the boards' pixels at 250
or more, and for each refiner the median error (px), the board's mean error (RMS over boards, px) and the
RMS of the smooth part of each board's errors left once its mean is removed (a degree-2 polynomial in
the corners' ids, as :func:`aicalib_tf.detect.corners.refine.polish_board`'s field; median over boards, px):
the part a calibration cannot take into a board's pose; and the radial error's slope in ρ (distance from the
circle's centre over its radius; the error along the radius ≈ slope·ρ, least squares over all corners, px): a
magnification, which a calibration takes into its focal length. Refiners: "detector" (the detector's
:func:`aicalib_tf.detect.corners.refine.refine_candidates` then
:func:`aicalib_tf.detect.corners.refine.polish_board`), "saddle" (the first alone) and OpenCV's
``cornerSubPix`` (11×11, as OpenCV's classic corners).
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace

import cv2
import numpy as np

from aicalib_tf.detect.corners.junctions import nearest_spacing
from aicalib_tf.detect.corners.refine import Smoothed, board_basis, polish_board, refine_candidates, refine_subpix
from aicalib_tf.io import quantize
from data_gen.degrade import circle_falloff
from data_gen.presets import get_preset
from data_gen.render import render_board
from data_gen.sample import _circle_px, draw_scene

COMA = (0.3, 1.5)  # the shifted copy's weight and its shift towards the rim (px)
CA = (1.003, 1.0, 0.997)  # red, green and blue's magnification about the circle's centre (lateral colour)
LUMA = (0.299, 0.587, 0.114)  # their weights in the grey image (JPEG's Y)


def _saddle(g, p, ids):
    return refine_candidates(Smoothed(g), p, nearest_spacing(p))


def _detector(g, p, ids):
    smoothed = Smoothed(g)
    out, ok = refine_candidates(smoothed, p, nearest_spacing(p))
    return polish_board(smoothed, out, ids, nearest_spacing(p)), ok


REFINERS = {"detector": _detector, "saddle": _saddle,
            "cornerSubPix hw5": lambda g, p, ids: refine_subpix(g, p, half_window=5)}


def _board_stats(err: np.ndarray, ids: np.ndarray) -> tuple[np.ndarray, float]:
    """A board's mean error (2,) and the RMS of its smooth part less that mean (px)."""
    basis = board_basis(ids.astype(np.float64))
    coef, *_ = np.linalg.lstsq(basis, err, rcond=None)
    field = basis @ coef
    return err.mean(axis=0), float(np.sqrt(np.mean(np.sum((field - field.mean(axis=0)) ** 2, axis=1))))


def render(scene, gain: float, psf: str, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) float32 grey in [0, 1] of ``scene`` under the sensor law (light fall-off, gain, blur, noise σ 2, then
    the 8-bit clipping) and the truth (N, 2) px of its visible corners under ``psf`` (see the module's help)."""
    circle = _circle_px(scene.camera)
    centre = np.array([circle["cx"], circle["cy"]])
    falloff = next(s for s in scene.steps if s["name"] == "circle_falloff")
    img = render_board(scene.camera, scene.board, scene.rvec, scene.tvec, scene.background)
    img = circle_falloff(img, None, **{k: v for k, v in falloff.items() if k != "name"}) * np.float32(gain)
    truth = scene.corners[scene.visible].astype(np.float64)
    if psf == "ca":  # each colour magnified about the circle's centre, blurred, clipped, then mixed to grey
        grey = np.zeros_like(img)
        for weight, scale in zip(LUMA, CA):
            m = np.float32([[scale, 0, (1 - scale) * centre[0]], [0, scale, (1 - scale) * centre[1]]])
            ch = cv2.warpAffine(img, m, img.shape[::-1], flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
            grey += np.float32(weight) * np.clip(_blur_noise(ch, rng), 0.0, 1.0)
        return quantize(grey).astype(np.float32) / 255.0, centre + np.dot(LUMA, CA) * (truth - centre)
    if psf == "coma":  # a weaker copy shifted towards the rim, the direction taken at the board's centre
        weight, length = COMA
        out = truth.mean(axis=0) - centre
        step = length * out / max(float(np.hypot(*out)), 1e-9)
        moved = cv2.warpAffine(img, np.float32([[1, 0, step[0]], [0, 1, step[1]]]), img.shape[::-1],
                               flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        img = (img + np.float32(weight) * moved) / np.float32(1 + weight)
        truth = truth + weight * step / (1 + weight)
    return quantize(_blur_noise(img, rng)).astype(np.float32) / 255.0, truth


def _blur_noise(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The optical blur (Gaussian σ 1 px) and the sensor's noise (σ 2 grey levels)."""
    img = cv2.GaussianBlur(img, (0, 0), 1.0, borderType=cv2.BORDER_REFLECT)
    return img + rng.standard_normal(img.shape, dtype=np.float32) * np.float32(2.0 / 255.0)


def measure(gain: float, psf: str, images: int, size: tuple[int, int]) -> dict:
    """{"clipped": the boards' shares of pixels >= 250, refiner: (errors (N,), board means (B, 2), smooth RMS (B,),
    (N, 2) rows of ρ and the error along the radius, px)}."""
    pre = replace(get_preset("fisheye_closeup"), clutter=(0.0, 0.0))
    rng = np.random.default_rng(0)
    res = {"clipped": []} | {name: ([], [], [], []) for name in REFINERS}
    for i in range(images):
        scene = draw_scene(pre, 7, i, size=size, pattern=(9, 6))
        if not scene.has_board or scene.visible.sum() < 20:
            continue
        gray, gt = render(scene, gain, psf, rng)
        circle = _circle_px(scene.camera)
        out = gt - [circle["cx"], circle["cy"]]
        rho = np.hypot(out[:, 0], out[:, 1])
        ids = np.stack(np.divmod(np.flatnonzero(scene.visible), 9)[::-1], 1)  # (col, row) on the 9-wide pattern
        hull = np.zeros(gray.shape, np.uint8)
        cv2.fillConvexPoly(hull, cv2.convexHull(np.round(gt).astype(np.int32)), 1)
        res["clipped"].append(float(np.mean(gray[hull > 0] >= 250 / 255)))
        ang = rng.uniform(0, 2 * np.pi, len(gt))
        start = gt + 0.5 * np.stack([np.cos(ang), np.sin(ang)], 1)
        for name, fn in REFINERS.items():
            q, ok = fn(gray, start, ids)
            err = (q - gt)[ok]
            mean, smooth = _board_stats(err, ids[ok])
            res[name][0].append(np.hypot(err[:, 0], err[:, 1]))
            res[name][1].append(mean)
            res[name][2].append(smooth)
            res[name][3].append(np.column_stack([rho[ok] / circle["radius"], np.sum(err * out[ok], axis=1) / rho[ok]]))
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--images", type=int, default=16)
    ap.add_argument("--gains", type=float, nargs="+", default=[1.0, 1.5, 2.5, 4.0])
    ap.add_argument("--psf", choices=("gauss", "coma", "ca"), default="gauss")
    ap.add_argument("--size", default="640x480", help="WxH px (default: 640x480)")
    args = ap.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))
    print(f"fisheye_closeup, psf {args.psf}, {args.images} images at {size[0]}x{size[1]}")
    print("| gain | clipped | refiner | median px | board mean RMS px | smooth RMS px | radial px at ρ 1 |\n"
          "|---|---|---|---|---|---|---|")
    for gain in args.gains:
        res = measure(gain, args.psf, args.images, size)
        clipped = np.median(res.pop("clipped"))
        for name, (errs, means, smooth, radial) in res.items():
            means, radial = np.asarray(means), np.concatenate(radial)
            scale = np.sum(radial[:, 0] * radial[:, 1]) / np.sum(radial[:, 0] ** 2)  # error along the radius ≈ scale·ρ
            print(f"| {gain:g} | {clipped:.0%} | {name} | {np.median(np.concatenate(errs)):.3f} | "
                  f"{np.sqrt(np.mean(np.sum(means * means, axis=1))):.3f} | {np.median(smooth):.3f} | {scale:+.3f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
