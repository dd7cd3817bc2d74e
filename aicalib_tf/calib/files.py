"""Calibration files: OpenCV FileStorage YAML, a JSON twin, and ROS ``camera_info`` YAML; undistortion.

``camera.yaml`` (read it with ``cv2.FileStorage(path, cv2.FILE_STORAGE_READ)``):
``camera_matrix`` (3×3), ``distortion_model`` (ROS's name: ``plumb_bob``, ``rational_polynomial``
or ``equidistant``; the thin prism is ``rational_polynomial`` with OpenCV's 12 coefficients; Double
Sphere and EUCM have no OpenCV or ROS name and are written ``ds`` with [ξ, α] and ``eucm`` with
[α, β], as Kalibr and basalt name them),
``distortion_coefficients`` (1×n in OpenCV order), ``image_width``, ``image_height``,
``avg_reprojection_error`` (px), ``per_view_reprojection_errors`` (V×1 px),
``extrinsic_parameters`` (V×6: rvec, tvec per used view), the board (``board_width``,
``board_height`` inner corners, ``square_size``) and ``calibration_time``.

``camera.json`` holds the same plus what is needed to rerun diagnostics: our model name
(``model``: plumb_bob, rational_polynomial, thin_prism, equidistant, ds or eucm), the intrinsics covariance,
the model-choice table, the quality summary, view names, per-view corner counts, standard
deviations, rejected views with reasons, the square unit and the provenance in ``meta``.
:func:`load_calibration` reads it back exactly (floats are written with full precision); it also
reads ``camera.yaml`` (without view names, covariance or table).

``camchain.yaml`` is Kalibr's camera chain (:mod:`aicalib_tf.calib.kalibr`).

``camera_info.yaml`` follows ROS's ``sensor_msgs/CameraInfo`` calibration file layout with the same
``distortion_model``. Its projection matrix P is the new camera matrix of :func:`undistort` with
alpha = 0: for the pinhole models ``cv2.getOptimalNewCameraMatrix(K, dist, size, alpha=0)`` as
ROS's monocular calibrator writes; for ``equidistant`` a pinhole with K's focal lengths centred on
the image (the central magnification kept, the periphery cropped).
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import cv2
import numpy as np

from aicalib_tf.calib.fit import Calibration
from aicalib_tf.calib.kalibr import to_camchain_yaml
from aicalib_tf.calib.quality import lens_of
from aicalib_tf.geometry import lens as L
from aicalib_tf.io import atomic_write_text

__all__ = ["save_calibration", "load_calibration", "to_opencv_yaml", "to_json", "to_camera_info_yaml", "undistort",
           "undistort_camera_matrix", "calibration_dict", "calibration_from_dict", "jsonable", "existing_file"]

FILES = ("camera.yaml", "camera.json", "camera_info.yaml")
MAX_FISHEYE_HALF_ANGLE_DEG = 75.0  # the widest half-angle a rectified pinhole of equidistant shows (alpha = 1)


def to_opencv_yaml(cal: Calibration) -> str:
    """The calibration as OpenCV FileStorage YAML text."""
    lens = lens_of(cal)
    fs = cv2.FileStorage("camera.yaml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    fs.write("calibration_time", time.strftime("%Y-%m-%d %H:%M:%S"))
    fs.write("image_width", int(cal.image_size[0]))
    fs.write("image_height", int(cal.image_size[1]))
    fs.write("board_width", int(cal.pattern_size[0]))
    fs.write("board_height", int(cal.pattern_size[1]))
    fs.write("square_size", float(cal.square_size))
    fs.write("nr_of_frames", len(cal.views))
    fs.write("camera_matrix", np.asarray(cal.K, np.float64))
    fs.write("distortion_model", L.ROS_NAMES[lens.model])
    fs.write("distortion_coefficients", np.asarray(cal.dist, np.float64).reshape(1, -1))
    fs.write("avg_reprojection_error", float(cal.rms))
    fs.write("per_view_reprojection_errors", np.asarray(cal.per_view_rms, np.float64).reshape(-1, 1))
    fs.write("extrinsic_parameters", np.concatenate([cal.rvecs, cal.tvecs], axis=1).astype(np.float64).reshape(-1, 6))
    return fs.releaseAndGetString()


def jsonable(x):
    """Nested dicts/lists/tuples with numpy scalars and arrays -> plain JSON types."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, np.generic):
        return x.item()
    return x


def calibration_dict(cal: Calibration) -> dict:
    """``camera.json``'s content: a JSON-able dict of the calibration (:func:`calibration_from_dict` reads it)."""
    lens = lens_of(cal)
    cov = getattr(cal, "covariance", None)
    return {
        "image_width": int(cal.image_size[0]), "image_height": int(cal.image_size[1]),
        "model": lens.model, "distortion_model": L.ROS_NAMES[lens.model],
        "camera_matrix": np.asarray(cal.K).tolist(), "distortion_coefficients": np.asarray(cal.dist).tolist(),
        "avg_reprojection_error": float(cal.rms),
        "std": {k: float(v) for k, v in cal.std.items()},
        "covariance": None if cov is None else np.asarray(cov, np.float64).tolist(),
        "model_table": jsonable(list(getattr(cal, "model_table", ()) or ())),
        "quality": jsonable(dict(getattr(cal, "quality", {}) or {})),
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
    return json.dumps(calibration_dict(cal), indent=1) + "\n"


def _ros_matrix(name: str, m: np.ndarray) -> str:
    m = np.atleast_2d(np.asarray(m, np.float64))
    data = ", ".join(repr(float(v)) for v in m.ravel())
    return f"{name}:\n  rows: {m.shape[0]}\n  cols: {m.shape[1]}\n  data: [{data}]\n"


def to_camera_info_yaml(cal: Calibration, camera_name: str = "camera", *, R=None, P=None) -> str:
    """The calibration in ROS's camera_info YAML layout.

    Monocular (R, P None): identity rectification, P = :func:`undistort_camera_matrix` with alpha = 0
    (module docstring). A camera of a rectified stereo pair: R (3, 3) its rectifying rotation and
    P (3, 4) its rectified projection, as ROS's stereo calibrator writes them."""
    w, h = cal.image_size
    R = np.eye(3) if R is None else np.asarray(R, np.float64)
    P = np.concatenate([undistort_camera_matrix(cal, 0.0), np.zeros((3, 1))], axis=1) if P is None else np.asarray(P, np.float64)
    return (f"image_width: {w}\nimage_height: {h}\ncamera_name: {camera_name}\n"
            + _ros_matrix("camera_matrix", cal.K)
            + f"distortion_model: {L.ROS_NAMES[lens_of(cal).model]}\n"
            + _ros_matrix("distortion_coefficients", np.asarray(cal.dist).reshape(1, -1))
            + _ros_matrix("rectification_matrix", R)
            + _ros_matrix("projection_matrix", P))


def save_calibration(cal: Calibration, folder) -> Path:
    """Write camera.yaml, camera.json, camera_info.yaml and Kalibr's camchain.yaml into ``folder``; returns the folder.

    Every text is produced before anything is written, and each file is replaced atomically.
    """
    folder = Path(folder)
    texts = {"camera.yaml": to_opencv_yaml(cal), "camera.json": to_json(cal), "camera_info.yaml": to_camera_info_yaml(cal)}
    texts["camchain.yaml"] = to_camchain_yaml(cal)  # Kalibr (calib.kalibr)
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in texts.items():
        atomic_write_text(folder / name, text)
    return folder


def _build(fields: dict, extra: dict) -> Calibration:
    """A Calibration from its fields plus the newer ones (model, covariance, model_table, quality)
    that this build's Calibration knows; a non-default model it cannot hold is an error."""
    known = {f.name for f in dataclasses.fields(Calibration)}
    fields.update({k: v for k, v in extra.items() if k in known})
    cal = Calibration(**fields)
    if "model" in extra and lens_of(cal).model != extra["model"]:
        raise ValueError(f"this build's Calibration cannot hold a {extra['model']!r} lens")
    return cal


def _load_json(path: Path) -> Calibration:
    return calibration_from_dict(json.loads(path.read_text(encoding="utf-8")))


def calibration_from_dict(d: dict) -> Calibration:
    """The inverse of :func:`calibration_dict` (``camera.json``'s content). Raises KeyError/ValueError when bad."""
    views, board = d["views"], d["board"]
    dist = np.asarray(d["distortion_coefficients"], np.float64).ravel()
    model = d.get("model") or L.model_from_ros(d.get("distortion_model", "plumb_bob"), dist.size)
    L.check_model(model, dist)
    cov = d.get("covariance")
    extra = {"model": model, "covariance": None if cov is None else np.asarray(cov, np.float64),
             "model_table": tuple(d.get("model_table") or ()), "quality": dict(d.get("quality") or {})}
    return _build(dict(
        K=np.asarray(d["camera_matrix"], np.float64).reshape(3, 3), dist=dist,
        image_size=(int(d["image_width"]), int(d["image_height"])),
        pattern_size=tuple(int(v) for v in board["pattern_size"]),
        square_size=float(board["square_size"]), square_unit=str(board.get("square_unit", "")),
        rms=float(d["avg_reprojection_error"]), views=tuple(str(v["name"]) for v in views),
        rvecs=np.asarray([v["rvec"] for v in views], np.float64).reshape(-1, 3),
        tvecs=np.asarray([v["tvec"] for v in views], np.float64).reshape(-1, 3),
        per_view_rms=np.asarray([v["rms"] for v in views], np.float64),
        corner_counts=np.asarray([v["corners"] for v in views], np.int64),
        std={str(k): float(v) for k, v in d.get("std", {}).items()},
        rejected={str(k): str(v) for k, v in d.get("rejected", {}).items()}, meta=dict(d.get("meta", {}))), extra)


def _load_opencv_yaml(path: Path) -> Calibration:
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:
        K, dist = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat()
        if K is None or dist is None:
            raise ValueError("no camera_matrix or distortion_coefficients matrix")
        dist = dist.astype(np.float64).ravel()
        node = fs.getNode("distortion_model")
        model = L.model_from_ros(node.string() if not node.empty() else "plumb_bob", dist.size)
        ext = fs.getNode("extrinsic_parameters").mat()
        ext = np.zeros((0, 6)) if ext is None else ext.reshape(-1, 6).astype(np.float64)
        errs = fs.getNode("per_view_reprojection_errors").mat()
        errs = np.zeros(len(ext)) if errs is None else errs.astype(np.float64).ravel()
        fields = dict(K=K.astype(np.float64), dist=L.check_model(model, dist)[1],
                      image_size=(int(fs.getNode("image_width").real()), int(fs.getNode("image_height").real())),
                      pattern_size=(int(fs.getNode("board_width").real()), int(fs.getNode("board_height").real())),
                      square_size=float(fs.getNode("square_size").real()), rms=float(fs.getNode("avg_reprojection_error").real()),
                      views=tuple(f"view{k}" for k in range(len(ext))), rvecs=ext[:, :3], tvecs=ext[:, 3:],
                      per_view_rms=errs, corner_counts=np.zeros(len(ext), np.int64), std={})
    finally:
        fs.release()
    return _build(fields, {"model": model})


def existing_file(path, default_name: str, what: str) -> Path:
    """``path``, or ``path / default_name`` when it is a folder; FileNotFoundError ("no such ``what``
    file") when that is not a file."""
    path = Path(path)
    if path.is_dir():
        path = path / default_name
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such {what} file")
    return path


def load_calibration(path) -> Calibration:
    """Read ``camera.json`` (or a folder holding it) or an OpenCV ``camera.yaml``.

    The lens model comes from ``model`` (JSON) or ``distortion_model`` with the coefficient
    count (:func:`~aicalib_tf.geometry.lens.model_from_ros`; plumb_bob when absent, as in older
    files). Raises FileNotFoundError, or ValueError naming the file if it is bad.
    """
    path = existing_file(path, "camera.json", "calibration")
    try:
        return _load_opencv_yaml(path) if path.suffix.lower() in (".yaml", ".yml") else _load_json(path)
    except (json.JSONDecodeError, KeyError, TypeError, ValueError, cv2.error) as exc:
        raise ValueError(f"{path}: not a valid aicalib_tf calibration file ({type(exc).__name__}: {exc})") from None


def undistort_camera_matrix(cal: Calibration, alpha: float = 0.0) -> np.ndarray:
    """(3, 3) camera matrix of the ideal pinhole image :func:`undistort` produces.

    Pinhole models: ``cv2.getOptimalNewCameraMatrix`` (alpha 0 keeps only valid pixels, 1 keeps
    every source pixel). The fisheye models (``IS_FISHEYE``: equidistant, ds, eucm; a pinhole
    cannot show 180°): the principal point at the
    image centre and a focal f = (1 − alpha)·fx + alpha·f₁ (likewise for y), where f₁ makes the
    output's left/right edges see the lens's horizontal half-field, capped at 75°
    (:data:`MAX_FISHEYE_HALF_ANGLE_DEG`): alpha 0 keeps the central magnification and crops the
    periphery, alpha 1 shows as much of the horizontal field as a pinhole reasonably can.
    """
    a = float(alpha)
    if not 0.0 <= a <= 1.0:
        raise ValueError(f"alpha must be in [0, 1], got {alpha!r}")
    lens = lens_of(cal)
    w, h = lens.image_size
    if not lens.spec.IS_FISHEYE:
        new_K, _ = cv2.getOptimalNewCameraMatrix(lens.K, lens.dist, (w, h), a)
        return np.asarray(new_K, np.float64)
    half = float(np.radians(lens.field_of_view()["horizontal"]) / 2)
    half = min(half, np.radians(MAX_FISHEYE_HALF_ANGLE_DEG))
    f1 = 0.5 * w / np.tan(half)
    fx, fy = (1 - a) * lens.fx + a * f1, (1 - a) * lens.fy + a * f1 * lens.fy / lens.fx
    return np.array([[fx, 0.0, (w - 1) / 2], [0.0, fy, (h - 1) / 2], [0.0, 0.0, 1.0]])


_REMAP_DTYPES = tuple(np.dtype(t) for t in (np.uint8, np.uint16, np.int16, np.float32, np.float64))  # cv2.remap's


def undistort(image: np.ndarray, cal: Calibration, *, alpha: float = 0.0) -> np.ndarray:
    """Remove lens distortion from an image taken by the calibrated camera (any lens model).

    image : (H, W) or (H, W, C) array of the calibration's image size.
    alpha : in [0, 1], the new camera matrix's trade-off (:func:`undistort_camera_matrix`).
    Returns an array of the same shape and dtype (black where the output pixel has no source:
    bilinear ``cv2.remap`` through :func:`~aicalib_tf.geometry.lens.undistort_maps`).
    """
    image = np.asarray(image)
    if image.ndim not in (2, 3) or image.dtype not in _REMAP_DTYPES:
        raise ValueError(f"undistort takes an (H, W) or (H, W, C) image of uint8, uint16, int16, float32 or float64, "
                         f"got shape {image.shape} of {image.dtype}")
    h, w = image.shape[:2]
    if (w, h) != tuple(cal.image_size):
        raise ValueError(f"image is {w}x{h} but the calibration is for {cal.image_size[0]}x{cal.image_size[1]}")
    lens = lens_of(cal)
    map_x, map_y = lens.undistort_maps(new_K=undistort_camera_matrix(cal, alpha))
    return cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
