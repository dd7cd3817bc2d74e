"""Kalibr ``camchain.yaml``: the calibration as Kalibr and tools built on it (basalt, OpenVINS, VINS) read it.

One entry per camera (``cam0``, ``cam1``, ...):

* ``camera_model``: ``pinhole`` (plumb_bob, equidistant), ``ds`` or ``eucm``;
* ``intrinsics``: [fu, fv, pu, pv] for pinhole, [ξ, α, fu, fv, pu, pv] for ds, [α, β, fu, fv, pu, pv]
  for eucm (px);
* ``distortion_model``: ``radtan`` (plumb_bob: [k1, k2, r1, r2] = OpenCV's k1 k2 p1 p2; Kalibr has
  no k3, so a non-zero k3 is left out and a comment says so: calibrate with ``--fix-k3`` for an exact
  file), ``equidistant`` ([k1, k2, k3, k4], as ``cv2.fisheye``) or ``none`` (ds, eucm);
* ``distortion_coeffs``, ``resolution`` [width, height] px, ``cam_overlaps``, ``rostopic``;
* for cameras after the first of a rig, ``T_cn_cnm1``: the 4×4 transform taking points from the
  previous camera's frame to this one's, translation in metres (mm, cm, m and in board units are
  converted; a unitless board is written as it is, and a comment says so).

The rational and thin-prism models have no Kalibr counterpart: their file holds a comment that says
so and no camera. :func:`load_camchain` reads what :func:`to_camchain_yaml` writes (a small reader:
mappings by indentation, flow lists, block lists of flow lists) without PyYAML.
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.calib.quality import lens_of

__all__ = ["camchain_entry", "to_camchain_yaml", "load_camchain", "METRES_PER_UNIT"]

METRES_PER_UNIT = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}


def _num(v: float) -> str:
    return repr(float(v))


def _flow(values) -> str:
    return "[" + ", ".join(_num(v) for v in np.ravel(values)) + "]"


def camchain_entry(cal) -> tuple[dict | None, str]:
    """(Kalibr fields of one camera or None when its model has none, a comment ("" when none))."""
    lens = lens_of(cal)
    names = lens.spec.NAMES["kalibr"]
    if names is None:
        return None, f"{lens.model} has no Kalibr camera model; no camera is written"
    camera_model, distortion = names
    k = [lens.fx, lens.fy, lens.cx, lens.cy]
    d, note = list(lens.dist), ""
    if camera_model != "pinhole":  # ds, eucm: the model's coefficients lead the intrinsics
        k, d = d + k, []
    elif distortion == "radtan":
        if d[4] != 0.0:
            note = f"k3 = {float(d[4])!r} is left out (Kalibr's radtan has none): this camera's file is approximate"
        d = d[:4]
    w, h = lens.image_size
    return {"camera_model": camera_model, "intrinsics": k, "distortion_model": distortion,
            "distortion_coeffs": d, "resolution": [int(w), int(h)]}, note


def _relative(R, T, n: int) -> np.ndarray:
    """4×4 transform from camera n−1 to camera n, from X_k = R_k·X_0 + T_k."""
    Rr = R[n] @ R[n - 1].T
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = Rr, T[n] - Rr @ T[n - 1]
    return M


def _camera_text(index: int, n_cams: int, entry: dict, T: np.ndarray | None) -> str:
    lines = [f"cam{index}:"]
    if T is not None:
        lines.append("  T_cn_cnm1:")
        lines += [f"  - {_flow(row)}" for row in T]
    lines += [f"  camera_model: {entry['camera_model']}", f"  intrinsics: {_flow(entry['intrinsics'])}",
              f"  distortion_model: {entry['distortion_model']}",
              f"  distortion_coeffs: {_flow(entry['distortion_coeffs'])}",
              f"  resolution: [{entry['resolution'][0]}, {entry['resolution'][1]}]",
              "  cam_overlaps: [" + ", ".join(str(i) for i in (index - 1, index + 1) if 0 <= i < n_cams) + "]",
              f"  rostopic: /cam{index}/image_raw"]
    return "\n".join(lines) + "\n"


def to_camchain_yaml(cal_or_rig) -> str:
    """Kalibr ``camchain.yaml`` text of a :class:`~aicalib_tf.calib.fit.Calibration` (one camera) or a
    :class:`~aicalib_tf.calib.rig.result.RigCalibration` (its ``cameras`` with ``R`` and ``T``)."""
    cams = list(getattr(cal_or_rig, "cameras", None) or [cal_or_rig])
    R, T = getattr(cal_or_rig, "R", None), getattr(cal_or_rig, "T", None)
    head = ["# Kalibr camchain, written by aicalib_tf"]
    scale = 1.0
    if R is not None and len(cams) > 1:
        unit = getattr(cams[0], "square_unit", "")
        scale = METRES_PER_UNIT.get(unit, 1.0)
        if unit not in METRES_PER_UNIT:
            head.append(f"# T_cn_cnm1 translations are in board units ({unit or 'unitless'}), not metres")
    entries = [camchain_entry(c) for c in cams]
    head += [f"# cam{i}: {note}" for i, (_, note) in enumerate(entries) if note]
    if any(e is None for e, _ in entries):
        return "\n".join(head) + "\n{}\n"
    body = []
    for i, (entry, _) in enumerate(entries):
        M = None
        if i > 0:
            M = _relative(np.asarray(R, np.float64), np.asarray(T, np.float64) * scale, i)
        body.append(_camera_text(i, len(entries), entry, M))
    return "\n".join(head) + "\n" + "".join(body)


def _value(text: str):
    text = text.strip()
    if text.startswith("[") and text.endswith("]"):
        inner = text[1:-1].strip()
        return [_value(v) for v in inner.split(",")] if inner else []
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return text


def load_camchain(text: str) -> dict:
    """Parse the ``camchain.yaml`` text :func:`to_camchain_yaml` writes: {"cam0": {field: value}, ...}
    (numbers as int or float, flow lists as lists, ``T_cn_cnm1`` as a list of rows). Raises ValueError."""
    out: dict = {}
    cam = key = None
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].rstrip()
        if not line.strip() or line.strip() == "{}":
            continue
        if not line.startswith(" ") and line.endswith(":"):
            cam = out.setdefault(line[:-1], {})
        elif cam is not None and line.startswith("  - ") and key is not None:
            cam[key].append(_value(line[4:]))
        elif cam is not None and line.startswith("  ") and ":" in line:
            key, _, rest = line.strip().partition(":")
            cam[key] = _value(rest) if rest.strip() else []
        else:
            raise ValueError(f"camchain line {n}: cannot read {raw!r}")
    return out
