"""Rig files: OpenCV's stereo YAML pair, ROS camera_info per camera, one JSON with everything; loaders.

For a pair (cameras i, j), as OpenCV's ``stereo_calib`` sample names the nodes
(read them with ``cv2.FileStorage``):

* ``intrinsics.yml``: M1, D1, M2, D2 (camera matrices and coefficients in OpenCV order), plus
  ``distortion_model1`` / ``distortion_model2`` (ROS names: plumb_bob, rational_polynomial,
  equidistant; a fisheye's D is ``cv2.fisheye``'s k1..k4) and ``image_width`` / ``image_height``;
* ``extrinsics.yml``: R, T (X2 = R·X1 + T, T in the board's unit), R1, R2, P1, P2, Q (the
  rectification, :func:`~aicalib_tf.geometry.rectify.rectify_pair`), plus E and F;
* ``<name>_camera_info.yaml`` per camera: ROS ``camera_info`` with R = R1 (R2) and P = P1 (P2).

A rig of two cameras writes them at the top of the output folder; a larger rig writes one folder
per pair with camera 0 (``cam0_cam2/``...). Every rig also gets ``rig.json`` (every camera's full
calibration as ``camera.json`` holds it, the poses with their covariance, the frames, the quality
and the rectifications) and each camera's one-camera files in a folder of its name.
Kalibr's ``camchain.yaml`` (:mod:`aicalib_tf.calib.kalibr`) holds every camera with ``T_cn_cnm1``.
:func:`load_rig` reads ``rig.json`` back exactly; :func:`load_stereo_yml` reads the YAML pair.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from aicalib_tf.calib.files import (FILES, calibration_dict, calibration_from_dict, existing_file, jsonable,
                                    to_camera_info_yaml, to_json, to_opencv_yaml)
from aicalib_tf.calib.kalibr import to_camchain_yaml
from aicalib_tf.calib.rig_quality import pair_rectification
from aicalib_tf.calib.rig_result import RigCalibration
from aicalib_tf.geometry import lens as L
from aicalib_tf.geometry.rectify import Rectification, essential_matrix, fundamental_matrix
from aicalib_tf.io import atomic_write_text

__all__ = ["save_rig", "load_rig", "load_stereo_yml", "rig_texts", "rig_dict", "rig_from_dict", "pair_folder"]


def _fs_text(name: str, nodes: dict) -> str:
    fs = cv2.FileStorage(name, cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    for key, value in nodes.items():
        fs.write(key, value if isinstance(value, str) else np.asarray(value, np.float64))
    return fs.releaseAndGetString()


def stereo_yml(rig: RigCalibration, rect: Rectification, i: int, j: int) -> tuple[str, str]:
    """(intrinsics.yml, extrinsics.yml) texts of the pair (i, j)."""
    a, b = rig.cameras[i], rig.cameras[j]
    R, T = rig.pair(i, j)
    intr = _fs_text("intrinsics.yml", {
        "M1": a.K, "D1": np.asarray(a.dist).reshape(1, -1), "M2": b.K, "D2": np.asarray(b.dist).reshape(1, -1),
        "distortion_model1": L.ROS_NAMES[a.model], "distortion_model2": L.ROS_NAMES[b.model],
        "image_width": np.array([[a.image_size[0]]]), "image_height": np.array([[a.image_size[1]]])})
    extr = _fs_text("extrinsics.yml", {
        "R": R, "T": T.reshape(3, 1), "R1": rect.R1, "R2": rect.R2, "P1": rect.P1, "P2": rect.P2, "Q": rect.Q,
        "E": essential_matrix(R, T), "F": fundamental_matrix(a.K, b.K, R, T)})
    return intr, extr


def _rect_dict(rect: Rectification) -> dict:
    return {"R1": rect.R1, "R2": rect.R2, "P1": rect.P1, "P2": rect.P2, "Q": rect.Q, "size": list(rect.size),
            "vertical": rect.vertical}


def rig_dict(rig: RigCalibration) -> dict:
    """``rig.json``'s content (JSON-able)."""
    rects = {f"{rig.names[0]}_{rig.names[k]}": _rect_dict(pair_rectification(rig.lenses, rig.R, rig.T, 0, k))
             for k in range(1, len(rig.names))}
    return jsonable({
        "names": list(rig.names), "cameras": [calibration_dict(c) for c in rig.cameras],
        "R": rig.R, "T": rig.T, "pose_covariance": rig.pose_covariance, "frames": list(rig.frames),
        "frame_rms": rig.frame_rms, "frame_cameras": [list(c) for c in rig.frame_cameras], "rms": rig.rms,
        "board": {"pattern_size": list(rig.pattern_size), "square_size": rig.square_size, "square_unit": rig.square_unit},
        "rejected": rig.rejected, "quality": rig.quality, "meta": rig.meta, "rectification": rects})


def rig_from_dict(d: dict) -> RigCalibration:
    """The inverse of :func:`rig_dict`."""
    board = d["board"]
    return RigCalibration(
        names=tuple(d["names"]), cameras=tuple(calibration_from_dict(c) for c in d["cameras"]),
        R=np.asarray(d["R"], np.float64).reshape(-1, 3, 3), T=np.asarray(d["T"], np.float64).reshape(-1, 3),
        pose_covariance=np.asarray(d["pose_covariance"], np.float64).reshape(-1, 6, 6), frames=tuple(d["frames"]),
        frame_rms=np.asarray(d["frame_rms"], np.float64), frame_cameras=tuple(tuple(c) for c in d["frame_cameras"]),
        rms=float(d["rms"]), pattern_size=tuple(board["pattern_size"]), square_size=float(board["square_size"]),
        square_unit=str(board.get("square_unit", "")), rejected=dict(d.get("rejected", {})),
        quality=dict(d.get("quality", {})), meta=dict(d.get("meta", {})))


def pair_folder(rig: RigCalibration, k: int) -> str:
    """Where the pair (0, k)'s stereo files go: "" (the top) for a two-camera rig, else "cam0_camk"."""
    return "" if len(rig.names) == 2 else f"{rig.names[0]}_{rig.names[k]}"


def rig_texts(rig: RigCalibration) -> dict[str, str]:
    """{relative path: text} of every rig file (module docstring)."""
    texts = {"rig.json": json.dumps(rig_dict(rig), indent=1) + "\n"}
    for k in range(1, len(rig.names)):
        rect = pair_rectification(rig.lenses, rig.R, rig.T, 0, k)
        sub = pair_folder(rig, k)
        intr, extr = stereo_yml(rig, rect, 0, k)
        texts[str(Path(sub) / "intrinsics.yml")] = intr
        texts[str(Path(sub) / "extrinsics.yml")] = extr
        for c, R, P in ((0, rect.R1, rect.P1), (k, rect.R2, rect.P2)):
            texts[str(Path(sub) / f"{rig.names[c]}_camera_info.yaml")] = to_camera_info_yaml(
                rig.cameras[c], rig.names[c], R=R, P=P)
    for name, cal in zip(rig.names, rig.cameras):
        for fname, text in zip(FILES, (to_opencv_yaml(cal), to_json(cal), to_camera_info_yaml(cal, name))):
            texts[str(Path(name) / fname)] = text
    return texts


def save_rig(rig: RigCalibration, folder) -> list[Path]:
    """Write every rig file into ``folder`` (each atomically, all texts made first); returns the paths."""
    folder = Path(folder)
    texts = rig_texts(rig)
    texts["camchain.yaml"] = to_camchain_yaml(rig)  # Kalibr (calib.kalibr)
    out = []
    for rel, text in texts.items():
        (folder / rel).parent.mkdir(parents=True, exist_ok=True)
        out.append(atomic_write_text(folder / rel, text))
    return out


def load_rig(path) -> RigCalibration:
    """Read ``rig.json`` (or a folder holding it). Raises FileNotFoundError, or ValueError naming the file."""
    path = existing_file(path, "rig.json", "rig")
    try:
        return rig_from_dict(json.loads(path.read_text(encoding="utf-8")))
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{path}: not a valid aicalib_tf rig file ({type(exc).__name__}: {exc})") from None


def load_stereo_yml(folder) -> dict:
    """The nodes of ``intrinsics.yml`` and ``extrinsics.yml`` in ``folder``: {"M1": (3, 3), ..., "Q": (4, 4),
    "distortion_model1": str, ...}. Raises FileNotFoundError or ValueError naming the file."""
    out = {}
    for name, keys in (("intrinsics.yml", ("M1", "D1", "M2", "D2", "distortion_model1", "distortion_model2")),
                       ("extrinsics.yml", ("R", "T", "R1", "R2", "P1", "P2", "Q", "E", "F"))):
        path = Path(folder) / name
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such file")
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        try:
            for key in keys:
                node = fs.getNode(key)
                if node.empty():
                    raise ValueError(f"{path}: no {key} node")
                out[key] = node.string() if key.startswith("distortion_model") else node.mat().astype(np.float64)
        finally:
            fs.release()
    return out
