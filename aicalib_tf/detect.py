"""Chessboard detection with the CNN: image -> ordered board (``python -m aicalib_tf.detect``).

Pipeline: CNN corner weights -> peaks (:mod:`aicalib_tf.inference`) -> saddle-point refinement
on the original image (:mod:`aicalib_tf.refine`) -> grid assembly (:mod:`aicalib_tf.grid`) ->
ordered board.

Order of a full board (OpenCV's, row-major: index = r·cols + c). A board read from the front
keeps its handedness, so only its rotations are ambiguous: 180°, and 90° too for a square
pattern. They are resolved like ``cv2.findChessboardCorners`` (measured on data_gen boards):

* cols + rows odd (e.g. 9x6): the board's colours tell 180° apart. Corner 0 is the one whose
  outer diagonal square is black (the square beyond it, away from corners 1 and ``cols``). It is
  decided by a vote of all inner squares, so it never samples outside the board.
* otherwise (both even or both odd): the reading whose last row starts lowest in the image
  relative to corner 0 (largest y[(rows−1)·cols] − y[0]). OpenCV reverses its order when that
  difference is negative; the two agree whenever one reading has it positive and the other negative.
* square patterns: of the four rotations, the one with the largest (x[cols−1] − x[0]) +
  (y[(rows−1)·cols] − y[0]): rows run most nearly left to right and top to bottom.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .grid import Grid, assemble_grids
from .io import load_image
from .refine import refine_saddle

__all__ = ["Detection", "detect_corners", "find_chessboard_corners", "order_full_board"]


@dataclass(frozen=True)
class Detection:
    """A detected chessboard.

    corners : (N, 2) float32 (x, y) px, in OpenCV order when ``complete``.
    ids : (N, 2) int32, (col, row) of each corner on the board.
    scores : (N,) float32 CNN corner weights in [0, 1]; 0 for a corner the CNN missed that was
        recovered where the grid predicts one (saddle fit and ring test on the image).
    pattern_size : (cols, rows) inner corners (the found grid's size when none was given).
    complete : every corner of ``pattern_size`` is present.
    image_size : (width, height) px.
    """

    corners: np.ndarray
    ids: np.ndarray
    scores: np.ndarray
    pattern_size: tuple[int, int] | None
    complete: bool
    image_size: tuple[int, int]

    @property
    def found(self) -> bool:
        return len(self.corners) > 0


_DEFAULT_MODEL = None
MAX_CANDIDATES = 3000  # a 20x15 board has 300 corners; more candidates are clutter


def _default_model():
    global _DEFAULT_MODEL
    if _DEFAULT_MODEL is None:
        from .model import load_model

        _DEFAULT_MODEL = load_model("default")
    return _DEFAULT_MODEL


class _Smoothed:
    """The image smoothed for each refinement radius r (σ = 0.4·r), made once per image on demand."""

    def __init__(self, gray: np.ndarray):
        self.gray, self.cache = gray, {}

    def __getitem__(self, r: int) -> np.ndarray:
        if r not in self.cache:
            self.cache[r] = cv2.GaussianBlur(self.gray, (0, 0), 0.4 * r)
        return self.cache[r]


def _radius(spacing: np.ndarray) -> np.ndarray:
    """Refinement window half-size (px) that fits inside squares of ``spacing`` px: 2..5."""
    return np.clip(np.round(0.45 * np.asarray(spacing, np.float64)), 2, 5).astype(int)


def _refine(smoothed: _Smoothed, pts: np.ndarray, spacing: np.ndarray, max_shift: np.ndarray | None = None):
    """Saddle refinement with a window that fits inside the local squares.

    pts : (N, 2). spacing : (N,) px, the local corner spacing. max_shift : (N,) px or None.
    Returns refined (N, 2) float32 and ok (N,) bool.
    """
    radius = _radius(spacing)
    out = np.asarray(pts, np.float32).copy()
    ok = np.zeros(len(pts), bool)
    for r in np.unique(radius):
        sel = radius == r
        out[sel], ok[sel] = refine_saddle(smoothed[int(r)], pts[sel], sigma=0.0, radius=int(r))
    if max_shift is not None:
        ok &= np.linalg.norm(out - pts, axis=1) <= max_shift
    return out, ok


def _nearest_spacing(pts: np.ndarray) -> np.ndarray:
    """(N,) distance from each point to its nearest other point (px); 8 when alone."""
    if len(pts) < 2:
        return np.full(len(pts), 8.0)
    d2 = ((pts[:, None, :] - pts[None, :, :]) ** 2).sum(-1)
    np.fill_diagonal(d2, np.inf)
    return np.sqrt(d2.min(axis=1))


def _dedupe(pts: np.ndarray, scores: np.ndarray, min_distance: float = 1.5) -> np.ndarray:
    """Indices of points to keep: of points closer than ``min_distance`` px, only the strongest."""
    order = np.argsort(-scores, kind="stable")
    d2 = ((pts[order, None, :] - pts[None, order, :]) ** 2).sum(-1)
    close = d2 < min_distance**2
    alive = np.ones(len(order), bool)
    for a in range(len(order)):
        if alive[a]:
            close_after = close[a].copy()
            close_after[: a + 1] = False
            alive &= ~close_after
    return order[alive]


_RING = np.stack([np.cos(np.linspace(0, 2 * np.pi, 16, endpoint=False)),
                  np.sin(np.linspace(0, 2 * np.pi, 16, endpoint=False))], 1)


def ring_symmetry(gray: np.ndarray, pts: np.ndarray, radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """X-junction evidence on a ring around each point.

    An X-junction is point-symmetric (I(p + d) = I(p − d)) and its ring alternates two dark and
    two bright arcs. gray : (H, W) float32. pts : (M, 2) px. radius : (M,) px.
    Returns amplitude (M,) (mean |I − mean| on the ring) and asymmetry (M,) (mean |I(θ) − I(θ + π)|).
    """
    xy = pts[:, None, :] + radius[:, None, None] * _RING[None]
    ring = cv2.remap(gray, xy[..., 0].astype(np.float32), xy[..., 1].astype(np.float32), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)
    amp = np.abs(ring - ring.mean(axis=1, keepdims=True)).mean(axis=1)
    asym = np.abs(ring[:, :8] - ring[:, 8:]).mean(axis=1)
    return amp, asym


def _proposer(smoothed: _Smoothed, ring_image: np.ndarray, ref_amp: float):
    """Look for a corner at each grid prediction: saddle refinement plus the ring test."""

    def propose(pred: np.ndarray, step: np.ndarray) -> np.ndarray:
        out = np.full(pred.shape, np.nan)
        h, w = ring_image.shape
        inside = (pred[:, 0] >= 1) & (pred[:, 0] <= w - 2) & (pred[:, 1] >= 1) & (pred[:, 1] <= h - 2)
        k = np.flatnonzero(inside)
        if len(k) == 0:
            return out
        q, ok = _refine(smoothed, pred[k], step[k], max_shift=0.3 * step[k])
        amp, asym = ring_symmetry(ring_image, q.astype(np.float64), 0.3 * step[k])
        ok &= (amp >= 0.3 * ref_amp) & (asym <= 0.5 * amp)  # a T-junction at a board edge has asym ≈ 1.3·amp
        out[k[ok]] = q[ok]
        return out

    return propose


def _parity_contrast(corners: np.ndarray, pattern_size: tuple[int, int], gray: np.ndarray) -> float:
    """Mean grey of the inner squares of odd parity minus that of even parity.

    corners : (cols·rows, 2) in a row-major reading. Inner square (c, r), between corners (c−1, r−1)
    and (c, r), has the colour of board square (c, r): black when c + r is even (the square
    outside corner 0 is black). So the reading that puts corner 0 at the black outer square gives
    a positive value. Every sampled square lies inside the board, hence inside the image.
    """
    cols, rows = pattern_size
    g = corners.reshape(rows, cols, 2)
    centres = 0.25 * (g[:-1, :-1] + g[1:, :-1] + g[:-1, 1:] + g[1:, 1:])  # (rows-1, cols-1, 2)
    rr, cc = np.meshgrid(np.arange(1, rows), np.arange(1, cols), indexing="ij")
    grey = cv2.remap(gray, centres[..., 0].astype(np.float32), centres[..., 1].astype(np.float32), cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)
    even = (rr + cc) % 2 == 0
    return float(grey[~even].mean() - grey[even].mean())


def order_full_board(corners: np.ndarray, pattern_size: tuple[int, int], gray: np.ndarray) -> np.ndarray:
    """Reorder a full board's corners (any admissible reading) by the module's rule.

    corners : (cols·rows, 2) in some row-major reading of the board with the right handedness.
    Returns the (cols·rows, 2) corners in the rule's order.
    """
    return corners[_reading(corners, pattern_size, gray)]


def _reading(corners: np.ndarray, pattern_size: tuple[int, int], gray: np.ndarray) -> np.ndarray:
    """The board symmetry (a (cols·rows,) index permutation) that puts ``corners`` in the rule's order."""
    from .metrics import board_symmetries

    cols, rows = pattern_size
    best, best_key = None, None
    for perm in board_symmetries(pattern_size):
        c = corners[perm]
        dy = c[(rows - 1) * cols, 1] - c[0, 1]
        dx = c[cols - 1, 0] - c[0, 0]
        if (cols + rows) % 2 == 1 and cols != rows:
            key = (_parity_contrast(c, pattern_size, gray), 0.0)
        elif cols == rows:
            key = (float(dx + dy), 0.0)
        else:
            key = (float(dy), float(dx))
        if best_key is None or key > best_key:
            best, best_key = perm, key
    return best


def _handed(grid_ij: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Flip j if needed so that the i and j directions have the image's handedness (x right, y down).

    A board seen from the front keeps its handedness, so the board's (col, row) axes must too.
    """
    a = np.concatenate([grid_ij.astype(np.float64), np.ones((len(grid_ij), 1))], axis=1)
    (u, v, _), *_ = np.linalg.lstsq(a, pts.astype(np.float64), rcond=None)
    if u[0] * v[1] - u[1] * v[0] < 0:
        return np.stack([grid_ij[:, 0], grid_ij[:, 1].max() - grid_ij[:, 1]], 1)
    return grid_ij


def _board_from_grid(grid: Grid, scores, pattern_size, gray, size) -> Detection | None:
    ij = _handed(grid.ij, grid.points)
    a, b = grid.shape
    if pattern_size is None:
        cols, rows = a, b
    else:
        cols, rows = pattern_size
        if (a, b) == (rows, cols) and a != b:
            # the grid's i runs along the board's rows: swap roles, keeping handedness
            ij = np.stack([ij[:, 1], ij[:, 0]], 1)
            ij = np.stack([ij[:, 0], ij[:, 1].max() - ij[:, 1]], 1)
            a, b = b, a
        if (a, b) != (cols, rows):
            return None  # a different (e.g. bigger) board, or a partial one: never cut to size
    full = len(grid) == cols * rows
    if not full:
        return None
    corners = np.zeros((cols * rows, 2), np.float32)
    sc = np.zeros(cols * rows, np.float32)
    idx = ij[:, 1] * cols + ij[:, 0]
    corners[idx] = grid.points
    sc[idx] = np.where(grid.index >= 0, scores[grid.index], 0.0)
    perm = _reading(corners, (cols, rows), gray)
    ids = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), -1).reshape(-1, 2).astype(np.int32)
    return Detection(corners[perm], ids, sc[perm], (cols, rows), True, size)


def detect_corners(image, pattern_size: tuple[int, int] | None = None, *, model=None,
                   threshold: float = 0.5) -> Detection:
    """Find a chessboard's inner corners.

    image : path or array (see :func:`aicalib_tf.io.load_image`).
    pattern_size : (cols, rows) inner corners; None returns the largest grid found.
    model : a loaded corner model (default: the shipped ``models/default.keras``).
    Returns a :class:`Detection`; ``found`` is False when no board is there.
    """
    from .inference import corner_points

    gray = load_image(image)
    h, w = gray.shape
    if pattern_size is not None:
        from data_gen.board import check_pattern

        check_pattern(pattern_size)
    empty = Detection(np.zeros((0, 2), np.float32), np.zeros((0, 2), np.int32), np.zeros(0, np.float32),
                      pattern_size, False, (w, h))
    if h < 8 or w < 8:
        return empty
    model = model if model is not None else _default_model()
    pts, scores = corner_points(model, gray, threshold)
    pts, scores = pts[:MAX_CANDIDATES], scores[:MAX_CANDIDATES]  # strongest first; bounds the N² steps
    if len(pts) < 9:
        return empty
    smoothed = _Smoothed(gray)
    refined, ok = _refine(smoothed, pts, _nearest_spacing(pts))
    refined, scores = refined[ok], scores[ok]
    keep = _dedupe(refined, scores)
    refined, scores = refined[keep], scores[keep]
    smooth = cv2.GaussianBlur(gray, (0, 0), 1.0)
    propose = None
    if len(refined) >= 9:
        spacing = _nearest_spacing(refined)
        amp, _ = ring_symmetry(smooth, refined.astype(np.float64), 0.3 * spacing)
        propose = _proposer(smoothed, smooth, float(np.median(amp[: max(9, len(amp) // 2)])))
    # grow one step past the pattern so that a bigger board shows itself and is rejected
    limit = max(pattern_size) + 1 if pattern_size is not None else None
    for grid in assemble_grids(refined, scores, gray=smooth, propose=propose, limit=limit):
        det = _board_from_grid(grid, scores, pattern_size, smooth, (w, h))
        if det is not None:
            return det
    return empty


def find_chessboard_corners(image, pattern_size: tuple[int, int], *, model=None) -> tuple[bool, np.ndarray | None]:
    """Drop-in for ``cv2.findChessboardCorners``: (found, corners (cols·rows, 1, 2) float32 or None)."""
    det = detect_corners(image, pattern_size, model=model)
    if not det.complete:
        return False, None
    return True, det.corners.reshape(-1, 1, 2).copy()


def draw_detection(gray: np.ndarray, det: Detection) -> np.ndarray:
    """An overlay: (H, W, 3) uint8 BGR with the corners, row lines and corner 0 marked."""
    img = cv2.cvtColor(np.clip(gray * 255.0 + 0.5, 0, 255).astype(np.uint8), cv2.COLOR_GRAY2BGR)
    if not det.found:
        cv2.putText(img, "no board", (10, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (0, 0, 255), 2)
        return img
    if det.complete:
        cols = det.pattern_size[0]
        for r in range(len(det.corners) // cols):
            row = det.corners[r * cols : (r + 1) * cols]
            colour = tuple(int(c) for c in cv2.applyColorMap(np.uint8([[40 * r % 255]]), cv2.COLORMAP_JET)[0, 0])
            cv2.polylines(img, [np.round(row * 16).astype(np.int32)], False, colour, 1, cv2.LINE_AA, shift=4)
    for k, (x, y) in enumerate(det.corners):
        cv2.circle(img, (int(round(x * 16)), int(round(y * 16))), 4 * 16, (0, 255, 0) if k else (0, 0, 255), 1,
                   cv2.LINE_AA, shift=4)
    return img


def _parse_args(argv):
    import argparse

    ap = argparse.ArgumentParser(prog="python -m aicalib_tf.detect", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("images", nargs="+", help="image files or glob patterns")
    ap.add_argument("--pattern", required=True, help="inner corners, COLSxROWS, e.g. 9x6")
    ap.add_argument("--out", required=True, help="folder for <image>.png overlays and <image>.json corners")
    ap.add_argument("--model", default="default", help="default, report, or a path to a .keras model (default: %(default)s)")
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    return ap.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Detect boards in images and write overlays and corner files; exit 2 on bad arguments."""
    import os

    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    import glob
    import json
    import sys
    from pathlib import Path

    from tqdm import tqdm

    from data_gen.board import parse_pattern

    from .io import ImageError, atomic_write_bytes, atomic_write_text
    from .model import file_sha256, load_model

    args = _parse_args(argv)
    try:
        pattern = parse_pattern(args.pattern)
        files = []
        for item in args.images:
            matches = sorted(glob.glob(item)) if any(ch in item for ch in "*?[") else [item]
            files += matches
        if not files:
            raise ValueError(f"no images match {' '.join(args.images)}")
        model = load_model(args.model)
    except (ValueError, FileNotFoundError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    sha = file_sha256(model.aicalib_path) if hasattr(model, "aicalib_path") else None
    counts = {"complete": 0, "partial": 0, "none": 0, "failed": 0}
    failures = []
    used: set[str] = set()
    for f in tqdm(files, desc="detect", unit="img", disable=args.quiet):
        try:
            gray = load_image(f)
            det = detect_corners(gray, pattern, model=model)
        except ImageError as exc:
            counts["failed"] += 1
            failures.append(str(exc))
            continue
        counts["complete" if det.complete else "partial" if det.found else "none"] += 1
        stem = Path(f).stem
        if stem in used:  # a/x.jpg and b/x.png must not overwrite each other
            stem = f"{stem}-{len(used)}"
        used.add(stem)
        ok, png = cv2.imencode(".png", draw_detection(gray, det))
        atomic_write_bytes(out / f"{stem}.png", png.tobytes())
        record = {
            "file": str(f), "image_size": list(det.image_size), "pattern_size": list(pattern),
            "found": det.found, "complete": det.complete, "corners": det.corners.tolist(),
            "ids": det.ids.tolist(), "scores": det.scores.tolist(), "model": str(args.model), "model_sha256": sha,
        }
        atomic_write_text(out / f"{stem}.json", json.dumps(record, indent=1) + "\n")
    print(f"{len(files)} images: {counts['complete']} full boards, {counts['partial']} partial, "
          f"{counts['none']} without a board, {counts['failed']} unreadable")
    for msg in failures:
        print(f"  skipped: {msg}")
    return 0


if __name__ == "__main__":
    import sys

    sys.exit(main())
