"""The sector test: an object's edge on a full board against a shadow edge across its corners."""

import cv2
import numpy as np

from aicalib_tf.detect.chessboard.occlusion import object_in_front, object_in_front_at, sector_contrast

PATTERN = (9, 6)
STEP = 30.0
ORIGIN = 40.0


def _board(shape=(260, 340)) -> tuple[np.ndarray, np.ndarray]:
    """A sharp 10 × 7 square board (float32 in [0, 1], dark 0.15, light 0.85) and its (54, 2) inner corners."""
    y, x = np.mgrid[: shape[0], : shape[1]].astype(np.float64)
    cx, cy = np.floor((x + 0.5 - ORIGIN) / STEP), np.floor((y + 0.5 - ORIGIN) / STEP)
    inside = (cx >= -1) & (cx <= PATTERN[0] - 1) & (cy >= -1) & (cy <= PATTERN[1] - 1)
    img = np.where(inside, np.where((cx + cy) % 2 == 0, 0.15, 0.85), 0.85)
    cols, rows = PATTERN
    corners = np.array([[ORIGIN + c * STEP - 0.5, ORIGIN + r * STEP - 0.5] for r in range(rows) for c in range(cols)])
    return img.astype(np.float32), corners


def _ring(img: np.ndarray) -> np.ndarray:
    return cv2.GaussianBlur(img, (0, 0), 1.0)


def test_clean_board_alternates_everywhere():
    img, corners = _board()
    contrast = sector_contrast(corners.reshape(6, 9, 2), _ring(img))
    assert (contrast > 1.0).all()
    assert not object_in_front(corners, PATTERN, _ring(img))


def test_shadow_edge_across_corners_is_no_object():
    img, corners = _board()
    y, x = np.mgrid[: img.shape[0], : img.shape[1]]
    shadowed = img * np.where(x + 0.6 * y > 250, 0.35, 1.0).astype(np.float32)  # crosses several corners
    assert (sector_contrast(corners.reshape(6, 9, 2), _ring(shadowed)) > 0).all()
    assert not object_in_front(corners, PATTERN, _ring(shadowed))


def test_point_on_an_objects_edge_is_found():
    img, corners = _board()
    k = 2 * PATTERN[0] + PATTERN[0] - 1  # the last corner of row 2, on the outer ring
    x, y = corners[k]
    img[int(y - 20): int(y + 20), int(x - 2):] = 0.5  # an object over its right half, 2 px past it
    moved = corners.copy()
    moved[k, 0] -= 2.0  # the grid's point on the object's edge
    assert object_in_front(moved, PATTERN, _ring(img))
    region = lambda x0, y0, x1, y1: img[y0:y1, x0:x1]  # noqa: E731
    assert object_in_front_at(region, (img.shape[1], img.shape[0]), moved, PATTERN)
