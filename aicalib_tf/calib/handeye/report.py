"""A hand-eye calibration's report.png: per-view residuals, robot residuals, the frames in 3D (matplotlib).

Panels: each used view's RMS reprojection error (px); each view's robot residual, the distance
between the reported flange pose and the one its image implies (mm, with degrees on a second
axis); and the scene in the base frame: the base's axes, every flange position, the camera (one
per view when it rides on the flange) and the board, drawn as axes of 5 cm (x red, y green, z blue).
"""

from __future__ import annotations

import numpy as np

__all__ = ["report_figure", "scene_frames"]

_AXIS = 0.05  # metres


def scene_frames(result) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(cameras (V or 1, 4, 4), boards (1 or V, 4, 4), flanges (V, 4, 4)), all T_base_*."""
    A = np.asarray(result.A)
    if result.setup == "eye-in-hand":
        return A @ result.X[None], result.Y[None], A
    return result.X[None], A @ result.Y[None], A


def _axes(ax, T, length: float = _AXIS, lw: float = 1.0) -> None:
    o = T[:3, 3]
    for k, c in enumerate("rgb"):
        e = o + length * T[:3, k]
        ax.plot([o[0], e[0]], [o[1], e[1]], [o[2], e[2]], color=c, lw=lw)


def _board_outline(ax, T, size_m) -> None:
    w, h = size_m
    pts = np.array([[0, 0, 0, 1], [w, 0, 0, 1], [w, h, 0, 1], [0, h, 0, 1], [0, 0, 0, 1]], float) @ T.T
    ax.plot(pts[:, 0], pts[:, 1], pts[:, 2], color="k", lw=0.8)


def _equal(ax, pts) -> None:
    lo, hi = pts.min(0), pts.max(0)
    c, r = (lo + hi) / 2, max((hi - lo).max() / 2, 0.1)
    ax.set_xlim(c[0] - r, c[0] + r)
    ax.set_ylim(c[1] - r, c[1] + r)
    ax.set_zlim(c[2] - r, c[2] + r)


def report_figure(result, board_size_m=(0.3, 0.2)) -> bytes:
    """report.png's bytes. board_size_m : (width, height) of the inner-corner grid, metres."""
    from aicalib_tf.plotting import new_figure, png_bytes

    fig = new_figure((13, 4.2))
    names = list(result.views)
    x = np.arange(len(names))
    a1 = fig.add_subplot(1, 3, 1)
    a1.bar(x, result.per_view_rms, color="tab:blue")
    a1.set_title(f"RMS per view (all views {result.rms:.3f} px)", fontsize=9)
    a1.set_ylabel("px")
    a1.set_xticks(x, names, rotation=90, fontsize=6)
    a2 = fig.add_subplot(1, 3, 2)
    a2.bar(x - 0.2, result.robot_mm, width=0.4, color="tab:orange", label="mm")
    a2.set_ylabel("mm", color="tab:orange")
    a2b = a2.twinx()
    a2b.bar(x + 0.2, result.robot_deg, width=0.4, color="tab:green", label="deg")
    a2b.set_ylabel("degrees", color="tab:green")
    a2.set_title("robot residual: mm (orange), degrees (green)", fontsize=9)
    a2.set_xticks(x, names, rotation=90, fontsize=6)
    a3 = fig.add_subplot(1, 3, 3, projection="3d")
    cams, boards, flanges = scene_frames(result)
    _axes(a3, np.eye(4), 2 * _AXIS, 2.0)
    a3.scatter(flanges[:, 0, 3], flanges[:, 1, 3], flanges[:, 2, 3], s=6, color="0.4", label="flange")
    for T in cams:
        _axes(a3, T)
    for T in boards:
        _board_outline(a3, T, board_size_m)
    a3.scatter(cams[:, 0, 3], cams[:, 1, 3], cams[:, 2, 3], s=10, color="tab:purple", label="camera")
    _equal(a3, np.concatenate([np.zeros((1, 3)), cams[:, :3, 3], boards[:, :3, 3], flanges[:, :3, 3]]))
    a3.set_title(f"{result.setup} (base frame, m)")
    a3.legend(fontsize=7, loc="upper left")
    return png_bytes(fig)
