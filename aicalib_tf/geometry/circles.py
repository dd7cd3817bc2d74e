"""OpenCV's circle grids: one description for detection, calibration and rendered test data.

A grid is ``cols × rows`` dark circles on a light board, in OpenCV's ``patternSize = (cols, rows)``
as ``cv2.findCirclesGrid`` takes it, ``spacing`` (s) apart:

- symmetric: circle (j, i) (column j < cols, row i < rows) sits at (j·s, i·s, 0);
- asymmetric: circle (j, i) sits at ((2j + i % 2)·s, i·s, 0), OpenCV's calibration sample's
  convention: each row holds ``cols`` circles 2s apart, odd rows shifted by s, and the nearest
  centres are s·√2 apart.

Both orders are OpenCV's: ``findCirclesGrid`` returns circle (j, i) at index i·cols + j.

The calibration code places ids on a uniform lattice of unit s, (c·s, r·s, 0). A symmetric grid is
that lattice; an asymmetric grid's circle (j, i) has the sparse lattice id (2j + i % 2, i) on a
lattice of (2·cols, rows) points, half of which hold no circle.

``diameter`` is the circles' diameter: the bias correction of the projected centre
(:mod:`aicalib_tf.calib.circle_bias`) scales with it. When not given it is half the distance
between the nearest centres: s / 2 (symmetric), s·√2 / 2 (asymmetric). OpenCV's printed
``acircles_pattern.png`` and ``circles_pattern`` of its pattern generator keep that ratio or close to it.

Text form: ``circles:4x11,spacing=20mm,asymmetric[,diameter=14mm]`` or
``circles:7x6,spacing=20mm,symmetric``. Pure numpy and OpenCV.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import cv2
import numpy as np

from aicalib_tf.geometry.charuco import UNIT_MM, parse_length
from aicalib_tf.geometry.pattern import board_points

__all__ = ["CircleGrid", "PREFIX", "LAYOUTS", "is_circles", "circle_count", "parse_board", "homography_maps", "pose_maps", "render_view"]

PREFIX = "circles:"
LAYOUTS = ("symmetric", "asymmetric")


@dataclass(frozen=True)
class CircleGrid:
    """A circle grid (see the module docstring).

    grid : (cols, rows), OpenCV's patternSize. spacing : s, in ``unit``. layout : "symmetric" or
    "asymmetric". diameter : the circles' diameter in ``unit`` (0: the default, half the nearest
    centre distance). unit : "mm", "cm", "m", "in" or "" (unitless).
    """

    grid: tuple[int, int]
    spacing: float
    layout: str = "asymmetric"
    diameter: float = 0.0
    unit: str = "mm"

    def __post_init__(self):
        cols, rows = (int(v) for v in self.grid)
        object.__setattr__(self, "grid", (cols, rows))
        if self.layout not in LAYOUTS:
            raise ValueError(f"layout: unknown circle grid layout {self.layout!r}; choose symmetric or asymmetric")
        if cols < 2 or rows < 2 or (self.layout == "symmetric" and min(cols, rows) < 3):
            raise ValueError(f"grid: a {self.layout} circle grid needs at least "
                             f"{'3x3' if self.layout == 'symmetric' else '2x3'} circles, got {cols}x{rows}")
        if self.layout == "asymmetric" and rows < 3:
            raise ValueError(f"grid: an asymmetric circle grid needs at least 3 rows, got {cols}x{rows}")
        if not 0 < float(self.spacing) < 1e6:
            raise ValueError(f"spacing: must be > 0 and under 1e6, got {self.spacing!r}")
        if not self.diameter:
            object.__setattr__(self, "diameter", float(self.nearest / 2))
        if not 0 < float(self.diameter) < self.nearest:
            raise ValueError(f"diameter: circles of diameter {self.diameter:g} touching or overlapping "
                             f"(nearest centres {self.nearest:g}{self.unit} apart)")

    @property
    def nearest(self) -> float:
        """The distance between the nearest centres, in ``unit``."""
        return float(self.spacing) * (np.sqrt(2.0) if self.layout == "asymmetric" else 1.0)

    @property
    def radius(self) -> float:
        return float(self.diameter) / 2

    @property
    def pattern_size(self) -> tuple[int, int]:
        """(cols, rows) of the id lattice."""
        cols, rows = self.grid
        return (2 * cols, rows) if self.layout == "asymmetric" else (cols, rows)

    @property
    def square_size(self) -> float:
        """The lattice unit s, in ``unit``."""
        return float(self.spacing)

    def circle_ids(self) -> np.ndarray:
        """(cols·rows, 2) int64 lattice ids (col, row) in OpenCV's order (index i·cols + j)."""
        cols, rows = self.grid
        i, j = np.mgrid[0:rows, 0:cols]
        i, j = i.ravel(), j.ravel()
        col = 2 * j + i % 2 if self.layout == "asymmetric" else j
        return np.stack([col, i], axis=1).astype(np.int64)

    def object_points(self, ids=None) -> np.ndarray:
        """(N, 3) float64 centres in ``unit`` (all circles by default)."""
        return board_points(self.circle_ids() if ids is None else np.asarray(ids), self.square_size)

    def cv_flags(self) -> int:
        """``cv2.findCirclesGrid``'s flags for this layout."""
        return cv2.CALIB_CB_ASYMMETRIC_GRID if self.layout == "asymmetric" else cv2.CALIB_CB_SYMMETRIC_GRID

    def describe(self) -> str:
        """The text form, which :func:`parse_board` reads back."""
        return (f"{PREFIX}{self.grid[0]}x{self.grid[1]},spacing={self.spacing:g}{self.unit},{self.layout},"
                f"diameter={self.diameter:.12g}{self.unit}")

    def to_dict(self) -> dict:
        return {"type": "circles", "description": self.describe(), "grid": list(self.grid), "spacing": self.spacing,
                "layout": self.layout, "diameter": self.diameter, "unit": self.unit,
                "pattern_size": list(self.pattern_size), "square_size": self.square_size}


def is_circles(text) -> bool:
    """Whether ``text`` names a circle grid (``circles:...``)."""
    return isinstance(text, str) and text.strip().lower().startswith(PREFIX)


def circle_count(description) -> int | None:
    """Circles of the grid that ``description`` names (its text), else None (another board, or text
    that no longer parses): a view with fewer is partial."""
    if not is_circles(description):
        return None
    try:
        board = parse_board(description)
    except ValueError:
        return None
    return board.grid[0] * board.grid[1]


def _length(text: str, field: str) -> tuple[float, str]:
    """(value, unit) of a length field, read by the boards' one length parser (:func:`parse_length`)."""
    return parse_length(text, f"{field}=", "20mm, 2cm or 0.02m")


def parse_board(text: str) -> CircleGrid:
    """Parse ``circles:COLSxROWS,spacing=LEN,symmetric|asymmetric[,diameter=LEN]``.

    Raises ValueError naming the field (missing spacing, unknown layout, circles touching, ...).
    """
    body = str(text).strip()
    if not body.lower().startswith(PREFIX):
        raise ValueError(f"a circle grid must look like circles:4x11,spacing=20mm,asymmetric, got {text!r}")
    parts = [p.strip() for p in body[len(PREFIX):].split(",") if p.strip()]
    m = re.fullmatch(r"(\d+)\s*[xX×]\s*(\d+)", parts[0]) if parts else None
    if not m:
        raise ValueError(f"board {text!r}: first give the circles as COLSxROWS, e.g. 4x11")
    fields, layout = {}, None
    for p in parts[1:]:
        key, eq, value = p.partition("=")
        key = key.strip().lower()
        if not eq and key in LAYOUTS and layout in (None, key):
            layout = key
        elif not eq and key in LAYOUTS:
            raise ValueError(f"board {text!r}: both symmetric and asymmetric; give one layout")
        elif eq and key in ("spacing", "diameter") and key not in fields:
            fields[key] = value
        else:
            raise ValueError(f"board {text!r}: unexpected {p!r} (fields: spacing=, diameter=, symmetric or asymmetric)")
    if "spacing" not in fields:
        raise ValueError(f"board {text!r}: missing spacing= (the distance between neighbouring centres, e.g. 20mm)")
    if layout is None:
        raise ValueError(f"board {text!r}: missing the layout: add symmetric or asymmetric")
    spacing, unit = _length(fields["spacing"], "spacing")
    diameter = 0.0
    if "diameter" in fields:
        diameter, dunit = _length(fields["diameter"], "diameter")
        if dunit != unit:
            if not (dunit and unit):
                raise ValueError(f"board {text!r}: diameter= and spacing= need the same unit")
            diameter *= UNIT_MM[dunit] / UNIT_MM[unit]
        if diameter <= 0:
            raise ValueError(f"board {text!r}: diameter= must be > 0")
    try:
        return CircleGrid((int(m.group(1)), int(m.group(2))), spacing, layout, diameter, unit)
    except ValueError as e:
        raise ValueError(f"board {text!r}: {e}") from None


def homography_maps(H: np.ndarray):
    """(pixel_to_plane, plane_to_pixel) of a homography ``H`` (3×3, board plane → pixel), each
    mapping (N, 2) float64 to (N, 2) float64, for :func:`render_view`."""
    H = np.asarray(H, np.float64)
    Hi = np.linalg.inv(H)

    def apply(M, p):
        q = np.concatenate([p, np.ones((len(p), 1))], axis=1) @ M.T
        return q[:, :2] / q[:, 2:]

    return (lambda p: apply(Hi, p)), (lambda p: apply(H, p))


def pose_maps(K, dist, rvec, tvec, model: str = "plumb_bob"):
    """(pixel_to_plane, plane_to_pixel) of a board seen at pose (rvec, tvec) (board → camera)
    through the lens ``model`` (K (3, 3), dist as the model takes it; :mod:`aicalib_tf.geometry.lens`),
    for :func:`render_view`."""
    from aicalib_tf.geometry.lens import project, unproject

    R, _ = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))
    t = np.asarray(tvec, np.float64).ravel()
    normal, offset = R[:, 2], float(R[:, 2] @ t)

    def to_plane(p):
        ray = unproject(p, model, K, dist)
        X = ray * (offset / (ray @ normal))[:, None]  # the ray meets the board's plane
        return ((X - t) @ R)[:, :2]

    def to_pixel(p):
        q = np.concatenate([p, np.zeros((len(p), 1))], axis=1)
        return project(q @ R.T + t, model, K, dist)

    return to_plane, to_pixel


def render_view(board: CircleGrid, size: tuple[int, int], pixel_to_plane, plane_to_pixel, supersample: int = 4,
                dark: float = 0.1, light: float = 0.9) -> np.ndarray:
    """Render the grid as an (h, w) float32 image in [0, 1] of size (w, h), each pixel the mean of
    ``supersample``² samples (area coverage up to the sampling). ``pixel_to_plane`` maps (N, 2) px
    to board-plane points (N, 2) in ``unit``; ``plane_to_pixel`` the other way (it bounds each
    circle's pixels). Pixel (0, 0)'s centre is at (0.0, 0.0)."""
    w, h = (int(v) for v in size)
    n = int(supersample)
    off = (np.arange(n) + 0.5) / n - 0.5
    cover = np.zeros((h, w), np.float64)
    t = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    ring = board.radius * np.stack([np.cos(t), np.sin(t)], axis=1)
    for c in board.object_points()[:, :2]:
        b = plane_to_pixel(c + ring)
        if not np.all(np.isfinite(b)):
            continue
        x0, y0 = np.maximum(np.floor(b.min(axis=0)).astype(int) - 2, 0)
        x1, y1 = np.minimum(np.ceil(b.max(axis=0)).astype(int) + 3, [w, h])
        if x1 <= x0 or y1 <= y0:
            continue
        ys, xs = np.mgrid[y0:y1, x0:x1].astype(np.float64)
        sx = (xs[..., None, None] + off[None, None, None, :]).repeat(n, axis=2)
        sy = (ys[..., None, None] + off[None, None, :, None]).repeat(n, axis=3)
        q = pixel_to_plane(np.stack([sx.ravel(), sy.ravel()], axis=1))
        inside = np.sum((q - c) ** 2, axis=1) <= board.radius ** 2
        cover[y0:y1, x0:x1] += inside.reshape(sx.shape).mean(axis=(2, 3))
    return (light + (dark - light) * np.clip(cover, 0, 1)).astype(np.float32)
