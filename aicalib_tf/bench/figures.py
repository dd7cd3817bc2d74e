"""The benchmark report's figures (matplotlib Agg), each written atomically as PNG bytes.

:func:`sweep_figure` (detection rate and corner error along a severity sweep),
:func:`error_histogram` (corner errors of hits), :func:`time_figure` (time per image, per size) and
:func:`example_figure` (one image with each detector's corners); :mod:`aicalib_tf.bench.report`
writes the page that links them.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from aicalib_tf.bench.metrics import WRONG_PX
from aicalib_tf.io import atomic_write_bytes
from aicalib_tf.plotting import new_figure, png_bytes

__all__ = ["SWEEP_AXES", "error_histogram", "example_figure", "sweep_figure", "time_figure"]

SWEEP_AXES = {"noise": ("Gaussian noise σ (grey levels)", False), "blur": ("Gaussian blur σ (px)", False),
              "contrast": ("contrast factor (1 = full)", True), "jpeg": ("JPEG quality", True),
              "distortion": ("lens distortion k1 (median of the images)", True),
              "tilt": ("board tilt (median, degrees)", False)}


def _save_fig(fig, path: Path) -> None:
    atomic_write_bytes(path, png_bytes(fig))


def sweep_figure(summary: pd.DataFrame, sweep: str, path: Path) -> None:
    s = summary[summary["sweep"] == sweep].sort_values("severity")
    label, invert = SWEEP_AXES.get(sweep, (sweep, False))
    fig = new_figure((10, 3.6))
    a1, a2 = fig.subplots(1, 2)
    for k, (det, g) in enumerate(s.groupby("detector", sort=False)):
        style = dict(marker="os^vD"[k % 5], ls=("-", "--", "-.", ":")[k % 4], ms=6 - k, label=det)
        a1.plot(g["severity"], 100 * g["detection_rate"], **style)
        a2.plot(g["severity"], g["err_median"], **style)
    a1.set(xlabel=label, ylabel="full boards found correctly (%)", ylim=(-3, 103), title=f"{sweep}: detection rate")
    a2.set(xlabel=label, ylabel="median corner error of hits (px)", yscale="log", title=f"{sweep}: corner error")
    for a in (a1, a2):
        a.grid(alpha=0.3)
        if invert:
            a.invert_xaxis()
    a1.legend(fontsize=8)
    _save_fig(fig, path)


def error_histogram(errors: dict, named: set, path: Path) -> None:
    fig = new_figure((7, 3.6))
    ax = fig.subplots()
    bins = np.logspace(-4, math.log10(WRONG_PX), 50)
    dets = sorted({d for _, d in errors}, key=list({d: 0 for _, d in errors}).index)
    for det in dets:
        e = [x for (c, d), arrs in errors.items() if d == det and c in named for x in arrs]
        e = np.concatenate(e) if e else np.zeros(0)
        if e.size:
            ax.hist(np.clip(e, 1e-4, None), bins=bins, histtype="step", lw=1.5, label=f"{det} ({e.size} corners)")
    ax.set(xscale="log", xlabel="corner error (px)", ylabel="corners",
           title="Corner errors: hits and correct partial corners (named conditions, calibration views)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    _save_fig(fig, path)


def time_figure(results: pd.DataFrame, path: Path) -> None:
    sizes = sorted({(int(w), int(h)) for w, h in zip(results["width"], results["height"])})
    dets = list(dict.fromkeys(results["detector"]))
    fig = new_figure((4.5 * len(sizes), 3.6))
    axes = fig.subplots(1, len(sizes), squeeze=False)
    for ax, (w, h) in zip(axes[0], sizes):
        g = results[(results["width"] == w) & (results["height"] == h)]
        data = [g.loc[g["detector"] == d, "time_ms"].to_numpy() for d in dets]
        ax.boxplot(data, whis=(0, 100))
        ax.set_xticks(range(1, len(dets) + 1), dets)
        ax.set(yscale="log", ylabel="ms per image", title=f"{w}×{h}: time per image ({len(g) // max(1, len(dets))} images)")
        ax.grid(alpha=0.3, axis="y")
    _save_fig(fig, path)


def example_figure(title: str, image: np.ndarray, truth, found_by: dict, path: Path) -> None:
    n = len(found_by)
    fig = new_figure((4.2 * n, 3.6))
    axes = fig.subplots(1, n, squeeze=False)
    for ax, (det, (found, outcome)) in zip(axes[0], found_by.items()):
        ax.imshow(image, cmap="gray", vmin=0, vmax=255)
        if truth is not None and len(truth):
            ax.plot(truth[:, 0], truth[:, 1], "+", color="cyan", ms=4, mew=0.8)
        c = found.corners
        if len(c):
            colour = {"hit": "lime", "partial": "yellow"}.get(outcome, "red")
            ax.plot(c[:, 0], c[:, 1], "o", mfc="none", mec=colour, ms=5, mew=1.0)
            ax.plot(c[:1, 0], c[:1, 1], "s", mfc="none", mec="magenta", ms=7)
        ax.set_title(f"{det}: {outcome} ({len(c)} corners)", fontsize=9)
        ax.axis("off")
    fig.suptitle(title + "  (cyan +: truth/reference; circles: detected, red = wrong/false)", fontsize=9)
    _save_fig(fig, path)
