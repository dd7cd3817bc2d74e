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
deviations, rejected views with reasons, the board's flex (``board_flex``: :func:`~aicalib_tf.calib.flex.flex_dict`),
single corners rejected inside the solve (``rejected_corners``: {view: [[col, row], ...]}, and their
count ``n_rejected_corners``), the square unit and the provenance in ``meta``; for a
circular fisheye the image circle (``image_circle``: {"cx", "cy", "radius"} px; absent or null when
the photos fill the frame, and in files written before it was kept).
:func:`load_calibration` reads it back exactly (floats are written with full precision); it also
reads ``camera.yaml`` (without view names, covariance or table). The JSON is strict (:mod:`aicalib_tf.jsonio`):
a number the calibration does not have (NaN: the cross-validation RMS of a forced model) is ``null``,
read back as NaN.

Loading checks every field before a :class:`Calibration` is made (:mod:`aicalib_tf.calib.schema`:
types, shapes, finite values, image size 1..100000 px, board ≥ 2×2 with a positive square, fx, fy
> 0, the coefficient count of the lens model, the covariance's size); the YAML is checked as text
before ``cv2.FileStorage`` parses it. A bad file is a ValueError naming the file and the field.

``camchain.yaml`` is Kalibr's camera chain (:mod:`aicalib_tf.calib.kalibr`).

``camera_info.yaml`` follows ROS's ``sensor_msgs/CameraInfo`` calibration file layout with the same
``distortion_model``. Its projection matrix P is the new camera matrix of :func:`undistort` with
alpha = 0: for the pinhole models ``cv2.getOptimalNewCameraMatrix(K, dist, size, alpha=0)`` as
ROS's monocular calibrator writes; for ``equidistant`` a pinhole with K's focal lengths centred on
the image (the central magnification kept, the periphery cropped).
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import cv2
import numpy as np

from aicalib_tf.calib import schema as S
from aicalib_tf.calib.fit import Calibration
from aicalib_tf.calib.flex import flex_dict, rejected_corners_dict, solve_fields_from_dict
from aicalib_tf.calib.kalibr import to_camchain_yaml
from aicalib_tf.calib.maps import map_entry, map_files, needs_maps
from aicalib_tf.calib.quality import lens_of
from aicalib_tf.geometry import lens as L
from aicalib_tf.geometry.image_circle import ImageCircle
from aicalib_tf.io import atomic_write_text
from aicalib_tf.jsonio import dumps, jsonable, nan_for_null, read_json

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
        "image_circle": None if getattr(cal, "image_circle", None) is None else cal.image_circle.to_dict(),
        "board_flex": flex_dict(cal),  # calib.flex: wx, wy, covariance (squares), sag, note; null: not considered
        "rejected_corners": rejected_corners_dict(cal), "n_rejected_corners": int(getattr(cal, "n_rejected_corners", 0)),
        **_lens_extras(cal),
    }


def _lens_extras(cal: Calibration) -> dict:
    """camera.json's ``lens_layout`` (a model whose layout its name carries: the spline's knot grid, base
    projection and range) and ``undistort_maps`` (a model no OpenCV model holds: :mod:`~aicalib_tf.calib.maps`)."""
    lens, out = lens_of(cal), {}
    if hasattr(lens.spec, "layout"):
        out["lens_layout"] = lens.spec.layout()
    if needs_maps(lens):
        out["undistort_maps"] = map_entry(lens, undistort_camera_matrix(cal, 0.0))
    return out


def to_json(cal: Calibration) -> str:
    """The calibration as strict JSON text (the format :func:`load_calibration` reads; a NaN, such as
    the cross-validation RMS of a forced model, is written as null)."""
    return dumps(calibration_dict(cal))


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

    A lens no OpenCV model holds (the spline, ds, eucm) also gets ``undistort_map_x.npy`` and
    ``undistort_map_y.npy``, float32 maps for ``cv2.remap`` (:mod:`~aicalib_tf.calib.maps`).

    Every text is produced before anything is written, and each file is replaced atomically.
    """
    folder = Path(folder)
    texts = {"camera.yaml": to_opencv_yaml(cal), "camera.json": to_json(cal), "camera_info.yaml": to_camera_info_yaml(cal)}
    texts["camchain.yaml"] = to_camchain_yaml(cal)  # Kalibr (calib.kalibr)
    folder.mkdir(parents=True, exist_ok=True)
    for name, text in texts.items():
        atomic_write_text(folder / name, text)
    lens = lens_of(cal)
    if needs_maps(lens):  # no OpenCV model holds the lens: the remap maps themselves
        map_files(lens, undistort_camera_matrix(cal, 0.0), folder, getattr(cal, "image_circle", None))
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


_TABLE_FLOATS = ("rms", "cv_rms", "cv_se")  # model_table numbers that may be null (NaN: the fit failed or was forced)
_YAML_KEYS = ("camera_matrix", "distortion_coefficients", "distortion_model", "image_width", "image_height",
              "board_width", "board_height", "square_size", "avg_reprojection_error", "per_view_reprojection_errors",
              "extrinsic_parameters", "camera_name")


def _optional_mapping(d: dict, key: str) -> dict:
    return S.require_mapping(d, key, {}) if d.get(key) is not None else {}


def _views(d: dict) -> dict:
    """The Calibration fields of ``views`` (a list of {name, rms, corners, rvec, tvec})."""
    views = S.require_list(d, "views")
    rows = []
    for k in range(len(views)):
        v = S.require_item(views, k, "views")
        with S.within(f"views[{k}]"):
            rows.append((S.require_str(v, "name"), S.require_number(v, "rms", nonnegative=True),
                         S.require_int(v, "corners", 0, 10**9), S.require_vector(v, "rvec", 3),
                         S.require_vector(v, "tvec", 3)))
    names, rms, corners, rvecs, tvecs = zip(*rows) if rows else ((), (), (), (), ())
    return dict(views=tuple(names), per_view_rms=np.asarray(rms, np.float64), corner_counts=np.asarray(corners, np.int64),
                rvecs=np.asarray(rvecs, np.float64).reshape(-1, 3), tvecs=np.asarray(tvecs, np.float64).reshape(-1, 3))


def _model_table(d: dict) -> tuple:
    """``model_table`` rows, their numbers null -> NaN (as the calibration held them)."""
    table = S.require_list(d, "model_table", default=None) if d.get("model_table") is not None else []
    out = []
    for k in range(len(table)):
        row = dict(S.require_item(table, k, "model_table"))
        with S.within(f"model_table[{k}]"):
            row.update({key: S.require_number(row, key, nullable=True) for key in _TABLE_FLOATS if key in row})
            S.require_str(row, "model", "")
        out.append(row)
    return tuple(out)


def _image_circle(d: dict) -> ImageCircle | None:
    """``image_circle`` ({"cx", "cy", "radius"} px), None when absent or null."""
    if d.get("image_circle") is None:
        return None
    c = S.require_mapping(d, "image_circle")
    with S.within("image_circle"):
        return ImageCircle(S.require_number(c, "cx"), S.require_number(c, "cy"), S.require_number(c, "radius", positive=True))


def _str_map(d: dict, key: str) -> dict:
    m = _optional_mapping(d, key)
    with S.within(key):
        return {k: S.require_str(m, k) for k in m}


def calibration_from_dict(d: dict) -> Calibration:
    """The inverse of :func:`calibration_dict` (``camera.json``'s content), every field checked.

    Raises :class:`~aicalib_tf.calib.schema.FieldError` (a ValueError naming the field) when a field
    is missing or wrong; null reads as NaN where a number is optional (std, model_table, quality)."""
    if not isinstance(d, dict):
        raise ValueError(f"expected a JSON object, got {type(d).__name__}")
    K = S.require_camera_matrix(d, "camera_matrix")
    model = S.require_model(d, S.require_vector(d, "distortion_coefficients").size)
    n = 4 + L.N_COEFFS[model]
    board = S.require_mapping(d, "board")
    with S.within("board"):
        pattern, square = S.require_board(board, "pattern_size", "square_size")
        unit = S.require_str(board, "square_unit", "")
    std = _optional_mapping(d, "std")
    with S.within("std"):
        std = {k: S.require_number(std, k, nullable=True) for k in std}
    extra = {"model": model, "covariance": S.require_matrix(d, "covariance", (n, n), default=None),
             "model_table": _model_table(d), "quality": nan_for_null(_optional_mapping(d, "quality")),
             "image_circle": _image_circle(d), **solve_fields_from_dict(d)}
    return _build(dict(K=K, dist=S.require_dist(d, "distortion_coefficients", model), image_size=S.require_image_size(d),
                       pattern_size=pattern, square_size=square, square_unit=unit,
                       rms=S.require_number(d, "avg_reprojection_error", nonnegative=True), **_views(d), std=std,
                       rejected=_str_map(d, "rejected"), meta=dict(_optional_mapping(d, "meta"))), extra)


def _load_opencv_yaml(path: Path) -> Calibration:
    d = S.read_opencv_yaml(path, _YAML_KEYS)
    if "camera_name" in d and "board_width" not in d:
        raise ValueError(f"{path}: a ROS camera_info file holds no board or views; load camera.json or camera.yaml")
    K = S.require_camera_matrix(d, "camera_matrix")
    model = S.require_model(d, S.require_vector(d, "distortion_coefficients").size, key=None)
    ext = S.require_matrix(d, "extrinsic_parameters", (-1, 6), default=None)
    ext = np.zeros((0, 6)) if ext is None else ext
    errs = S.require_vector(d, "per_view_reprojection_errors", len(ext), default=None)
    if errs is not None and np.any(errs < 0):
        raise S.FieldError("per_view_reprojection_errors", f"must be >= 0, got {errs.tolist()}")
    fields = dict(K=K, dist=S.require_dist(d, "distortion_coefficients", model), image_size=S.require_image_size(d),
                  pattern_size=(S.require_int(d, "board_width", 2, S.MAX_PATTERN_SIDE),
                                S.require_int(d, "board_height", 2, S.MAX_PATTERN_SIDE)),
                  square_size=S.require_number(d, "square_size", positive=True),
                  rms=S.require_number(d, "avg_reprojection_error", nonnegative=True),
                  views=tuple(f"view{k}" for k in range(len(ext))), rvecs=ext[:, :3], tvecs=ext[:, 3:],
                  per_view_rms=np.zeros(len(ext)) if errs is None else errs, corner_counts=np.zeros(len(ext), np.int64),
                  std={})
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
    files). Every field is checked (module docstring). Raises FileNotFoundError, or ValueError naming
    the file (and the field: ``camera.json: field board.square_size must be a positive finite number,
    got -25``) if it is bad; OSError when it cannot be read.
    """
    path = existing_file(path, "camera.json", "calibration")
    with S.file_errors(path, "aicalib_tf calibration file"):
        if path.suffix.lower() in (".yaml", ".yml"):
            return _load_opencv_yaml(path)
        return calibration_from_dict(read_json(path))


def undistort_camera_matrix(cal: Calibration, alpha: float = 0.0) -> np.ndarray:
    """(3, 3) camera matrix of the ideal pinhole image :func:`undistort` produces.

    Pinhole models: ``cv2.getOptimalNewCameraMatrix`` (alpha 0 keeps only valid pixels, 1 keeps
    every source pixel). The fisheye models (``IS_FISHEYE``: equidistant, ds, eucm; a pinhole
    cannot show 180°) and any other model OpenCV does not hold (a spline of a narrow lens): the
    principal point at the image centre and a focal f = (1 − alpha)·fx + alpha·f₁ (likewise for y), where f₁ makes the
    output's left/right edges see the lens's horizontal half-field, capped at 75°
    (:data:`MAX_FISHEYE_HALF_ANGLE_DEG`): alpha 0 keeps the central magnification and crops the
    periphery, alpha 1 shows as much of the horizontal field as a pinhole reasonably can.
    """
    a = float(alpha)
    if not 0.0 <= a <= 1.0:
        raise ValueError(f"alpha must be in [0, 1], got {alpha!r}")
    lens = lens_of(cal)
    w, h = lens.image_size
    if not lens.spec.IS_FISHEYE and not needs_maps(lens):  # a model OpenCV holds (a narrow spline is not one)
        new_K, _ = cv2.getOptimalNewCameraMatrix(lens.K, lens.dist, (w, h), a)
        return np.asarray(new_K, np.float64)
    half = float(np.radians(lens.field_of_view(getattr(cal, "image_circle", None))["horizontal"]) / 2)
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
    bilinear ``cv2.remap`` through :func:`~aicalib_tf.geometry.lens.undistort_maps`; black too where it
    would come from outside the calibration's image circle).
    """
    image = np.asarray(image)
    if image.ndim not in (2, 3) or image.dtype not in _REMAP_DTYPES:
        raise ValueError(f"undistort takes an (H, W) or (H, W, C) image of uint8, uint16, int16, float32 or float64, "
                         f"got shape {image.shape} of {image.dtype}")
    h, w = image.shape[:2]
    if (w, h) != tuple(cal.image_size):
        raise ValueError(f"image is {w}x{h} but the calibration is for {cal.image_size[0]}x{cal.image_size[1]}")
    lens = lens_of(cal)
    map_x, map_y = lens.undistort_maps(new_K=undistort_camera_matrix(cal, alpha), circle=getattr(cal, "image_circle", None))
    return cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
