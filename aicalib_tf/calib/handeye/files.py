"""A hand-eye calibration's files: handeye.json, handeye.yaml, the ROS static-transform lines, report text.

* ``handeye.json`` (strict JSON, :mod:`aicalib_tf.jsonio`): ``setup``; the two transforms under their
  frame names (eye-in-hand ``T_flange_camera`` and ``T_base_board``; eye-to-hand ``T_base_camera``
  and ``T_flange_board``), each with ``matrix`` (4×4, metres), ``translation_m``, ``quaternion_xyzw``,
  ``covariance`` (6×6 over tx, ty, tz in metres then rx, ry, rz in radians, a small rotation in the
  parent frame), ``sigma_mm`` and ``sigma_deg``; the camera; the robot's σ; per used view its RMS
  (px), the robot residual (how far the reported flange pose is from the one the image implies,
  mm and degrees) and the fit's correction of it; rejected views and unmatched images and pose rows
  with reasons; the verdict; the ROS lines.
* ``handeye.yaml``: the same transforms, σ and camera as OpenCV FileStorage nodes.
* ``static_transform.txt``: per transform ``parent child x y z qx qy qz qw`` and the matching
  ``ros2 run tf2_ros static_transform_publisher`` command.
"""

from __future__ import annotations

import time
from pathlib import Path

import cv2
import numpy as np

from aicalib_tf.geometry.transform import matrix_to_quat

__all__ = ["transform_names", "ros_line", "ros_command", "handeye_dict", "to_opencv_yaml", "static_transform_text",
           "format_report", "partial_dict", "write_handeye_files"]

COVARIANCE_ORDER = "tx ty tz (m), rx ry rz (rad, a small rotation in the parent frame)"


def transform_names(result) -> tuple[str, str]:
    """('T_flange_camera', 'T_base_board') or ('T_base_camera', 'T_flange_board')."""
    (xp, xc), (yp, yc) = result.names
    return f"T_{xp}_{xc}", f"T_{yp}_{yc}"


def ros_line(T, parent: str, child: str) -> str:
    """``parent child x y z qx qy qz qw`` (metres, quaternion x y z w)."""
    q = matrix_to_quat(T[:3, :3])
    return " ".join([parent, child] + [f"{v:.6f}" for v in T[:3, 3]] + [f"{v:.9f}" for v in q])


def ros_command(T, parent: str, child: str) -> str:
    """The ROS 2 static_transform_publisher command for T_parent_child."""
    q = matrix_to_quat(T[:3, :3])
    xyz = " ".join(f"--{k} {v:.6f}" for k, v in zip("xyz", T[:3, 3]))
    quat = " ".join(f"--{k} {v:.9f}" for k, v in zip(("qx", "qy", "qz", "qw"), q))
    return f"ros2 run tf2_ros static_transform_publisher {xyz} {quat} --frame-id {parent} --child-frame-id {child}"


def _transform(T, cov) -> dict:
    s = np.sqrt(np.maximum(np.diag(cov), 0.0))
    return {"matrix": np.asarray(T).tolist(), "translation_m": T[:3, 3].tolist(),
            "quaternion_xyzw": matrix_to_quat(T[:3, :3]).tolist(), "covariance": np.asarray(cov).tolist(),
            "covariance_order": COVARIANCE_ORDER, "sigma_mm": (1e3 * s[:3]).tolist(),
            "sigma_deg": np.degrees(s[3:]).tolist()}


def _views(result) -> list[dict]:
    return [{"image": n, "rms_px": float(result.per_view_rms[k]), "robot_residual_deg": float(result.robot_deg[k]),
             "robot_residual_mm": float(result.robot_mm[k]), "correction_deg": float(result.correction_deg[k]),
             "correction_mm": float(result.correction_mm[k]), "T_base_flange": result.A[k].tolist()}
            for k, n in enumerate(result.views)]


def handeye_dict(result, *, board: dict | None = None, unmatched_images=(), unmatched_poses=(), meta=None) -> dict:
    """handeye.json's content (module docstring)."""
    xn, yn = transform_names(result)
    (xp, xc), (yp, yc) = result.names
    lens = result.lens
    return {
        "setup": result.setup, "status": result.quality.get("status", "ok"),
        xn: _transform(result.X, result.cov_X), yn: _transform(result.Y, result.cov_Y),
        "frames": {xn: [xp, xc], yn: [yp, yc]},
        "camera": {**lens.to_dict(), "fitted": result.intrinsics_fitted},
        "board": board or {},
        "robot_sigma": {"rotation_deg": result.sigma_rot_deg, "translation_mm": result.sigma_t_mm},
        "sigma_px": result.sigma_px, "rms_px": result.rms, "chi2": result.chi2,
        "robot_residual_median": {"deg": float(np.median(result.robot_deg)), "mm": float(np.median(result.robot_mm))},
        "views": _views(result),
        "rejected": [{"image": k, "reason": v} for k, v in result.rejected.items()],
        "unmatched_images": list(unmatched_images), "unmatched_poses": list(unmatched_poses),
        "quality": result.quality,
        "ros_static_transform": [ros_line(result.X, xp, xc), ros_line(result.Y, yp, yc)],
        "meta": meta or {},
    }


def partial_dict(error: str, *, setup: str, rejected: dict, unmatched_images=(), unmatched_poses=(), lens=None) -> dict:
    """handeye.json of a failed fit (written only with --save-partial)."""
    return {"setup": setup, "status": "failed", "error": error, "camera": lens.to_dict() if lens is not None else None,
            "rejected": [{"image": k, "reason": v} for k, v in rejected.items()],
            "unmatched_images": list(unmatched_images), "unmatched_poses": list(unmatched_poses)}


def to_opencv_yaml(result) -> str:
    """The transforms, their covariance and the camera as OpenCV FileStorage YAML."""
    xn, yn = transform_names(result)
    fs = cv2.FileStorage("handeye.yaml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    fs.write("calibration_time", time.strftime("%Y-%m-%d %H:%M:%S"))
    fs.write("setup", result.setup)
    for name, T, cov in ((xn, result.X, result.cov_X), (yn, result.Y, result.cov_Y)):
        fs.write(name, np.asarray(T, np.float64))
        fs.write(f"{name}_covariance", np.asarray(cov, np.float64))
    fs.write("covariance_order", COVARIANCE_ORDER)
    fs.write("image_width", int(result.lens.image_size[0]))
    fs.write("image_height", int(result.lens.image_size[1]))
    fs.write("camera_matrix", np.asarray(result.lens.K, np.float64))
    fs.write("distortion_model", result.lens.model)
    fs.write("distortion_coefficients", np.asarray(result.lens.dist, np.float64).reshape(1, -1))
    fs.write("rms_px", float(result.rms))
    fs.write("nr_of_views", len(result.views))
    return fs.releaseAndGetString()


def static_transform_text(result) -> str:
    """static_transform.txt (module docstring)."""
    (xp, xc), (yp, yc) = result.names
    lines = ["# parent child x y z qx qy qz qw (metres; quaternion x y z w)",
             ros_line(result.X, xp, xc), ros_line(result.Y, yp, yc), "",
             ros_command(result.X, xp, xc), ros_command(result.Y, yp, yc)]
    return "\n".join(lines) + "\n"


def _pose_line(name: str, T, cov) -> str:
    s = np.sqrt(np.maximum(np.diag(cov), 0.0))
    t, st = 1e3 * T[:3, 3], 1e3 * s[:3]
    q = matrix_to_quat(T[:3, :3])
    return (f"{name}: t = [{t[0]:.2f}, {t[1]:.2f}, {t[2]:.2f}] mm ± [{st[0]:.3f}, {st[1]:.3f}, {st[2]:.3f}]; "
            f"q (x y z w) = [{q[0]:.5f}, {q[1]:.5f}, {q[2]:.5f}, {q[3]:.5f}] ± "
            f"[{', '.join(f'{v:.4f}' for v in np.degrees(s[3:]))}]°")


def format_report(result, *, total: int, skipped: dict | None = None, unmatched_images=(), unmatched_poses=()) -> str:
    """The compact report the command line prints."""
    xn, yn = transform_names(result)
    q = result.quality
    lines = [f"hand-eye ({result.setup}): {len(result.views)} of {total} images used"]
    for what, items in (("skipped", skipped or {}), ("rejected", result.rejected)):
        for name, why in items.items():
            lines.append(f"  {what}: {name}: {why}")
    if unmatched_images:
        lines.append(f"  no robot pose for {len(unmatched_images)} image(s): {', '.join(list(unmatched_images)[:8])}")
    if unmatched_poses:
        lines.append(f"  {len(unmatched_poses)} pose row(s) match no image: {', '.join(list(unmatched_poses)[:8])}")
    lens = result.lens
    lines.append(f"camera: {lens.model}, fx {lens.fx:.2f} fy {lens.fy:.2f} cx {lens.cx:.2f} cy {lens.cy:.2f} px "
                 f"({'fitted with the hand-eye transform' if result.intrinsics_fitted else 'held fixed'})")
    lines.append(f"RMS {result.rms:.3f} px (corner noise σ {result.sigma_px:.3f} px); robot residual median "
                 f"{np.median(result.robot_mm):.3f} mm, {np.median(result.robot_deg):.4f}° "
                 f"(stated σ {result.sigma_t_mm:g} mm, {result.sigma_rot_deg:g}° per axis)")
    lines.append(_pose_line(xn, result.X, result.cov_X))
    lines.append(_pose_line(yn, result.Y, result.cov_Y))
    sp = q.get("spread", {})
    if sp:
        lines.append(f"rotation spread: {', '.join(f'{v:.1f}' for v in sp['rms_deg'])}° RMS about the {sp['frame']}'s "
                     "principal axes")
    h = q.get("halves", {})
    if "diff_deg" in h:
        lines.append(f"halves ({h['views'][0]} + {h['views'][1]} views): differ by {h['diff_deg']:.4f}° and "
                     f"{h['diff_mm']:.3f} mm ({'agree' if h['agree'] else 'DISAGREE'}, d² {h['d2']:.1f})")
    elif h.get("note"):
        lines.append(f"halves: {h['note']}")
    lines.append(f"verdict: {q.get('status', 'ok')}")
    lines += [f"  warning: {w}" for w in q.get("warnings", [])]
    (xp, xc), (yp, yc) = result.names
    lines.append(f"ROS: {ros_line(result.X, xp, xc)}")
    return "\n".join(lines)


def write_handeye_files(folder: Path, result, report: str, figure: bytes, **extra) -> None:
    """Every file of a hand-eye run into ``folder`` (an OutputFolder's staging path)."""
    from aicalib_tf.io import atomic_write_bytes, atomic_write_text
    from aicalib_tf.jsonio import dumps

    folder = Path(folder)
    texts = {"handeye.json": dumps(handeye_dict(result, **extra)) + "\n", "handeye.yaml": to_opencv_yaml(result),
             "static_transform.txt": static_transform_text(result), "report.txt": report + "\n"}
    for name, text in texts.items():
        atomic_write_text(folder / name, text)
    atomic_write_bytes(folder / "report.png", figure)
