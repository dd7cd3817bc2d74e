"""Drawing a detection over its image, for previews and reports.
"""

from __future__ import annotations

import textwrap

import cv2
import numpy as np

from aicalib_tf.detect.detection import Detection
from aicalib_tf.io import quantize

__all__ = ["draw_detection"]


def draw_detection(gray: np.ndarray, det: Detection) -> np.ndarray:
    """An overlay: (H, W, 3) uint8 BGR with the corners, row lines and corner (0, 0) marked (red)."""
    img = cv2.cvtColor(quantize(gray), cv2.COLOR_GRAY2BGR)
    if not det.found:
        cv2.putText(img, "no board", (10, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (0, 0, 255), 2)
        for k, line in enumerate(textwrap.wrap(det.reason, 60)):  # why, in lines that fit a 640 px image
            cv2.putText(img, line, (10, 55 + 18 * k), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 255), 1, cv2.LINE_AA)
        return img
    for r in np.unique(det.ids[:, 1]):  # a partial board's rows too: its corners are ordered by id
        row = det.corners[det.ids[:, 1] == r]
        colour = tuple(int(c) for c in cv2.applyColorMap(np.uint8([[40 * int(r) % 255]]), cv2.COLORMAP_JET)[0, 0])
        cv2.polylines(img, [np.round(row * 16).astype(np.int32)], False, colour, 1, cv2.LINE_AA, shift=4)
    first = (det.ids == 0).all(axis=1)
    for (x, y), is_first in zip(det.corners, first):
        cv2.circle(img, (int(round(x * 16)), int(round(y * 16))), 4 * 16, (0, 0, 255) if is_first else (0, 255, 0), 1,
                   cv2.LINE_AA, shift=4)
    if not det.complete:
        cv2.putText(img, f"partial: {len(det.corners)} corners", (10, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (0, 200, 255), 2)
    return img


