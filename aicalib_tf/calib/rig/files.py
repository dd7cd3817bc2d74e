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
:func:`load_rig` reads ``rig.json`` back exactly; :func:`load_stereo_yml` reads the YAML pair. Both
check every field (:mod:`aicalib_tf.calib.schema`: at least one camera, rotations orthonormal with
det +1, finite values, shapes) and raise a ValueError naming the file and the field. ``rig.json`` is
strict JSON (a missing number, such as a frame RMS that could not be measured, is ``null``).
Kalibr's ``camchain.yaml`` (:mod:`aicalib_tf.calib.kalibr`) holds every camera with ``T_cn_cnm1``.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from aicalib_tf.calib import schema as S
from aicalib_tf.calib.files import (FILES, calibration_dict, calibration_from_dict, existing_file, to_camera_info_yaml,
                                    to_json, to_opencv_yaml)
from aicalib_tf.calib.kalibr import to_camchain_yaml
from aicalib_tf.calib.rig.quality import pair_rectification
from aicalib_tf.calib.rig.result import RigCalibration
from aicalib_tf.geometry import lens as L
from aicalib_tf.geometry.rectify import Rectification, essential_matrix, fundamental_matrix
from aicalib_tf.io import atomic_write_text
from aicalib_tf.jsonio import dumps, jsonable, nan_for_null, read_json

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


def _cameras(d: dict) -> tuple[tuple[str, ...], tuple]:
    """(names, calibrations): at least one camera, names unique strings, one calibration per name."""
    names = S.require_list(d, "names", min_len=1)
    names = tuple(S.require_str({f"names[{k}]": n}, f"names[{k}]") for k, n in enumerate(names))
    if len(set(names)) != len(names):
        raise S.FieldError("names", f"must be unique, got {list(names)}")
    cams = S.require_list(d, "cameras")
    if len(cams) != len(names):
        raise S.FieldError("cameras", f"must hold one calibration per name ({len(names)}), got {len(cams)}")
    out = []
    for k in range(len(cams)):
        cam = S.require_item(cams, k, "cameras")
        with S.within(f"cameras[{k}]"):
            out.append(calibration_from_dict(cam))
    return names, tuple(out)


def _frames(d: dict, n_cams: int) -> dict:
    """frames (F names), frame_rms (F,) px (null: NaN) and frame_cameras (camera indices per frame)."""
    frames = tuple(S.require_str({f"frames[{k}]": f}, f"frames[{k}]") for k, f in enumerate(S.require_list(d, "frames")))
    rms = np.array([S.require_number({f"frame_rms[{k}]": v}, f"frame_rms[{k}]", nonnegative=True, nullable=True)
                    for k, v in enumerate(S.require_list(d, "frame_rms"))], np.float64)
    cams = []
    for k, cs in enumerate(S.require_list(d, "frame_cameras")):
        key = f"frame_cameras[{k}]"
        cams.append(tuple(S.require_int({key: c}, key, 0, n_cams - 1) for c in S.require_list({key: cs}, key)))
    cams = tuple(cams)
    if not len(frames) == len(rms) == len(cams):
        raise S.FieldError("frames", f"has {len(frames)} names, {len(rms)} frame_rms and {len(cams)} frame_cameras")
    return dict(frames=frames, frame_rms=rms, frame_cameras=cams)


def rig_from_dict(d: dict) -> RigCalibration:
    """The inverse of :func:`rig_dict`, every field checked (:mod:`~aicalib_tf.calib.schema`).

    Raises :class:`~aicalib_tf.calib.schema.FieldError` (a ValueError naming the field) when a field
    is missing or wrong (``cameras[1].board.square_size``, ``R``...)."""
    if not isinstance(d, dict):
        raise ValueError(f"expected a JSON object, got {type(d).__name__}")
    names, cameras = _cameras(d)
    c = len(names)
    board = S.require_mapping(d, "board")
    with S.within("board"):
        pattern, square = S.require_board(board, "pattern_size", "square_size")
        unit = S.require_str(board, "square_unit", "")
    opt = {k: S.require_mapping(d, k, {}) if d.get(k) is not None else {} for k in ("rejected", "quality", "meta")}
    opt["quality"] = nan_for_null(opt["quality"])
    return RigCalibration(
        names=names, cameras=cameras, R=S.require_rotation(d, "R", (c, 3, 3)), T=S.require_matrix(d, "T", (c, 3)),
        pose_covariance=S.require_matrix(d, "pose_covariance", (c, 6, 6)), **_frames(d, c),
        rms=S.require_number(d, "rms", nonnegative=True), pattern_size=pattern, square_size=square, square_unit=unit,
        **opt)


def pair_folder(rig: RigCalibration, k: int) -> str:
    """Where the pair (0, k)'s stereo files go: "" (the top) for a two-camera rig, else "cam0_camk"."""
    return "" if len(rig.names) == 2 else f"{rig.names[0]}_{rig.names[k]}"


def rig_texts(rig: RigCalibration) -> dict[str, str]:
    """{relative path: text} of every rig file (module docstring)."""
    texts = {"rig.json": dumps(rig_dict(rig))}
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
    """Read ``rig.json`` (or a folder holding it). Raises FileNotFoundError, or ValueError naming the file
    (and the field, when one is wrong)."""
    path = existing_file(path, "rig.json", "rig")
    with S.file_errors(path, "aicalib_tf rig file"):
        return rig_from_dict(read_json(path))


_STEREO_NODES = {
    "intrinsics.yml": ("M1", "D1", "M2", "D2", "distortion_model1", "distortion_model2", "image_width", "image_height"),
    "extrinsics.yml": ("R", "T", "R1", "R2", "P1", "P2", "Q", "E", "F"),
}


def _intrinsics(d: dict) -> dict:
    """intrinsics.yml's nodes, checked: M1, M2 camera matrices; D1, D2 with the counts of their models."""
    out = {}
    for k in ("1", "2"):
        out[f"M{k}"] = S.require_camera_matrix(d, f"M{k}")
        D = S.require_matrix(d, f"D{k}", (-1, -1))
        ros = S.require_str(d, f"distortion_model{k}")
        S.require_dist(d, f"D{k}", S.require_model(d, D.size, key=None, ros_key=f"distortion_model{k}"))
        out[f"D{k}"], out[f"distortion_model{k}"] = D, ros
    if "image_width" in d or "image_height" in d:
        out["image_width"], out["image_height"] = S.require_image_size(d)
    return out


def _extrinsics(d: dict) -> dict:
    """extrinsics.yml's nodes, checked: R, R1, R2 rotations; T (3 values); P1, P2 (3, 4); Q (4, 4); E, F (3, 3)."""
    out = {key: S.require_rotation(d, key) for key in ("R", "R1", "R2")}
    T = S.require_matrix(d, "T", (-1, -1))
    S.require_vector(d, "T", 3)
    out.update(T=T, P1=S.require_matrix(d, "P1", (3, 4)), P2=S.require_matrix(d, "P2", (3, 4)),
               Q=S.require_matrix(d, "Q", (4, 4)), E=S.require_matrix(d, "E", (3, 3)), F=S.require_matrix(d, "F", (3, 3)))
    return out


def load_stereo_yml(folder) -> dict:
    """The nodes of ``intrinsics.yml`` and ``extrinsics.yml`` in ``folder``: {"M1": (3, 3), "D1": (1, n), ...,
    "T": (3, 1), "Q": (4, 4), "distortion_model1": str, ...} (matrices float64 as stored; image_width and
    image_height ints when present), every node checked (:mod:`~aicalib_tf.calib.schema`: K's form,
    coefficient counts, rotations, finite values). Raises FileNotFoundError or ValueError naming the file."""
    out = {}
    for name, keys in _STEREO_NODES.items():
        path = Path(folder) / name
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such file")
        with S.file_errors(path, "OpenCV stereo file"):
            d = S.read_opencv_yaml(path, keys)
            out.update(_intrinsics(d) if name == "intrinsics.yml" else _extrinsics(d))
    return out
