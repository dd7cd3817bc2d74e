"""Render a chessboard into an image by inverse mapping with exact distortion inversion.

For every pixel *corner* (the grid of points (u ± 0.5, v ± 0.5)) we undistort exactly
(:func:`data_gen.camera.undistort_normalized`) and intersect the ray with the board plane
through the board homography. A pixel whose four corners fall in one class (black square,
white paper, off the paper) is filled directly. Pixels that straddle an edge, and every pixel
near an X-junction, are supersampled: the undistorted ray is interpolated bilinearly inside the
pixel (the distortion is smooth on a 1-px scale, error < 1e-4 px) and each sample goes through
the exact homography. Samples sit on a Fibonacci lattice, whose projections on both axes are
all distinct, so even axis-aligned edges are resolved to 1/N of a pixel (N = 89 by default).
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from .board import Board
from .camera import Camera

__all__ = ["render_board", "fibonacci_lattice", "board_coordinates"]

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
    return np.stack([s, t], axis=1)


@functools.lru_cache(maxsize=4)
def _corner_rays(camera_key: tuple) -> np.ndarray:
    """Undistorted normalized rays at every pixel corner, (H+1, W+1, 2) float64 (NaN = not imaged)."""
    K = np.array(camera_key[0]).reshape(3, 3)
    dist = np.array(camera_key[1])
    w, h = camera_key[2]
    cam = Camera(K, dist, (w, h))
    us = np.arange(w + 1, dtype=np.float64) - 0.5
    vs = np.arange(h + 1, dtype=np.float64) - 0.5
    uu, vv = np.meshgrid(us, vs)
    rays = cam.pixel_to_normalized(np.stack([uu, vv], axis=-1))
    rays.setflags(write=False)
    return rays


def _camera_key(camera: Camera) -> tuple:
    return (tuple(camera.K.ravel().tolist()), tuple(camera.dist.tolist()), tuple(camera.image_size))


def board_coordinates(rays: np.ndarray, rvec, tvec) -> tuple[np.ndarray, np.ndarray]:
    """Intersect normalized rays (..., 2) with the board plane; returns board X, Y (NaN behind)."""
    R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    Hm = np.column_stack([R[:, 0], R[:, 1], np.asarray(tvec, dtype=np.float64).ravel()])
    Hi = np.linalg.inv(Hm)
    x = rays[..., 0]
    y = rays[..., 1]
    q0 = Hi[0, 0] * x + Hi[0, 1] * y + Hi[0, 2]
    q1 = Hi[1, 0] * x + Hi[1, 1] * y + Hi[1, 2]
    q2 = Hi[2, 0] * x + Hi[2, 1] * y + Hi[2, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        front = q2 > 0
        X = np.where(front, q0 / q2, np.nan)
        Y = np.where(front, q1 / q2, np.nan)
    return X, Y


def render_board(
    camera: Camera,
    board: Board,
    rvec,
    tvec,
    background: np.ndarray,
    *,
    samples: int = 89,
) -> np.ndarray:
    """Composite ``board`` seen from pose (rvec, tvec) over ``background``.

    Parameters
    ----------
    camera, board : the scene.
    rvec, tvec : (3,) pose of the board in the camera frame (T_cam_board).
    background : (H, W) float32 in [0, 1], H, W matching ``camera.image_size``.
    samples : supersamples per edge pixel (Fibonacci number, see :func:`fibonacci_lattice`).

    Returns
    -------
    (H, W) float32 image in [0, 1], anti-aliased, no blur or noise.
    """
    w, h = camera.image_size
    if background.shape != (h, w):
        raise ValueError(f"background must be (H, W) = {(h, w)}, got {background.shape}")
    rays = _corner_rays(_camera_key(camera))
    X, Y = board_coordinates(rays, rvec, tvec)
    cls = board.classify(X, Y)  # (H+1, W+1)
    levels = np.array([board.black, board.white], dtype=np.float32)

    c00, c10, c01, c11 = cls[:-1, :-1], cls[:-1, 1:], cls[1:, :-1], cls[1:, 1:]
    uniform = (c00 == c10) & (c00 == c01) & (c00 == c11)

    # Near an X-junction two edges meet; a thin wedge can hide between pixel corners, so
    # supersample a 1-px ring around every pixel whose corners span two square indices both ways.
    s = board.square_size
    with np.errstate(invalid="ignore"):
        gi = np.floor(X / s)
        gj = np.floor(Y / s)
    gi = np.nan_to_num(gi, nan=-1e9)
    gj = np.nan_to_num(gj, nan=-1e9)
    span_i = np.maximum.reduce([gi[:-1, :-1], gi[:-1, 1:], gi[1:, :-1], gi[1:, 1:]]) != np.minimum.reduce(
        [gi[:-1, :-1], gi[:-1, 1:], gi[1:, :-1], gi[1:, 1:]]
    )
    span_j = np.maximum.reduce([gj[:-1, :-1], gj[:-1, 1:], gj[1:, :-1], gj[1:, 1:]]) != np.minimum.reduce(
        [gj[:-1, :-1], gj[:-1, 1:], gj[1:, :-1], gj[1:, 1:]]
    )
    junction = (span_i & span_j & (c00 != 2)).astype(np.uint8)
    mixed = ~uniform | cv2.dilate(junction, np.ones((3, 3), np.uint8)).astype(bool)

    out = background.astype(np.float32, copy=True)
    on_paper = uniform & (c00 != 2)
    out[on_paper] = levels[c00[on_paper]]

    rows, cols = np.nonzero(mixed)
    if rows.size:
        lat = fibonacci_lattice(samples)
        s_off = lat[None, :, 0]
        t_off = lat[None, :, 1]
        r00 = rays[rows, cols]
        r10 = rays[rows, cols + 1]
        r01 = rays[rows + 1, cols]
        r11 = rays[rows + 1, cols + 1]
        a = r10 - r00
        b = r01 - r00
        c = r11 - r10 - r01 + r00
        sub = (
            r00[:, None, :]
            + s_off[..., None] * a[:, None, :]
            + t_off[..., None] * b[:, None, :]
            + (s_off * t_off)[..., None] * c[:, None, :]
        )  # (E, n, 2)
        sX, sY = board_coordinates(sub, rvec, tvec)
        scls = board.classify(sX, sY)  # (E, n)
        n = float(samples)
        frac_black = (scls == 0).sum(axis=1) / n
        frac_white = (scls == 1).sum(axis=1) / n
        frac_off = 1.0 - frac_black - frac_white
        out[rows, cols] = (
            frac_black * board.black + frac_white * board.white + frac_off * background[rows, cols]
        ).astype(np.float32)
    return out
