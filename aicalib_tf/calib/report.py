"""How good is a calibration? Field of view, warnings, the printed report and ``report.png``.

Warnings flag view sets that cannot pin the parameters down (the usual causes of a calibration
that fits its own images but is wrong elsewhere):

* every board nearly fronto-parallel (largest tilt < 15°): focal length and principal point trade
  off against the distance;
* no corner in one of the image's corner regions (the outer 1/4 × 1/4): distortion is
  extrapolated there;
* a focal length with a 1σ uncertainty above 1%, or fewer than 6 views;
* an RMS above 1 px (blur, a wrong pattern, or a lens the model cannot describe).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from aicalib_tf.calib.fit import Calibration, View, view_rms
from aicalib_tf.geometry.camera import normalized_rays

__all__ = ["field_of_view", "view_tilts_deg", "coverage_counts", "calibration_warnings", "format_report", "report_figure"]

def field_of_view(cal: Calibration) -> tuple[float, float]:
    """(horizontal, vertical) field of view in degrees, through the lens model.

    The rays of the left/right (top/bottom) edge midpoints, undistorted. Falls back to the
    pinhole value 2·atan(w / 2f) where the inverse distortion does not converge.
    """
    w, h = cal.image_size
    pts = np.array([[0.0, cal.cy], [w - 1.0, cal.cy], [cal.cx, 0.0], [cal.cx, h - 1.0]])
    norm, ok = normalized_rays(pts, cal.K, cal.dist, tol_px=1e-2)
    if ok.all():
        hfov = np.degrees(np.arctan(norm[1, 0]) - np.arctan(norm[0, 0]))
        vfov = np.degrees(np.arctan(norm[3, 1]) - np.arctan(norm[2, 1]))
    else:
        hfov = 2 * np.degrees(np.arctan(w / (2 * cal.fx)))
        vfov = 2 * np.degrees(np.arctan(h / (2 * cal.fy)))
    return float(hfov), float(vfov)


def view_tilts_deg(cal: Calibration) -> np.ndarray:
    """(V,) angle in degrees between each board's normal and the optical axis."""
    out = []
    for r in cal.rvecs:
        R, _ = cv2.Rodrigues(np.asarray(r, np.float64))
        out.append(np.degrees(np.arccos(min(1.0, abs(R[2, 2])))))
    return np.asarray(out)


def coverage_counts(views: list[View], image_size: tuple[int, int], cells: tuple[int, int] = (16, 12)) -> np.ndarray:
    """(cells_y, cells_x) int: how many detected corners fall in each cell of the image."""
    w, h = image_size
    pts = np.concatenate([v.corners for v in views]) if views else np.zeros((0, 2))
    counts, _, _ = np.histogram2d(pts[:, 1], pts[:, 0], bins=(cells[1], cells[0]), range=((-0.5, h - 0.5), (-0.5, w - 0.5)))
    return counts.astype(np.int64)


def calibration_warnings(cal: Calibration, views: list[View]) -> list[str]:
    """Human-readable warnings about how well ``views`` (the used ones) constrain ``cal``."""
    warnings = []
    tilts = view_tilts_deg(cal)
    if tilts.max() < 15.0:
        warnings.append(f"all boards are nearly fronto-parallel (largest tilt {tilts.max():.0f}°): focal length and "
                        "principal point are poorly constrained; add views tilted 30–50°")
    cov = coverage_counts(views, cal.image_size, (4, 4))
    empty = [name for name, c in (("top-left", cov[0, 0]), ("top-right", cov[0, -1]),
                                  ("bottom-left", cov[-1, 0]), ("bottom-right", cov[-1, -1])) if c == 0]
    if empty:
        warnings.append(f"no corners in the image's {', '.join(empty)} region{'s' if len(empty) > 1 else ''}: "
                        "distortion is extrapolated there; add views with the board near the image corners")
    if cal.std.get("fx", 0.0) > 0.01 * cal.fx:
        warnings.append(f"focal length uncertain: fx ± {100 * cal.std['fx'] / cal.fx:.1f}% (1σ)")
    if len(cal.views) < 6:
        warnings.append(f"only {len(cal.views)} views used: 10–20 varied views give a reliable calibration")
    if cal.rms > 1.0:
        warnings.append(f"RMS reprojection error {cal.rms:.2f} px is high: check blur, the pattern size, or try --rational")
    return warnings


def format_report(cal: Calibration, views: list[View], *, skipped: dict | None = None, total: int | None = None) -> str:
    """The compact text report the CLI prints.

    skipped : {file: reason} for images that gave no view (unreadable, no board).
    total : how many images were given.
    """
    skipped = skipped or {}
    total = total if total is not None else len(cal.views) + len(cal.rejected) + len(skipped)
    lines = [f"{total} images: {len(cal.views)} used, {len(skipped)} skipped, {len(cal.rejected)} rejected"]
    for name, why in skipped.items():
        lines.append(f"  skipped  {name}: {why}")
    for name, why in cal.rejected.items():
        lines.append(f"  rejected {name}: {why}")
    worst, worst_rms = cal.worst_view()
    partial = int(np.sum(cal.corner_counts < cal.pattern_size[0] * cal.pattern_size[1]))
    lines.append(f"RMS reprojection error {cal.rms:.3f} px (worst view {worst}: {worst_rms:.3f} px)"
                 + (f"; {partial} partial board{'s' if partial != 1 else ''}" if partial else ""))
    s = cal.std
    lines.append(f"image {cal.image_size[0]}x{cal.image_size[1]} px")
    lines.append(f"fx = {cal.fx:.2f} ± {s.get('fx', 0):.2f}   fy = {cal.fy:.2f} ± {s.get('fy', 0):.2f}   (px)")
    lines.append(f"cx = {cal.cx:.2f} ± {s.get('cx', 0):.2f}   cy = {cal.cy:.2f} ± {s.get('cy', 0):.2f}   (px)")
    names = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")[: len(cal.dist)]
    lines.append("dist: " + "  ".join(f"{n} = {v:+.5f} ± {s.get(n, 0):.5f}" for n, v in zip(names, cal.dist)))
    hfov, vfov = field_of_view(cal)
    lines.append(f"field of view {hfov:.1f}° x {vfov:.1f}° (horizontal x vertical)")
    for w in calibration_warnings(cal, views):
        lines.append(f"warning: {w}")
    return "\n".join(lines)


def report_figure(cal: Calibration, views: list[View]) -> bytes:
    """``report.png`` as PNG bytes: per-view RMS bars, residual vectors, corner coverage.

    views : the used views, in ``cal.views`` order.
    """
    from aicalib_tf.plotting import new_figure, png_bytes

    w, h = cal.image_size
    fig = new_figure((17, 4.8))
    axes = fig.subplots(1, 3, gridspec_kw={"width_ratios": [1.1, 1, 1]})
    ax = axes[0]
    order = np.arange(len(cal.views))
    ax.bar(order, cal.per_view_rms, color="tab:blue")
    ax.axhline(cal.rms, color="k", ls="--", lw=1, label=f"overall RMS {cal.rms:.3f} px")
    ax.set_xticks(order, [Path(n).stem[:18] for n in cal.views], rotation=90, fontsize=7)
    ax.set_ylabel("RMS reprojection error (px)")
    ax.set_title(f"per-view error ({len(cal.views)} used, {len(cal.rejected)} rejected)")
    ax.legend(fontsize=8)

    ax = axes[1]
    pts, res = [], []
    for v, r, t in zip(views, cal.rvecs, cal.tvecs):
        _, d = view_rms(v, cal.K, cal.dist, r, t, cal.square_size)
        pts.append(v.corners)
        res.append(d)
    pts, res = np.concatenate(pts), np.concatenate(res)
    mag = np.linalg.norm(res, axis=1)
    scale = 0.05 * max(w, h) / max(float(np.percentile(mag, 95)), 1e-6)
    ax.quiver(pts[:, 0], pts[:, 1], res[:, 0] * scale, res[:, 1] * scale, mag, angles="xy", scale_units="xy",
              scale=1, cmap="viridis", width=0.003)
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_aspect("equal")
    ax.set_title(f"residuals (detected − projected), ×{scale:.0f}")

    ax = axes[2]
    cov = coverage_counts(views, cal.image_size)
    im = ax.imshow(cov, extent=(-0.5, w - 0.5, h - 0.5, -0.5), cmap="magma", interpolation="nearest")
    fig.colorbar(im, ax=ax, fraction=0.04, label="corners per cell")
    ax.set_title(f"corner coverage ({100 * np.mean(cov > 0):.0f}% of cells)")
    fig.tight_layout()
    return png_bytes(fig, tight=False)
