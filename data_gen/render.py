"""Render a chessboard into an image by inverse mapping with exact distortion inversion.

For every pixel *corner* (the grid of points (u ± 0.5, v ± 0.5)) we unproject exactly
(:meth:`aicalib_tf.geometry.camera.Camera.pixel_to_ray`, i.e. :func:`aicalib_tf.geometry.lens.unproject`)
and intersect the 3-D ray with the board plane through the board homography (a flexed board's
surface by :func:`surface_homogeneous`), so fisheye rays
beyond 90° off-axis work; pixels outside a fisheye's image circle have no ray. A pixel whose four corners fall in one class (black square,
white paper, off the paper) and one square/paper cell is filled directly. Pixels that straddle
an edge are supersampled: the undistorted ray is interpolated bilinearly inside the pixel (the
distortion is smooth on a 1-px scale, error < 1e-4 px) and each sample goes through the exact
homography. Samples sit on a Fibonacci lattice, whose projections on both axes are all distinct,
so even axis-aligned edges are resolved to 1/N of a pixel (N = 89). Pixels within 1 px of an
X-junction or a paper corner, where a lattice aliases most, get N = 233.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from aicalib_tf.geometry.camera import Camera

from .board import Board

__all__ = ["render_board", "fibonacci_lattice", "board_coordinates", "plane_homogeneous", "surface_homogeneous",
           "lens_coverage"]

_FIB = {13: 8, 21: 13, 34: 21, 55: 34, 89: 55, 144: 89, 233: 144}


@functools.lru_cache(maxsize=8)
def fibonacci_lattice(n: int = 89) -> np.ndarray:
    """(n, 2) float64 sample offsets in [0, 1)², from a pixel's top-left corner, as (s, t) = (x, y).

    n must be a Fibonacci number in ``{13, 21, 34, 55, 89, 144, 233}``.
    """
    if n not in _FIB:
        raise ValueError(f"samples must be one of {sorted(_FIB)}, got {n}")
    k = np.arange(n)
    s = (k + 0.5) / n
    t = np.mod(k * _FIB[n] + 0.5, n) / n
    lattice = np.stack([s, t], axis=1)
    lattice.setflags(write=False)  # shared through the cache
    return lattice


def _corner_rays(camera: Camera, box: tuple[int, int, int, int]) -> np.ndarray:
    """Rays at the pixel corners of ``box`` = (x0, y0, x1, y1), pixels x0..x1-1.

    Returns (y1-y0+1, x1-x0+1, 3) float64 (:meth:`Camera.pixel_to_ray`), NaN where not imaged.
    """
    x0, y0, x1, y1 = box
    uu, vv = np.meshgrid(np.arange(x0, x1 + 1) - 0.5, np.arange(y0, y1 + 1) - 0.5)
    return camera.pixel_to_ray(np.stack([uu, vv], axis=-1))


def lens_coverage(camera: Camera, samples_per_axis: int = 4) -> np.ndarray | None:
    """(H, W) float32 fraction of each pixel inside the image circle; None when all of it is inside.

    ``samples_per_axis``² point samples per pixel; a pinhole camera (no circle) gives None.
    """
    if not camera.fisheye:
        return None
    w, h = camera.image_size
    offs = (np.arange(samples_per_axis) + 0.5) / samples_per_axis - 0.5
    uu, vv = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    acc = np.zeros((h, w), np.float32)
    for dy in offs:
        for dx in offs:
            acc += camera.inside_circle(np.stack([uu + dx, vv + dy], axis=-1))
    acc /= samples_per_axis ** 2
    return None if acc.min() >= 1.0 else acc


def _pixel_corners(a: np.ndarray) -> tuple[np.ndarray, ...]:
    """(H+1, W+1) values at pixel corners -> four (H, W) views: top-left, top-right, bottom-left, bottom-right."""
    return a[:-1, :-1], a[:-1, 1:], a[1:, :-1], a[1:, 1:]


def _corner_span(a: np.ndarray) -> np.ndarray:
    """(H+1, W+1) values at pixel corners -> (H, W) bool: do a pixel's four corners differ?"""
    q = _pixel_corners(a)
    return np.maximum.reduce(q) != np.minimum.reduce(q)


def _active_box(camera: Camera, board: Board, rvec, tvec, step: int = 16):
    """Pixel box (x0, y0, x1, y1) that holds all of the paper, or None if none of it is imaged.

    A coarse grid of pixel corners (every ``step`` px) is mapped to the board; a coarse cell is
    kept when its board-space bounding box, padded by a quarter of its size for curvature,
    meets the paper, or when the plane or the lens model ends inside it.
    """
    w, h = camera.image_size
    us = np.append(np.arange(0, w, step), w) - 0.5
    vs = np.append(np.arange(0, h, step), h) - 0.5
    uu, vv = np.meshgrid(us, vs)
    X, Y = board_coordinates(camera.pixel_to_ray(np.stack([uu, vv], axis=-1)), rvec, tvec, board)
    nan = np.stack(_pixel_corners(np.isnan(X) | np.isnan(Y)))  # X and Y are NaN together
    all_nan = nan.all(axis=0)
    # NaN-ignoring ranges over each cell's corners (NaN only where all four are NaN).
    lo_x, hi_x = np.fmin.reduce(_pixel_corners(X)), np.fmax.reduce(_pixel_corners(X))
    lo_y, hi_y = np.fmin.reduce(_pixel_corners(Y)), np.fmax.reduce(_pixel_corners(Y))
    with np.errstate(invalid="ignore"):
        pad_x, pad_y = 0.25 * (hi_x - lo_x), 0.25 * (hi_y - lo_y)
        px0, py0, px1, py1 = board.paper_bounds()
        hit = (hi_x + pad_x >= px0) & (lo_x - pad_x <= px1) & (hi_y + pad_y >= py0) & (lo_y - pad_y <= py1)
    active = (hit & ~all_nan) | (nan.any(axis=0) & ~all_nan)
    if not active.any():
        return None
    rows, cols = np.nonzero(active)
    x0 = max(int(us[cols.min()] + 0.5) - 2, 0)
    x1 = min(int(us[cols.max() + 1] + 0.5) + 2, w)
    y0 = max(int(vs[rows.min()] + 0.5) - 2, 0)
    y1 = min(int(vs[rows.max() + 1] + 0.5) + 2, h)
    return x0, y0, x1, y1


def plane_homogeneous(rays: np.ndarray, rvec, tvec) -> np.ndarray:
    """Board-plane point of each normalized ray in homogeneous form.

    rays : (..., 3) camera-frame rays (any scale, any direction, e.g. unit fisheye rays past
    90°) or (..., 2) undistorted normalized (x, y), meaning (x, y, 1). Returns (..., 3) q with
    board (X, Y) = (q0 / q2, q1 / q2); q2 > 0 exactly when the plane is hit in front along the
    ray. q is linear in the ray, so it may be interpolated wherever the rays may.
    """
    R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    Hi = np.linalg.inv(np.column_stack([R[:, 0], R[:, 1], np.asarray(tvec, dtype=np.float64).ravel()]))
    rays = np.asarray(rays, dtype=np.float64)
    if rays.shape[-1] == 2:
        return rays @ Hi[:, :2].T + Hi[:, 2]
    if rays.shape[-1] != 3:
        raise ValueError(f"rays must have shape (..., 2) or (..., 3), got {rays.shape}")
    return rays[..., :2] @ Hi[:, :2].T + rays[..., 2:3] * Hi[:, 2]  # z = 1 multiplies exactly


def _dehomogenize(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    with np.errstate(divide="ignore", invalid="ignore"):
        front = q[..., 2] > 0
        X = np.where(front, q[..., 0] / q[..., 2], np.nan)
        Y = np.where(front, q[..., 1] / q[..., 2], np.nan)
    return X, Y


def board_coordinates(rays: np.ndarray, rvec, tvec, board=None) -> tuple[np.ndarray, np.ndarray]:
    """Intersect rays ((..., 3), or normalized (..., 2)) with the board (its plane, or its flexed surface when
    ``board`` has a ``flex``: :func:`surface_homogeneous`); returns board X, Y (NaN behind)."""
    return _dehomogenize(surface_homogeneous(rays, rvec, tvec, board))


def surface_homogeneous(rays: np.ndarray, rvec, tvec, board=None, iterations: int = 6) -> np.ndarray:
    """:func:`plane_homogeneous` for a flexed or shaped board (``board.flex`` or ``board.shape`` nonzero; else the
    plane's q itself).

    The ray meets the surface z = board.height(X, Y) (:mod:`aicalib_tf.geometry.board_shape`) by fixed-point
    iteration from the plane's hit: the ray's point at height z(X_k, Y_k) gives (X_k+1, Y_k+1). Each step
    shrinks the error by the surface's slope times the ray's tangent to the board normal (a sag of 0.02
    squares has slopes below 0.1), so ``iterations`` steps reach float precision for rays up to ~80°
    from the normal; a ray still moving by more than 1e-9 squares (grazing the board) keeps the plane's
    hit. Returns (..., 3) q = (X, Y, 1)·q2 with the plane's q2 (its sign says in front).
    """
    q = plane_homogeneous(rays, rvec, tvec)
    if board is None or not (any(getattr(board, "flex", ())) or any(getattr(board, "shape", ()))):
        return q
    R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    t = np.asarray(tvec, dtype=np.float64).ravel()
    rays = np.asarray(rays, dtype=np.float64)
    if rays.shape[-1] == 2:
        rays = np.concatenate([rays, np.ones(rays.shape[:-1] + (1,))], axis=-1)
    o, d = -R.T @ t, rays @ R  # the camera centre and the rays in the board frame
    X, Y = _dehomogenize(q)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for _ in range(iterations):
            s = (board.height(X, Y) - o[2]) / d[..., 2]
            X1, Y1 = o[0] + s * d[..., 0], o[1] + s * d[..., 1]
            step, X, Y = np.abs(X1 - X) + np.abs(Y1 - Y), X1, Y1
        # a ray that did not settle grazes the board far from the paper: it keeps the plane's hit
        hit = np.isfinite(X) & np.isfinite(Y) & (step <= 1e-9 * board.square_size)
        out = np.stack([X * q[..., 2], Y * q[..., 2], q[..., 2]], axis=-1)
    return np.where(hit[..., None], out, q)


def render_board(
    camera: Camera,
    board: Board,
    rvec,
    tvec,
    background: np.ndarray,
    *,
    samples: int = 89,
    junction_samples: int = 233,
) -> np.ndarray:
    """Composite ``board`` seen from pose (rvec, tvec) over ``background``.

    Parameters
    ----------
    camera, board : the scene.
    rvec, tvec : (3,) pose of the board in the camera frame (T_cam_board).
    background : (H, W) float32 in [0, 1], H, W matching ``camera.image_size``.
    samples : supersamples per edge pixel (Fibonacci number, :func:`fibonacci_lattice`); 1: each centre alone (steps).
    junction_samples : supersamples per pixel near an X-junction or a paper corner.

    Returns
    -------
    (H, W) float32 image in [0, 1], anti-aliased, no blur or noise.
    """
    w, h = camera.image_size
    if background.shape != (h, w):
        raise ValueError(f"background must be (H, W) = {(h, w)}, got {background.shape}")
    out = background.astype(np.float32, copy=True)
    box = _active_box(camera, board, rvec, tvec)
    if box is None:
        return out
    if samples == 1:
        return _point_sampled(out, camera, board, rvec, tvec, box)
    bx0, by0, bx1, by1 = box
    crop = out[by0:by1, bx0:bx1]  # a view: writes land in ``out``
    bg = background[by0:by1, bx0:bx1]
    q = surface_homogeneous(_corner_rays(camera, box), rvec, tvec, board)  # (h+1, w+1, 3)
    X, Y = _dehomogenize(q)
    cls = board.classify(X, Y)  # (h+1, w+1) at the box's pixel corners
    c00 = cls[:-1, :-1]
    # A pixel is filled directly only if no square edge or paper edge crosses it: its corners
    # must agree in class *and* in square/paper cell along both board axes (a square thinner
    # than a pixel, or a paper corner poking in, can hide between corners of equal class).
    px0, py0, px1, py1 = board.paper_bounds()
    cross_x = _board_cell_span(X, board, (px0, px1)) & _corner_range_meets(Y, py0, py1)
    cross_y = _board_cell_span(Y, board, (py0, py1)) & _corner_range_meets(X, px0, px1)
    uniform = ~(_corner_span(cls) | cross_x | cross_y)
    # Where two edges meet (X-junctions, paper corners) thin wedges need more samples, in a
    # 1-px ring, on a denser lattice: 89 points alias up to ~8% of the contrast there.
    junction = cv2.dilate((cross_x & cross_y).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)

    on_paper = uniform & (c00 != 2)
    crop[on_paper] = np.array([board.black, board.white], dtype=np.float32)[c00[on_paper]]
    # Pixels that the lens' domain (a fisheye's image circle) cuts: interpolating q from their
    # corners would lose the imaged part, so their samples are unprojected one by one.
    rim = _corner_span(np.isnan(q[..., 2]))
    _supersample(crop, bg, q, board, ~uniform & ~junction & ~rim, samples)
    _supersample(crop, bg, q, board, junction & ~rim, junction_samples)
    _supersample_exact(crop, bg, camera, board, rvec, tvec, (bx0, by0), rim, samples)
    return out


def _point_sampled(out: np.ndarray, camera: Camera, board: Board, rvec, tvec, box) -> np.ndarray:
    """``out`` with the board painted in ``box`` (x0, y0, x1, y1) from one ray through each pixel's centre."""
    x0, y0, x1, y1 = box
    uu, vv = np.meshgrid(np.arange(x0, x1, dtype=np.float64), np.arange(y0, y1, dtype=np.float64))
    X, Y = board_coordinates(camera.pixel_to_ray(np.stack([uu, vv], axis=-1)), rvec, tvec, board)
    cls = board.classify(X, Y)
    crop = out[y0:y1, x0:x1]
    crop[cls == 0] = board.black
    crop[cls == 1] = board.white
    return out


def _supersample_exact(crop, bg, camera: Camera, board: Board, rvec, tvec, origin: tuple[int, int],
                       mask: np.ndarray, samples: int) -> None:
    """Fill the pixels of ``mask`` in ``crop`` from ``samples`` lattice points each, every point
    unprojected exactly (no interpolation): for pixels the lens' domain cuts. origin : the
    crop's (x0, y0) px in the image."""
    rows, cols = np.nonzero(mask)
    if not rows.size:
        return
    lat = fibonacci_lattice(samples)
    u = (cols + origin[0] - 0.5)[:, None] + lat[None, :, 0]
    v = (rows + origin[1] - 0.5)[:, None] + lat[None, :, 1]
    X, Y = board_coordinates(camera.pixel_to_ray(np.stack([u, v], axis=-1)), rvec, tvec, board)
    scls = board.classify(X, Y)  # (E, n); NaN (not imaged) is off the paper
    frac_black = np.count_nonzero(scls == 0, axis=1) / float(samples)
    frac_white = np.count_nonzero(scls == 1, axis=1) / float(samples)
    frac_off = 1.0 - frac_black - frac_white
    crop[rows, cols] = (frac_black * board.black + frac_white * board.white + frac_off * bg[rows, cols]).astype(np.float32)


def _corner_range_meets(A: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """(H, W) bool: does the range of A over a pixel's four corners meet [lo, hi]? (NaN ignored)"""
    q = _pixel_corners(A)
    with np.errstate(invalid="ignore"):
        return (np.fmax.reduce(q) >= lo) & (np.fmin.reduce(q) <= hi)


def _board_cell_span(A: np.ndarray, board, paper: tuple[float, float]) -> np.ndarray:
    """(H, W) bool: does a pixel's corner set straddle a grid line or a paper edge along one axis?

    A : (H+1, W+1) board coordinate (X or Y) at pixel corners, NaN where not imaged. A board with
    finer print than its squares (:class:`data_gen.charuco.CharucoTarget`) numbers its own 1-D
    cells (``axis_cells``); a chessboard's are its squares.
    """
    cells = getattr(board, "axis_cells", None)
    with np.errstate(invalid="ignore"):
        base = cells(A) if cells is not None else np.nan_to_num(np.floor(A / board.square_size), nan=-1e9)
        cell = base * 4.0 + (A >= paper[0]) + 2.0 * (A >= paper[1])
    return _corner_span(cell)


def _supersample(crop, bg, q: np.ndarray, board: Board, mask: np.ndarray, samples: int) -> None:
    """Fill the pixels of ``mask`` in ``crop`` by averaging ``samples`` lattice points each.

    q : (h+1, w+1, 3) homogeneous board points at the pixel corners; inside a pixel they are
    interpolated bilinearly (the same as interpolating the rays, since q is linear in them).
    """
    rows, cols = np.nonzero(mask)
    if not rows.size:
        return
    lat = fibonacci_lattice(samples).astype(np.float32)
    s_off, t_off = lat[:, 0], lat[:, 1]
    st_off = s_off * t_off
    q00 = q[rows, cols].astype(np.float32)
    q10 = q[rows, cols + 1].astype(np.float32)
    q01 = q[rows + 1, cols].astype(np.float32)
    q11 = q[rows + 1, cols + 1].astype(np.float32)
    a, b, c = q10 - q00, q01 - q00, q11 - q10 - q01 + q00
    q0, q1, q2 = (
        q00[:, k, None] + a[:, k, None] * s_off + b[:, k, None] * t_off + c[:, k, None] * st_off for k in range(3)
    )  # each (E, n)
    with np.errstate(divide="ignore", invalid="ignore"):
        q2 = np.where(q2 > 0, q2, np.nan)  # behind the camera: not on the board
        scls = board.classify(q0 / q2, q1 / q2)  # (E, n)
    n = float(samples)
    frac_black = np.count_nonzero(scls == 0, axis=1) / n
    frac_white = np.count_nonzero(scls == 1, axis=1) / n
    frac_off = 1.0 - frac_black - frac_white
    crop[rows, cols] = (frac_black * board.black + frac_white * board.white + frac_off * bg[rows, cols]).astype(np.float32)
