"""A robot's reported poses for hand-eye calibration: read, check, match to images (numpy/OpenCV).

A pose is ``T_base_flange``: the flange (tool) frame in the robot's base frame, translation in
metres, rotation as a unit quaternion (Hamilton, x y z w, as ROS) or as the 3×3 block of a 4×4
matrix. Three file forms hold the same data, one pose per image:

* CSV with a header naming at least ``image,x,y,z,qx,qy,qz,qw`` (any order, more columns allowed);
* JSON or YAML: a list of entries (or ``{"poses": [...]}``), each ``{"image": name, "x": .., "y": ..,
  "z": .., "qx": .., "qy": .., "qz": .., "qw": ..}`` or ``{"image": name, "matrix": 4×4 (nested or
  16 numbers, row-major)}``. YAML is read by OpenCV's FileStorage parser.

Every problem is a :class:`~aicalib_tf.cli.InputError` naming the file, the row and what is wrong:
missing columns, values that are not finite numbers, a quaternion whose norm is not 1 (within
``QUAT_TOL`` it is normalised with a warning), a matrix whose rotation block is not a rotation, a
translation over ``MAX_TRANSLATION_M`` (the file is probably in millimetres), two rows for one image.

Rows are matched to images by file name (the row's path may hold folders), else by the name
without its extension; unmatched rows and images are listed, not fatal.
"""

from __future__ import annotations

import csv
import io
import math
import re
from dataclasses import dataclass, field
from pathlib import Path, PurePath

import cv2
import numpy as np

from aicalib_tf.cli import InputError
from aicalib_tf.geometry.transform import matrix_to_quat, quat_to_matrix

__all__ = ["RobotPoses", "read_poses", "parse_poses", "match_poses", "quat_to_matrix", "matrix_to_quat",
           "QUAT_TOL", "MAX_TRANSLATION_M", "CSV_COLUMNS"]

CSV_COLUMNS = ("image", "x", "y", "z", "qx", "qy", "qz", "qw")
QUAT_TOL = 1e-3  # | |q| - 1 | up to this is normalised with a warning; beyond it the row is refused
ROT_TOL = 1e-3  # a matrix's rotation block: max |RᵀR − I| up to this is re-orthonormalised with a warning
MAX_TRANSLATION_M = 10.0  # a robot's flange further than this from its base: the file is in mm, not m
_MAX_BYTES = 64 << 20


@dataclass(frozen=True)
class RobotPoses:
    """The poses of one file. names : row image names as given; T : (N, 4, 4) float64 T_base_flange, metres.
    warnings : notes about normalised rows. source : the file's name, for messages."""

    names: tuple[str, ...]
    T: np.ndarray
    source: str
    warnings: tuple[str, ...] = field(default=())


def _number(value, where: str, what: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{where}: {what} is not a number ({value!r})") from None
    if not math.isfinite(v):
        raise InputError(f"{where}: {what} is {value!r}, not a finite number")
    return v


def _check_translation(t: np.ndarray, where: str) -> None:
    d = float(np.linalg.norm(t))
    if d > MAX_TRANSLATION_M:
        raise InputError(f"{where}: translation {d:.4g} m from the base is over {MAX_TRANSLATION_M:g} m; "
                         "the poses look like millimetres (give metres)")


def _from_quaternion(values: dict, where: str, warnings: list) -> np.ndarray:
    t = np.array([_number(values.get(k), where, k) for k in "xyz"])
    q = np.array([_number(values.get(k), where, k) for k in ("qx", "qy", "qz", "qw")])
    n = float(np.linalg.norm(q))
    if abs(n - 1.0) > QUAT_TOL:
        raise InputError(f"{where}: quaternion norm {n:.6g} is not 1 (qx qy qz qw must be a unit quaternion, x y z w)")
    if abs(n - 1.0) > 1e-6:  # beyond the rounding of printed numbers
        warnings.append(f"{where}: quaternion norm {n:.7g} normalised to 1")
    _check_translation(t, where)
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = quat_to_matrix(q / n), t
    return T


def _from_matrix(m, where: str, warnings: list) -> np.ndarray:
    flat = np.ravel(np.asarray(m, dtype=object))
    if flat.size != 16:
        raise InputError(f"{where}: matrix has {flat.size} numbers, not 16 (a 4×4 T_base_flange, row-major)")
    T = np.array([_number(v, where, "matrix") for v in flat]).reshape(4, 4)
    if not np.allclose(T[3], [0, 0, 0, 1], atol=1e-9):
        raise InputError(f"{where}: matrix's last row is {T[3].tolist()}, not [0, 0, 0, 1]")
    R = T[:3, :3]
    err = float(np.max(np.abs(R.T @ R - np.eye(3))))
    if err > ROT_TOL or np.linalg.det(R) <= 0:
        raise InputError(f"{where}: matrix's 3×3 block is not a rotation (|RᵀR − I| = {err:.3g}, det {np.linalg.det(R):.3g})")
    if err > 1e-12:
        u, _, vt = np.linalg.svd(R)
        T[:3, :3] = u @ vt
        if err > 1e-9:
            warnings.append(f"{where}: rotation re-orthonormalised (|RᵀR − I| was {err:.2g})")
    _check_translation(T[:3, 3], where)
    return T


def _entry(values: dict, where: str, warnings: list) -> tuple[str, np.ndarray]:
    name = values.get("image")
    if name is None or str(name).strip() == "":
        raise InputError(f"{where}: no image name")
    if values.get("matrix") is not None:
        return str(name).strip(), _from_matrix(values["matrix"], where, warnings)
    missing = [k for k in CSV_COLUMNS[1:] if k not in values]
    if missing:
        raise InputError(f"{where}: missing {', '.join(missing)} (give x y z qx qy qz qw, or a 4×4 matrix)")
    return str(name).strip(), _from_quaternion(values, where, warnings)


def _csv_rows(text: str, source: str) -> list[tuple[str, dict]]:
    reader = csv.reader(io.StringIO(text))
    rows = [r for r in reader if any(c.strip() for c in r) and not r[0].lstrip().startswith("#")]
    if not rows:
        raise InputError(f"{source}: no rows")
    header = [c.strip().lower() for c in rows[0]]
    missing = [c for c in CSV_COLUMNS if c not in header]
    if missing:
        raise InputError(f"{source}: missing column(s) {', '.join(missing)} (the header must name "
                         f"{','.join(CSV_COLUMNS)})")
    out = []
    for k, r in enumerate(rows[1:], start=2):
        if len(r) < len(header):
            raise InputError(f"{source} row {k}: {len(r)} values for {len(header)} columns")
        values = dict(zip(header, (c.strip() for c in r)))
        out.append((f"{source} row {k} ({values.get('image', '')})", values))
    return out


def _node(n):
    """An OpenCV FileNode -> Python (dicts, lists, floats, strings)."""
    if n.isMap():
        return {k: _node(n.getNode(k)) for k in n.keys()}
    if n.isSeq():
        return [_node(n.at(i)) for i in range(n.size())]
    if n.isString():
        return n.string()
    if n.isInt() or n.isReal():
        return n.real()
    return None


def _yaml(text: str, source: str):
    from aicalib_tf.calib.schema import MAX_DEPTH, yaml_depth

    if yaml_depth(text) > MAX_DEPTH:  # OpenCV's parser (and _node) recurse: a deep file overflows the stack
        raise InputError(f"{source}: nested more than {MAX_DEPTH} levels deep; not read (the limit guards the parser)")
    tag = re.search(r"!!(?!opencv-matrix(?![\w-]))\S*", text)
    if tag:  # OpenCV's base64 reader (!!binary) can loop forever on bad input
        raise InputError(f"{source}: holds the YAML tag {tag[0][:40]!r}; only !!opencv-matrix is read")
    flags = cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY | cv2.FILE_STORAGE_FORMAT_YAML
    try:
        fs = cv2.FileStorage(text, flags)
        data = _node(fs.root())
        fs.release()
    except cv2.error as exc:
        raise InputError(f"{source}: not YAML that OpenCV reads ({str(exc).strip().splitlines()[-1][:120]})") from None
    return data


def _list_rows(data, source: str) -> list[tuple[str, dict]]:
    if isinstance(data, dict) and "poses" in data:
        data = data["poses"]
    if isinstance(data, dict):  # {image name: entry}
        data = [{"image": k, **(v if isinstance(v, dict) else {"matrix": v})} for k, v in data.items()]
    if not isinstance(data, list) or not data:
        raise InputError(f"{source}: expected a list of poses (or {{'poses': [...]}}), got {type(data).__name__}")
    out = []
    for k, e in enumerate(data):
        if not isinstance(e, dict):
            raise InputError(f"{source} entry {k}: expected a mapping with image and x y z qx qy qz qw (or matrix)")
        out.append((f"{source} entry {k} ({e.get('image', '')})", e))
    return out


def parse_poses(text: str, source: str, kind: str | None = None) -> RobotPoses:
    """Poses from a file's text. kind : "csv", "json" or "yaml" (None: from ``source``'s extension,
    else CSV). Raises :class:`~aicalib_tf.cli.InputError` naming ``source`` and the row."""
    from aicalib_tf.jsonio import loads

    kind = kind or {".json": "json", ".yaml": "yaml", ".yml": "yaml"}.get(Path(source).suffix.lower(), "csv")
    if kind == "csv":
        rows = _csv_rows(text, source)
    elif kind == "json":
        try:
            rows = _list_rows(loads(text, source), source)
        except InputError:
            raise
        except ValueError as exc:
            raise InputError(f"{source}: not valid JSON ({exc})") from None
    else:
        rows = _list_rows(_yaml(text, source), source)
    warnings: list[str] = []
    names, Ts, seen = [], [], {}
    for where, values in rows:
        name, T = _entry(values, where, warnings)
        if name in seen:
            raise InputError(f"{where}: a second pose for image {name} (the first is {seen[name]})")
        seen[name] = where
        names.append(name)
        Ts.append(T)
    if not Ts:
        raise InputError(f"{source}: no poses")
    return RobotPoses(tuple(names), np.array(Ts), source, tuple(warnings))


def read_poses(path) -> RobotPoses:
    """:func:`parse_poses` of a file (CSV, .json, .yaml/.yml). OSError for a missing file."""
    from aicalib_tf.jsonio import read_text

    name = Path(path).name
    return parse_poses(read_text(path, max_bytes=_MAX_BYTES), name)


def match_poses(poses: RobotPoses, images: list[str]) -> tuple[dict[str, np.ndarray], list[str], list[str]]:
    """Match pose rows to image labels by file name, else by stem (name without extension).

    images : image labels (file names). Returns ({image label: (4, 4) T_base_flange}, unmatched
    image labels, unmatched row names). A stem shared by two images is not used for matching.
    """
    by_name = {PurePath(n.replace("\\", "/")).name: k for k, n in enumerate(poses.names)}
    by_stem: dict[str, int | None] = {}
    for n, k in by_name.items():
        stem = PurePath(n).stem
        by_stem[stem] = None if stem in by_stem else k
    image_stems: dict[str, int] = {}
    for img in images:
        s = PurePath(img).stem
        image_stems[s] = image_stems.get(s, 0) + 1
    matched, used, lonely = {}, set(), []
    for img in images:
        name = PurePath(img).name
        k = by_name.get(name)
        if k is None and image_stems[PurePath(img).stem] == 1:
            k = by_stem.get(PurePath(img).stem)
        if k is None or k in used:
            lonely.append(img)
            continue
        used.add(k)
        matched[img] = poses.T[k]
    rows = [n for k, n in enumerate(poses.names) if k not in used]
    return matched, lonely, rows
