"""Compare two calibrations of one camera: how far apart their projections are, px.

    python -m aicalib_tf.compare run1/camera.json run2/camera.json [--out diff.png]
    python -m aicalib_tf.compare monday/ tuesday/camera.yaml --no-rotation

Each calibration is a camera.json, a camera.yaml (OpenCV) or a folder holding camera.json. As
mrcal's projection_diff does, every pixel of a grid over the image is unprojected with A to a
ray, the rotation that best maps A's rays onto B's projections is fitted (a monocular
calibration cannot see a rotation of its own camera frame: a principal point that moves is
absorbed by the board poses), and the difference at the pixel is how far B projects the rotated
ray from it. --no-rotation leaves the rotation out.

The rotation is fitted, and the median and 95th percentile taken, over the area both
calibrations' boards covered: each stored board pose projected through its own calibration, its
convex hull filled (a calibration is only known where its boards were). A file without board
poses, or two calibrations whose boards share no area, make that the whole image, and the output
says so. Cells outside a
circular fisheye's image circle never count. It prints those figures, and over the whole image
too, and writes a heat map of the difference (--out, default diff.png; the covered area outlined)
atomically; --json writes the figures as JSON.

Exit codes: 0 compared; 2 bad input: an unreadable file, or two calibrations of different image
sizes or of obviously different cameras (their pixel scales at the image centre differ by more
than 30%), as one line naming both files.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np

__all__ = ["CompareConfig", "build_parser", "main", "run_compare", "format_compare", "heat_map_png"]


@dataclasses.dataclass(frozen=True)
class CompareConfig:
    """Everything one comparison needs (the CLI's options)."""

    a: str
    b: str
    out: str | None = "diff.png"
    json: str | None = None
    rotation: bool = True
    grid: tuple[int, int] = (32, 24)
    cbmax: float | None = None


def _grid(text: str) -> tuple[int, int]:
    import argparse

    try:
        gx, gy = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WxH cells such as 32x24, got {text!r}") from None
    if not (2 <= gx <= 1000 and 2 <= gy <= 1000):
        raise argparse.ArgumentTypeError(f"grid cells must be 2..1000 each way, got {text!r}")
    return gx, gy


def build_parser():
    """The command line's parser (docs/cli.md is generated from it)."""
    from aicalib_tf.cli import parser

    ap = parser("python -m aicalib_tf.compare", __doc__)
    ap.add_argument("a", help="calibration A: camera.json, camera.yaml or a folder holding camera.json")
    ap.add_argument("b", help="calibration B, of the same camera")
    ap.add_argument("--out", default="diff.png", help="heat map PNG to write (default: %(default)s)")
    ap.add_argument("--no-plot", action="store_true", help="write no heat map")
    ap.add_argument("--json", default=None, help="also write the figures as JSON to this file")
    ap.add_argument("--no-rotation", action="store_true", help="compare the raw projections, no rotation fitted")
    ap.add_argument("--grid", type=_grid, default=(32, 24), help="WxH cells sampled over the image (default: 32x24)")
    ap.add_argument("--cbmax", type=float, default=None,
                    help="heat map colour scale top, px (default: twice the covered area's 95th percentile)")
    return ap


def main(argv: list[str] | None = None) -> int:
    """CLI entry: 0 compared, 2 bad input (one line on stderr)."""
    from aicalib_tf.cli import run_main

    args = build_parser().parse_args(argv)
    cfg = CompareConfig(a=args.a, b=args.b, out=None if args.no_plot else args.out, json=args.json,
                        rotation=not args.no_rotation, grid=args.grid, cbmax=args.cbmax)
    return run_main(lambda: _main(cfg), debug=args.debug)


def _main(cfg: CompareConfig) -> int:
    result, text = run_compare(cfg)
    print(text)
    return 0


def run_compare(cfg: CompareConfig) -> tuple[dict, str]:
    """Load both calibrations, compare them, write --out and --json; returns (the
    :func:`~aicalib_tf.calib.diff.compare_calibrations` dict, the printed text).

    Raises InputError naming both files when they are not one camera; FileNotFoundError or
    ValueError (naming the file) when one cannot be read.
    """
    from aicalib_tf.calib.diff import compare_calibrations
    from aicalib_tf.calib.files import load_calibration
    from aicalib_tf.cli import InputError
    from aicalib_tf.io import atomic_write_bytes, atomic_write_text
    from aicalib_tf.jsonio import dumps

    if cfg.cbmax is not None and not cfg.cbmax > 0:
        raise InputError(f"--cbmax must be > 0 px, got {cfg.cbmax}")
    _check_outputs(cfg)
    cal_a, cal_b = load_calibration(cfg.a), load_calibration(cfg.b)
    try:
        result = compare_calibrations(cal_a, cal_b, grid=cfg.grid, rotation=cfg.rotation)
    except ValueError as exc:
        raise InputError(f"{cfg.a} and {cfg.b}: {exc}") from None
    lines = [format_compare(result, cfg.a, cfg.b, cal_a, cal_b)]
    if cfg.out:
        atomic_write_bytes(Path(cfg.out), heat_map_png(result, cfg.a, cfg.b, cbmax=cfg.cbmax))
        lines.append(f"heat map: {cfg.out}")
    if cfg.json:
        try:
            atomic_write_text(Path(cfg.json), dumps(_summary(result, cfg)) + "\n")
        except BaseException:  # both files or neither
            if cfg.out:
                Path(cfg.out).unlink(missing_ok=True)
            raise
        lines.append(f"figures: {cfg.json}")
    return result, "\n".join(lines)


_CALIBRATION_FILES = ("camera", "undistort_map", "camchain")  # a calibration folder's own files begin so


def _check_outputs(cfg: CompareConfig) -> None:
    """Refuse, with an InputError naming it, an output (--out, --json) that is a folder, that both
    name, or that is a file of one of the compared calibrations (it would be overwritten)."""
    from aicalib_tf.cli import InputError

    inputs = set()
    for src in (Path(cfg.a), Path(cfg.b)):
        files = [src] if not src.is_dir() else [f for f in src.iterdir() if f.name.startswith(_CALIBRATION_FILES)]
        inputs |= {os.path.realpath(f) for f in files}
    outs = [(flag, name) for flag, name in (("--out", cfg.out), ("--json", cfg.json)) if name]
    for flag, name in outs:
        if Path(name).is_dir():
            raise InputError(f"{flag} {name}: is a folder; give a file name")
        if os.path.realpath(name) in inputs:
            raise InputError(f"{flag} {name}: is a file of a compared calibration; it would be overwritten, choose another")
    if len(outs) == 2 and os.path.realpath(outs[0][1]) == os.path.realpath(outs[1][1]):
        raise InputError(f"--out and --json name the same file {outs[0][1]}")


def _summary(result: dict, cfg: CompareConfig) -> dict:
    keys = ("grid", "rotation_deg", "rotation_fitted", "covered_stats", "all_stats", "coverage", "scale_ratio")
    return {"a": str(cfg.a), "b": str(cfg.b), **{k: result[k] for k in keys},
            "covered_cells": int(np.count_nonzero(result["covered"]))}


def _describe(cal) -> str:
    w, h = cal.image_size
    return f"{cal.lens.model}, {w}x{h} px, {len(cal.views)} views, fx {cal.fx:.1f} px"


def format_compare(result: dict, name_a, name_b, cal_a, cal_b) -> str:
    """The printed report: both files, the rotation, median and p95 over the covered area and the whole image."""
    c, w = result["covered_stats"], result["all_stats"]
    n = int(np.size(result["diff"]))
    area = {"both": "the area both calibrations' boards covered",
            "no common area": "the whole image (the two calibrations' boards share no area)"}.get(
        result["coverage"], "the whole image (a file holds no board poses, so the covered area is unknown)")
    rot = (f"rotation fitted out: {result['rotation_deg']:.3f}°" if result["rotation_fitted"]
           else "no rotation fitted")
    return "\n".join([
        f"A: {name_a} ({_describe(cal_a)})",
        f"B: {name_b} ({_describe(cal_b)})",
        f"{rot} (over {area})",
        f"difference over {area}, {c['cells']} of {n} cells: median {c['median']:.3f} px, p95 {c['p95']:.3f} px, "
        f"max {c['max']:.3f} px",
        f"difference over the whole image ({w['cells']} cells): median {w['median']:.3f} px, p95 {w['p95']:.3f} px, "
        f"max {w['max']:.3f} px"])


def _short(name) -> str:
    """The file's last two path parts (run1/camera.json): enough to tell two calibrations apart."""
    return "/".join(Path(str(name)).parts[-2:])


def heat_map_png(result: dict, name_a, name_b, *, cbmax: float | None = None) -> bytes:
    """PNG bytes: the difference over the image (px, colour), the covered area outlined."""
    from aicalib_tf.plotting import new_figure, png_bytes

    gx, gy = result["grid"]
    pts = result["points"]
    w = float(pts[:, 0].max() + pts[:, 0].min() + 1)  # cell centres are symmetric about the image centre
    h = float(pts[:, 1].max() + pts[:, 1].min() + 1)
    d = result["diff"].reshape(gy, gx)
    c = result["covered_stats"]
    top = cbmax or (2 * c["p95"] if np.isfinite(c["p95"]) and c["p95"] > 0 else float(np.nanmax(d)) or 1.0)
    fig = new_figure((7.0, 7.0 * h / w + 0.8))
    ax = fig.add_subplot(1, 1, 1)
    im = ax.imshow(np.ma.masked_invalid(d), extent=(-0.5, w - 0.5, h - 0.5, -0.5), cmap="viridis", vmin=0.0,
                   vmax=top, interpolation="nearest")
    cov = result["covered"].reshape(gy, gx).astype(float)
    if 0 < cov.sum() < cov.size:
        ax.contour(pts[:, 0].reshape(gy, gx), pts[:, 1].reshape(gy, gx), cov, levels=[0.5], colors="white",
                   linewidths=1.2)
    fig.colorbar(im, ax=ax, label="projection difference, px", shrink=0.8)
    rot = "rotation fitted" if result["rotation_fitted"] else "no rotation"
    ax.set_title(f"{_short(name_a)} vs {_short(name_b)} ({rot})\n"
                 f"covered area: median {c['median']:.3f} px, p95 {c['p95']:.3f} px", fontsize=9)
    ax.set_xlabel("x, px")
    ax.set_ylabel("y, px")
    return png_bytes(fig)


if __name__ == "__main__":
    raise SystemExit(main())
