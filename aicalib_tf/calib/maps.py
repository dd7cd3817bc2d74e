"""Dense undistortion maps for lens models that no OpenCV model holds (the spline, Double Sphere, EUCM).

OpenCV's ``initUndistortRectifyMap`` cannot rebuild such a camera from ``camera.yaml``, so the
calibration folder also holds the maps themselves, ready for ``cv2.remap``:

* ``undistort_map_x.npy``, ``undistort_map_y.npy``: float32 (H, W) arrays (numpy's ``.npy`` format:
  ``numpy.load`` reads them; no pickle, no aicalib_tf needed), for each pixel of the undistorted image
  the (x, y) px of the source pixel in the photo; −1 where the output pixel has no source;
* in ``camera.json``, ``undistort_maps``: {"files", "camera_matrix" (3×3: the undistorted image's
  pinhole camera, :func:`~aicalib_tf.calib.files.undistort_camera_matrix` with alpha 0), "image_size"}.

Use::

    import cv2, numpy as np
    mx, my = np.load("undistort_map_x.npy"), np.load("undistort_map_y.npy")
    ideal = cv2.remap(cv2.imread("photo.png"), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)

The maps are computed in bands of rows (:func:`aicalib_tf.geometry.lens.undistort_maps`), so a 12 MP
image needs little more memory than the two maps.
"""

from __future__ import annotations

import io

import numpy as np

from aicalib_tf.io import atomic_write_bytes

__all__ = ["needs_maps", "undistort_map_arrays", "map_files", "map_entry", "MAP_FILES"]

MAP_FILES = ("undistort_map_x.npy", "undistort_map_y.npy")


def needs_maps(lens) -> bool:
    """True when no OpenCV model holds the lens (its model's ``NAMES["opencv"]`` is None)."""
    return lens.spec.NAMES.get("opencv") is None


def undistort_map_arrays(lens, new_K, circle=None) -> tuple[np.ndarray, np.ndarray]:
    """(map_x, map_y) float32 (H, W) px of ``lens.image_size``: :meth:`~aicalib_tf.geometry.lens.Lens.undistort_maps`
    towards the pinhole camera ``new_K`` (3, 3); −1 where no source pixel."""
    return lens.undistort_maps(new_K=np.asarray(new_K, np.float64), new_size=lens.image_size, circle=circle)


def _npy_bytes(arr: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(arr, np.float32), allow_pickle=False)
    return buf.getvalue()


def map_files(lens, new_K, folder, circle=None) -> dict:
    """Write :data:`MAP_FILES` into ``folder`` (atomically); returns camera.json's ``undistort_maps`` entry."""
    mx, my = undistort_map_arrays(lens, new_K, circle)
    for name, arr in zip(MAP_FILES, (mx, my)):
        atomic_write_bytes(folder / name, _npy_bytes(arr))
    return map_entry(lens, new_K)


def map_entry(lens, new_K) -> dict:
    """camera.json's ``undistort_maps`` entry (module docstring)."""
    return {"files": list(MAP_FILES), "camera_matrix": np.asarray(new_K, np.float64).tolist(),
            "image_size": [int(s) for s in lens.image_size]}
