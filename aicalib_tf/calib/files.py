"""Calibration files: OpenCV FileStorage YAML, a JSON twin, and ROS ``camera_info`` YAML.

``camera.yaml`` (read it with ``cv2.FileStorage(path, cv2.FILE_STORAGE_READ)``):
``camera_matrix`` (3×3), ``distortion_coefficients`` (1×5 or 1×8), ``image_width``,
``image_height``, ``avg_reprojection_error`` (px), ``per_view_reprojection_errors`` (V×1 px),
``extrinsic_parameters`` (V×6: rvec, tvec per used view), the board (``board_width``,
``board_height`` inner corners, ``square_size``) and ``calibration_time``.

``camera.json`` holds the same plus what is needed to rerun diagnostics: view names, per-view
corner counts, standard deviations, rejected views with reasons, the square unit and the
provenance in ``meta`` (detector, model sha256, flags). :func:`load_calibration` reads it back
exactly (floats are written with full precision).

``camera_info.yaml`` follows ROS's ``sensor_msgs/CameraInfo`` calibration file layout
(``plumb_bob`` for 5 coefficients, ``rational_polynomial`` for 8). Its projection matrix is
``cv2.getOptimalNewCameraMatrix(K, dist, size, alpha=0)``, as ROS's monocular calibrator writes.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import cv2
import numpy as np

from aicalib_tf.calib.fit import Calibration
from aicalib_tf.io import atomic_write_text

__all__ = ["save_calibration", "load_calibration", "to_opencv_yaml", "to_json", "to_camera_info_yaml", "undistort"]

FILES = ("camera.yaml", "camera.json", "camera_info.yaml")


def to_opencv_yaml(cal: Calibration) -> str:
    """The calibration as OpenCV FileStorage YAML text."""
    fs = cv2.FileStorage("camera.yaml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    fs.write("calibration_time", time.strftime("%Y-%m-%d %H:%M:%S"))
    fs.write("image_width", int(cal.image_size[0]))
    fs.write("image_height", int(cal.image_size[1]))
    fs.write("board_width", int(cal.pattern_size[0]))
    fs.write("board_height", int(cal.pattern_size[1]))
    fs.write("square_size", float(cal.square_size))
    fs.write("nr_of_frames", len(cal.views))
    fs.write("camera_matrix", np.asarray(cal.K, np.float64))
    fs.write("distortion_coefficients", np.asarray(cal.dist, np.float64).reshape(1, -1))
    fs.write("avg_reprojection_error", float(cal.rms))
    fs.write("per_view_reprojection_errors", np.asarray(cal.per_view_rms, np.float64).reshape(-1, 1))
    fs.write("extrinsic_parameters", np.concatenate([cal.rvecs, cal.tvecs], axis=1).astype(np.float64))
    return fs.releaseAndGetString()


def _as_dict(cal: Calibration) -> dict:
    return {
        "image_width": int(cal.image_size[0]), "image_height": int(cal.image_size[1]),
        "camera_matrix": np.asarray(cal.K).tolist(), "distortion_coefficients": np.asarray(cal.dist).tolist(),
        "avg_reprojection_error": float(cal.rms),
        "std": {k: float(v) for k, v in cal.std.items()},
        "board": {"pattern_size": list(cal.pattern_size), "square_size": float(cal.square_size),
                  "square_unit": cal.square_unit},
        "views": [
            {"name": n, "rms": float(e), "corners": int(c), "rvec": r.tolist(), "tvec": t.tolist()}
            for n, e, c, r, t in zip(cal.views, cal.per_view_rms, cal.corner_counts, cal.rvecs, cal.tvecs)
        ],
        "rejected": dict(cal.rejected),
        "meta": dict(cal.meta),
    }


def to_json(cal: Calibration) -> str:
    """The calibration as JSON text (the format :func:`load_calibration` reads)."""
    return json.dumps(_as_dict(cal), indent=1) + "\n"


def _ros_matrix(name: str, m: np.ndarray) -> str:
    m = np.atleast_2d(np.asarray(m, np.float64))
    data = ", ".join(repr(float(v)) for v in m.ravel())
    return f"{name}:\n  rows: {m.shape[0]}\n  cols: {m.shape[1]}\n  data: [{data}]\n"


def to_camera_info_yaml(cal: Calibration, camera_name: str = "camera") -> str:
    """The calibration in ROS's camera_info YAML layout (monocular: identity rectification)."""
    w, h = cal.image_size
    P, _ = cv2.getOptimalNewCameraMatrix(cal.K, cal.dist, (w, h), 0.0)
    model = "rational_polynomial" if len(cal.dist) == 8 else "plumb_bob"
    return (f"image_width: {w}\nimage_height: {h}\ncamera_name: {camera_name}\n"
            + _ros_matrix("camera_matrix", cal.K)
            + f"distortion_model: {model}\n"
            + _ros_matrix("distortion_coefficients", np.asarray(cal.dist).reshape(1, -1))
            + _ros_matrix("rectification_matrix", np.eye(3))
            + _ros_matrix("projection_matrix", np.concatenate([P, np.zeros((3, 1))], axis=1)))


def save_calibration(cal: Calibration, folder) -> Path:
    """Write camera.yaml, camera.json and camera_info.yaml into ``folder``; returns the folder.

    Every text is produced before anything is written, and each file is replaced atomically.
    """
    folder = Path(folder)
    texts = {"camera.yaml": to_opencv_yaml(cal), "camera.json": to_json(cal), "camera_info.yaml": to_camera_info_yaml(cal)}
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in texts.items():
        atomic_write_text(folder / name, text)
    return folder


def load_calibration(path) -> Calibration:
    """Read ``camera.json`` (or a folder holding it). Raises ValueError naming the file if it is bad."""
    path = Path(path)
    if path.is_dir():
        path = path / "camera.json"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such calibration file")
    try:
        d = json.loads(path.read_text(encoding="utf-8"))
        views = d["views"]
        board = d["board"]
        return Calibration(
            K=np.asarray(d["camera_matrix"], np.float64).reshape(3, 3),
            dist=np.asarray(d["distortion_coefficients"], np.float64).ravel(),
            image_size=(int(d["image_width"]), int(d["image_height"])),
            pattern_size=tuple(int(v) for v in board["pattern_size"]),
            square_size=float(board["square_size"]), square_unit=str(board.get("square_unit", "")),
            rms=float(d["avg_reprojection_error"]),
            views=tuple(str(v["name"]) for v in views),
            rvecs=np.asarray([v["rvec"] for v in views], np.float64).reshape(-1, 3),
            tvecs=np.asarray([v["tvec"] for v in views], np.float64).reshape(-1, 3),
            per_view_rms=np.asarray([v["rms"] for v in views], np.float64),
            corner_counts=np.asarray([v["corners"] for v in views], np.int64),
            std={str(k): float(v) for k, v in d.get("std", {}).items()},
            rejected={str(k): str(v) for k, v in d.get("rejected", {}).items()},
            meta=dict(d.get("meta", {})),
        )
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{path}: not a valid aicalib_tf calibration file ({type(exc).__name__}: {exc})") from None


def undistort(image: np.ndarray, cal: Calibration, *, alpha: float = 0.0) -> np.ndarray:
    """Remove lens distortion from an image taken by the calibrated camera.

    image : (H, W) or (H, W, C) array of the calibration's image size.
    alpha : 0 keeps only valid pixels (crops the curved border); 1 keeps every source pixel.
    Returns an array of the same shape and dtype.
    """
    h, w = image.shape[:2]
    if (w, h) != tuple(cal.image_size):
        raise ValueError(f"image is {w}x{h} but the calibration is for {cal.image_size[0]}x{cal.image_size[1]}")
    new_K, _ = cv2.getOptimalNewCameraMatrix(cal.K, cal.dist, (w, h), float(alpha))
    return cv2.undistort(image, cal.K, cal.dist, None, new_K)
