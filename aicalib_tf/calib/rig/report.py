"""The rig's printed report and ``report.png``: a rectified preview pair, per-pair epipolar errors, the baseline."""

from __future__ import annotations

import cv2
import numpy as np

from aicalib_tf.calib.report import fov_line
from aicalib_tf.calib.rig.quality import pair_rectification
from aicalib_tf.calib.rig.result import RigCalibration
from aicalib_tf.geometry import lens as L
from aicalib_tf.io import ImageError, load_image, quantize

__all__ = ["format_rig_report", "rig_figure", "rectify_images"]

PREVIEW_LINES = 16  # horizontal lines drawn across the rectified preview


def format_rig_report(rig: RigCalibration, pairing, skipped: dict) -> str:
    """The text the CLI prints. pairing : :class:`~aicalib_tf.calib.rig.workflow.Pairing`; skipped : {"cam/frame": why}."""
    n_img = sum(len(fs) for _, fs in pairing.frames)
    lines = [f"{len(rig.names)} cameras, {len(pairing.frames)} frames ({n_img} images) paired by {pairing.rule}; "
             f"{len(rig.frames)} frames seen by two or more cameras used"]
    for cam, files in pairing.unpaired.items():
        lines.append(f"  unpaired {cam}: {len(files)} image(s) without a partner, used for {cam}'s lens only: "
                     + ", ".join(sorted(files))[:300])
    for name, why in skipped.items():
        lines.append(f"  skipped  {name}: {why}")
    for name, why in rig.rejected.items():
        lines.append(f"  rejected {name}: {why}")
    lines.append(f"joint fit: RMS reprojection error {rig.rms:.3f} px over every camera and frame")
    for name, cal in zip(rig.names, rig.cameras):
        s = cal.std
        lines.append(f"{name}: {cal.image_size[0]}x{cal.image_size[1]} px, {cal.model} (ROS {L.ROS_NAMES[cal.model]}), "
                     f"{len(cal.views)} views, RMS {cal.rms:.3f} px; fx {cal.fx:.2f} ± {s.get('fx', 0):.2f}, "
                     f"fy {cal.fy:.2f} ± {s.get('fy', 0):.2f}, cx {cal.cx:.2f} ± {s.get('cx', 0):.2f}, "
                     f"cy {cal.cy:.2f} ± {s.get('cy', 0):.2f}")
        lines.append(f"  {fov_line(cal)}")
        if rig.meta.get("image_circle_notes", {}).get(name):
            lines.append(f"  {rig.meta['image_circle_notes'][name]}: no image circle, the full frame is used")
        if cal.quality.get("verdict"):
            lines.append(f"  {cal.quality['verdict']}")
    unit = f" {rig.square_unit}" if rig.square_unit else ""
    for k in range(1, len(rig.names)):
        t = rig.T[k]
        lines.append(f"{rig.names[k]} from {rig.names[0]}: T = [{t[0]:.4g}, {t[1]:.4g}, {t[2]:.4g}]{unit}, "
                     f"R = {np.degrees(cv2.Rodrigues(rig.R[k])[0].ravel()).round(4).tolist()} deg (rotation vector)")
    for p in rig.quality.get("pairs", []):
        frames = p["per_frame"]
        worst = max(frames, key=lambda f: frames[f]["in_sample_px"]) if frames else None
        if worst is not None:
            lines.append(f"{p['cameras'][0]}-{p['cameras'][1]}: worst pair {worst}: |Δy| RMS "
                         f"{frames[worst]['in_sample_px']:.3f} px in-sample")
    if rig.quality.get("verdict"):
        lines.append(f"verdict: {rig.quality['verdict']}")
    return "\n".join(lines)


def rectify_images(rig: RigCalibration, images, i: int = 0, j: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """The rectified images (same shape kind as the inputs) of cameras i and j: images = (image_i, image_j)."""
    rect = pair_rectification(rig.lenses, rig.R, rig.T, i, j)
    out = []
    for k, R, P, img in ((i, rect.R1, rect.P1, images[0]), (j, rect.R2, rect.P2, images[1])):
        circle = getattr(rig.cameras[k], "image_circle", None)  # nothing is sampled from outside it
        mx, my = rig.lenses[k].undistort_maps(new_K=P[:, :3], R=R, new_size=rect.size, circle=circle)
        out.append(cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT))
    return out[0], out[1]


def _preview(rig: RigCalibration, pairing):
    """(frame name, rectified image 0, rectified image 1) of the first kept frame both images of which load, or None."""
    files = dict(pairing.frames)
    for name in rig.frames:
        fs = files.get(name, {})
        paths = [fs.get(rig.names[0]), fs.get(rig.names[1])]  # file paths, or (H, W) frames of a video
        if any(p is None for p in paths):
            continue
        try:
            imgs = [quantize(load_image(p)) for p in paths]
        except ImageError:
            continue
        return (name, *rectify_images(rig, imgs))
    return None


def rig_figure(rig: RigCalibration, pairing) -> bytes:
    """``report.png``: the rectified preview pair of cameras 0 and 1 with horizontal lines, per-pair epipolar
    errors (in-sample and held-out, px) for every pair with camera 0, and the baselines and rotations with σ."""
    from aicalib_tf.plotting import new_figure, png_bytes

    fig = new_figure((20, 5.2))
    axes = fig.subplots(1, 3, gridspec_kw={"width_ratios": [2.2, 1.2, 0.8]})
    prev = _preview(rig, pairing)
    ax = axes[0]
    if prev is None:
        ax.text(0.5, 0.5, "no image pair to preview", ha="center", va="center", transform=ax.transAxes)
    else:
        name, a, b = prev
        both = np.concatenate([a, b], axis=1)
        ax.imshow(both, cmap="gray", vmin=0, vmax=255)
        for y in np.linspace(0, both.shape[0] - 1, PREVIEW_LINES + 2)[1:-1]:
            ax.axhline(y, color="lime", lw=0.6)
        ax.set_title(f"rectified {rig.names[0]} | {rig.names[1]}, frame {name}")
    ax.set_axis_off()
    ax = axes[1]
    for p in rig.quality.get("pairs", []):
        frames = list(p["per_frame"])
        x = np.arange(len(frames))
        label = f"{p['cameras'][0]}-{p['cameras'][1]}"
        ax.plot(x, [p["per_frame"][f]["in_sample_px"] for f in frames], "o-", ms=3, label=f"{label} in-sample")
        held = [p["per_frame"][f]["held_out_px"] for f in frames]
        if any(h is not None for h in held):
            ax.plot(x, [np.nan if h is None else h for h in held], "s--", ms=3, label=f"{label} held-out")
        ax.set_xticks(x, frames, rotation=90, fontsize=7)
    ax.set_ylabel("rectified |Δy| RMS per pair (px)")
    ax.set_title("epipolar error per pair")
    ax.legend(fontsize=8)
    ax = axes[2]
    ax.set_axis_off()
    text = []
    for p in rig.quality.get("pairs", []):
        sb = f" ± {p['baseline_std']:.3g}" if p.get("baseline_std") is not None else ""
        sr = f" ± {p['rotation_std_deg']:.2g}" if p.get("rotation_std_deg") is not None else ""
        held = p["held_out_rms_px"]
        text += [f"{p['cameras'][0]} - {p['cameras'][1]}", f"  baseline {p['baseline']:.5g}{sb} {rig.square_unit}",
                 f"  rotation {p['rotation_deg']:.3f}{sr} deg", f"  |Δy| in-sample {p['in_sample_rms_px']:.3f} px",
                 f"  |Δy| held-out {'-' if held is None else f'{held:.3f} px'}", ""]
    ax.text(0.0, 1.0, "\n".join(text), va="top", family="monospace", fontsize=9, transform=ax.transAxes)
    fig.tight_layout()
    return png_bytes(fig, tight=False)
