"""How good is a calibration? Field of view, warnings, the printed report and ``report.png``.

Warnings flag view sets that cannot pin the parameters down (the usual causes of a calibration
that fits its own images but is wrong elsewhere):

* every board nearly fronto-parallel (largest tilt < 15°): focal length and principal point trade
  off against the distance;
* no corner in one of the image's corner regions (the outer 1/4 × 1/4): distortion is
  extrapolated there (a corner region outside a circular fisheye's image circle is passed over:
  no board can reach it; the circle's rim is checked instead, :func:`~aicalib_tf.calib.coverage.rim_gaps`);
* an image circle that the lens model does not agree with
  (:func:`~aicalib_tf.geometry.image_circle.circle_problem`);
* a focal length with a 1σ uncertainty above 1%, or fewer than 6 views;
* an RMS above 1 px (blur, a wrong pattern, or a lens the model cannot describe).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from aicalib_tf.calib import quality as Q
from aicalib_tf.calib.fit import Calibration, View
from aicalib_tf.calib.flex import flex_line
from aicalib_tf.calib.coverage import coverage_counts, in_circle, rim_gaps, uncovered_regions
from aicalib_tf.geometry import lens as L
from aicalib_tf.geometry.image_circle import circle_fov_deg, circle_problem
from aicalib_tf.geometry.aprilgrid import corner_count
from aicalib_tf.geometry.circles import circle_count
from aicalib_tf.geometry.pattern import board_points

__all__ = ["field_of_view", "fov_line", "view_tilts_deg", "coverage_counts", "calibration_warnings", "format_report", "report_figure",
           "uncertainty_map"]


def field_of_view(cal: Calibration) -> tuple[float, float]:
    """(horizontal, vertical) field of view in degrees through the lens model
    (:func:`aicalib_tf.geometry.lens.field_of_view`, within ``cal.image_circle`` when it has one;
    never NaN: an edge pixel with no ray counts with the widest angle the lens images, the valid
    region's diameter)."""
    fov = Q.lens_of(cal).field_of_view(getattr(cal, "image_circle", None))
    return fov["horizontal"], fov["vertical"]


def fov_line(cal: Calibration, views: list[View] | None = None) -> str:
    """The report's field-of-view line: the image circle's diameter in degrees when the calibration
    has one, then horizontal x vertical (marked when an edge lies beyond the model's range).

    The circle's diameter comes from the model (:func:`~aicalib_tf.geometry.image_circle.circle_fov_deg`)
    and is marked as extrapolated when the rim lies beyond the boards' reach: ``cal.quality``'s
    ``boards_reach_deg``, else that of ``views``' corners; past that reach an equidistant model's figure is
    that of the fewest terms the held-out views support (:mod:`aicalib_tf.calib.circle_fov`), the model's
    own beside it.
    """
    lens, circle = Q.lens_of(cal), getattr(cal, "image_circle", None)
    fov = lens.field_of_view(circle)
    text = f"field of view {fov['horizontal']:.1f}° x {fov['vertical']:.1f}° (horizontal x vertical)"
    if fov["beyond_model"]:
        text += f"; the frame's edges lie beyond the model's range (counted at its widest, {np.degrees(lens.max_angle()):.0f}°)"
    if circle is not None:
        fields = getattr(cal, "quality", None) or {}
        if fields.get("boards_reach_deg") is None and views:
            fields = Q.field_of_view_fields(cal, views)
        reach, terms = fields.get("boards_reach_deg"), fields.get("circle_fov_terms")
        across = fields.get("circle_fov_deg") if terms else circle_fov_deg(lens, circle)
        how = (f" through k1..k{terms}, the fewest terms within one standard error held out; the model's own "
               f"{fields['circle_fov_model_deg']:.1f}°" if terms and terms < 4 else "")
        beyond = (f" (beyond the boards' reach, {reach:.0f}° off-axis: extrapolated{how})"
                  if reach is not None and np.isfinite(reach) and across > 2 * reach + 0.05 else "")
        text = (f"field of view {across:.1f}° across the image circle{beyond} (centre {circle.cx:.1f}, "
                f"{circle.cy:.1f}, radius {circle.radius:.1f} px); " + text.removeprefix("field of view "))
    return text


def view_tilts_deg(cal: Calibration) -> np.ndarray:
    """(V,) angle in degrees between each board's normal and the optical axis."""
    out = []
    for r in cal.rvecs:
        R, _ = cv2.Rodrigues(np.asarray(r, np.float64))
        out.append(np.degrees(np.arccos(min(1.0, abs(R[2, 2])))))
    return np.asarray(out)


def calibration_warnings(cal: Calibration, views: list[View]) -> list[str]:
    """Human-readable warnings about how well ``views`` (the used ones) constrain ``cal``."""
    warnings = []
    tilts = view_tilts_deg(cal)
    if tilts.max() < 15.0:
        warnings.append(f"all boards are nearly fronto-parallel (largest tilt {tilts.max():.0f}°): focal length and "
                        "principal point are poorly constrained; add views tilted 30–50°")
    circle = getattr(cal, "image_circle", None)
    if cal.meta.get("image_circle_note"):
        warnings.append(f"{cal.meta['image_circle_note']}: no image circle is used; coverage, uncertainty and "
                        "field of view count the full frame")
    empty = [name for name in uncovered_regions(views, cal.image_size, circle) if "-" in name]
    if empty:
        warnings.append(f"no corners in the image's {', '.join(empty)} region{'s' if len(empty) > 1 else ''}: "
                        "distortion is extrapolated there; add views with the board near the image corners")
    gaps = rim_gaps(views, cal.image_size, circle) if circle is not None else []
    if gaps:
        warnings.append(f"no corners near the image circle's {', '.join(gaps)} rim: distortion is extrapolated "
                        "there; add views with the board near the edge of the image circle")
    corners = np.concatenate([v.corners for v in views]) if views else None
    problem = circle_problem(Q.lens_of(cal), circle, corners) if circle else None
    if problem:
        warnings.append(f"image circle and lens model disagree: {problem}")
    if cal.std.get("fx", 0.0) > 0.01 * cal.fx:
        warnings.append(f"focal length uncertain: fx ± {100 * cal.std['fx'] / cal.fx:.1f}% (1σ)")
    if len(cal.views) < 6:
        warnings.append(f"only {len(cal.views)} views used: 10–20 varied views give a reliable calibration")
    if cal.rms > 1.0:
        warnings.append(f"RMS reprojection error {cal.rms:.2f} px is high: check blur, the pattern size, or try --rational")
    return warnings


def solve_lines(cal: Calibration) -> list[str]:
    """The report's lines on the solve's single-corner rejections and the board flex (:mod:`aicalib_tf.calib.flex`)."""
    out = []
    n = int(getattr(cal, "n_rejected_corners", 0))
    if n:
        per = sorted(cal.rejected_corners.items(), key=lambda kv: -len(kv[1]))
        out.append(f"{n} single corner{'s' if n != 1 else ''} rejected inside the solve (of "
                   f"{int(np.sum(cal.corner_counts))}): " + ", ".join(f"{k} {len(v)}" for k, v in per[:5])
                   + (", ..." if len(per) > 5 else ""))
    line = flex_line(cal)
    return out + ([line] if line else [])


def format_report(cal: Calibration, views: list[View], *, skipped: dict | None = None, total: int | None = None) -> str:
    """The compact text report the CLI prints.

    skipped : {file: reason} for images that gave no view (unreadable, no board).
    total : how many images were given.
    """
    skipped = skipped or {}
    model = Q.lens_of(cal).model
    total = total if total is not None else len(cal.views) + len(cal.rejected) + len(skipped)
    lines = [f"{total} images: {len(cal.views)} used, {len(skipped)} skipped, {len(cal.rejected)} rejected"]
    for name, why in skipped.items():
        lines.append(f"  skipped  {name}: {why}")
    for name, why in cal.rejected.items():
        lines.append(f"  rejected {name}: {why}")
    worst, worst_rms = cal.worst_view()
    board = (cal.meta or {}).get("board")
    full = corner_count(board) or circle_count(board) or cal.pattern_size[0] * cal.pattern_size[1]  # sparse lattices
    partial = int(np.sum(cal.corner_counts < full))
    used = set(cal.views)
    relative = sum(1 for v in views if getattr(v, "relative", False) and v.name in used)
    lines.append(f"RMS reprojection error {cal.rms:.3f} px (worst view {worst}: {worst_rms:.3f} px)"
                 + (f"; {partial} partial board{'s' if partial != 1 else ''}" if partial else "")
                 + (f" ({relative} larger than the frame, ids relative to what is seen)" if relative else ""))
    lines.extend(solve_lines(cal))
    s = Q.honest_std(cal)
    names_in = "ROS " if L.get_model(model).NAMES["opencv"] else "files: no OpenCV or ROS name, "
    lines.append(f"image {cal.image_size[0]}x{cal.image_size[1]} px, lens model {model} ({names_in}{L.ROS_NAMES[model]})")
    lines.extend(_model_table_lines(getattr(cal, "model_table", ()) or ()))
    lines.append(f"fx = {cal.fx:.2f} ± {s.get('fx', 0):.2f}   fy = {cal.fy:.2f} ± {s.get('fy', 0):.2f}   (px)")
    lines.append(f"cx = {cal.cx:.2f} ± {s.get('cx', 0):.2f}   cy = {cal.cy:.2f} ± {s.get('cy', 0):.2f}   (px)")
    names = L.COEFF_NAMES[Q.lens_of(cal).model]
    lines.append("dist: " + "  ".join(f"{n} = {v:+.5f} ± {s.get(n, 0):.5f}" for n, v in zip(names, cal.dist)))
    lines.append(fov_line(cal, views))
    for w in calibration_warnings(cal, views):
        lines.append(f"warning: {w}")
    quality = getattr(cal, "quality", None) or Q.assess(cal, views)
    lines.append(f"verdict: {quality['verdict']}")
    return "\n".join(lines)


def _model_table_lines(table) -> list[str]:
    """The model-choice table (rows {"model", "n_params", "rms", "cv_rms", "cv_se", "chosen", "note"}) as text."""
    if not table:
        return []
    out = ["model choice (held-out views):", f"  {'model':<20s} {'params':>6s} {'RMS':>7s} {'CV RMS':>14s}"]
    for row in table:
        cv = row.get("cv_rms")
        cv_txt = "-" if cv is None or not np.isfinite(cv) else f"{cv:.3f} ± {row.get('cv_se', float('nan')):.3f}"
        rms = row.get("rms")
        rms_txt = "-" if rms is None or not np.isfinite(rms) else f"{rms:.3f}"
        out.append(f"{'*' if row.get('chosen') else ' '} {row.get('model', '?'):<20s} {row.get('n_params', 0):>6d} "
                   f"{rms_txt:>7s} {cv_txt:>14s}" + (f"  {row['note']}" if row.get("note") else ""))
    return out


def uncertainty_map(cal: Calibration, views: list[View], grid=(32, 24)) -> tuple[np.ndarray, np.ndarray] | None:
    """(points (gy·gx, 2) px, sigma (gy, gx) px 1σ) of :func:`~aicalib_tf.calib.quality.projection_uncertainty`
    with :func:`~aicalib_tf.calib.quality.honest_covariance` (``cal.covariance``, or one computed from ``views``,
    with the views as the independent units), the rotation fitted over the covered cells; None when no
    covariance can be had."""
    covered = coverage_counts(views, cal.image_size, grid).ravel() > 0
    try:
        cov = Q.honest_covariance(cal, views, covered, grid)[0]
    except (ValueError, np.linalg.LinAlgError):
        return None
    pts, sigma = Q.projection_uncertainty(cal, grid, covariance=cov, fit_mask=covered)
    return pts, sigma.reshape(grid[1], grid[0])


def report_figure(cal: Calibration, views: list[View]) -> bytes:
    """``report.png`` as PNG bytes: per-view RMS bars, residual vectors, corner coverage and the
    projection uncertainty map (px, 1σ, :func:`uncertainty_map`; an empty panel without one).

    views : the used views, in ``cal.views`` order.
    """
    from aicalib_tf.plotting import new_figure, png_bytes

    w, h = cal.image_size
    fig = new_figure((22, 4.8))
    axes = fig.subplots(1, 4, gridspec_kw={"width_ratios": [1.1, 1, 1, 1]})
    ax = axes[0]
    order = np.arange(len(cal.views))
    ax.bar(order, cal.per_view_rms, color="tab:blue")
    ax.axhline(cal.rms, color="k", ls="--", lw=1, label=f"overall RMS {cal.rms:.3f} px")
    ax.set_xticks(order, [Path(n).stem[:18] for n in cal.views], rotation=90, fontsize=7)
    ax.set_ylabel("RMS reprojection error (px)")
    ax.set_title(f"per-view error ({len(cal.views)} used, {len(cal.rejected)} rejected)")
    ax.legend(fontsize=8)

    _draw_residuals(fig, axes[1], cal, views)

    ax = axes[2]
    cov = coverage_counts(views, cal.image_size).astype(np.float64)
    inside = in_circle(cal.image_size, cov.shape[::-1], getattr(cal, "image_circle", None)).reshape(cov.shape)
    share = float(np.mean(cov[inside] > 0)) if inside.any() else 0.0
    cov[~inside & (cov == 0)] = np.nan  # outside the image circle: not missing, left blank
    im = ax.imshow(cov, extent=(-0.5, w - 0.5, h - 0.5, -0.5), cmap="magma", interpolation="nearest")
    fig.colorbar(im, ax=ax, fraction=0.04, label="corners per cell")
    where = "the circle's cells" if getattr(cal, "image_circle", None) else "cells"
    ax.set_title(f"corner coverage ({100 * share:.0f}% of {where})")
    _draw_circle(ax, cal)
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    _draw_uncertainty(fig, axes[3], cal, views)
    fig.tight_layout()
    return png_bytes(fig, tight=False)


def _draw_uncertainty(fig, ax, cal: Calibration, views: list[View]) -> None:
    """The 1σ projection uncertainty (px) as an image with a colour bar and labelled contours."""
    w, h = cal.image_size
    found = uncertainty_map(cal, views)
    if found is None:
        ax.text(0.5, 0.5, "no covariance: uncertainty unknown", ha="center", va="center", transform=ax.transAxes)
        ax.set_axis_off()
        return
    pts, sigma = found
    im = ax.imshow(sigma, extent=(-0.5, w - 0.5, h - 0.5, -0.5), cmap="viridis", interpolation="bilinear")
    fig.colorbar(im, ax=ax, fraction=0.04, label="projection uncertainty, px (1σ)")
    finite = sigma[np.isfinite(sigma)]
    if finite.size and finite.max() > finite.min():
        levels = np.unique(np.quantile(finite, [0.25, 0.5, 0.75, 0.95]))
        xs, ys = pts[:, 0].reshape(sigma.shape), pts[:, 1].reshape(sigma.shape)
        cs = ax.contour(xs, ys, sigma, levels=levels, colors="w", linewidths=0.8)
        ax.clabel(cs, fmt="%.2g", fontsize=7)
    _draw_circle(ax, cal)
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    ax.set_aspect("equal")
    ax.set_title(f"projection uncertainty (median {np.nanmedian(sigma):.3g} px)")


def _draw_circle(ax, cal: Calibration) -> None:
    """The image circle's outline (dashed), when the calibration has one."""
    c = getattr(cal, "image_circle", None)
    if c is not None:
        a = np.linspace(0, 2 * np.pi, 181)
        ax.plot(c.cx + c.radius * np.cos(a), c.cy + c.radius * np.sin(a), "c--", lw=0.8)


def _draw_residuals(fig, ax, cal: Calibration, views: list[View]) -> None:
    """Residual vectors (detected − projected, scaled up) of every used corner, coloured by length (px)."""
    w, h = cal.image_size
    lens = Q.lens_of(cal)
    pts, res = [], []
    for v, r, t in zip(views, cal.rvecs, cal.tvecs):
        R, _ = cv2.Rodrigues(np.asarray(r, np.float64).reshape(3, 1))
        pts.append(v.corners)
        res.append(v.corners - lens.project(board_points(v.ids, cal.square_size) @ R.T + np.ravel(t)))
    pts, res = np.concatenate(pts), np.concatenate(res)
    keep = np.all(np.isfinite(res), axis=1)
    pts, res = pts[keep], res[keep]
    mag = np.linalg.norm(res, axis=1)
    scale = 0.05 * max(w, h) / max(float(np.percentile(mag, 95)), 1e-6)
    ax.quiver(pts[:, 0], pts[:, 1], res[:, 0] * scale, res[:, 1] * scale, mag, angles="xy", scale_units="xy",
              scale=1, cmap="viridis", width=0.003)
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_aspect("equal")
    ax.set_title(f"residuals (detected − projected), ×{scale:.0f}")
