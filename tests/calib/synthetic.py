"""Synthetic views for the calibration tests: a known lens projects a 9x6 board in random poses."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from aicalib_tf.calib.fit import View
from aicalib_tf.geometry.board_shape import shaped_points
from aicalib_tf.geometry.pattern import board_points

PATTERN = (9, 6)
SQUARE = 0.04


def synthetic_views(lens, n=20, noise=0.0, *, seed=0, avoid=None, distance=(0.35, 0.6), min_corners=20, flex=None,
                    noise_of=None):
    """``n`` views of a 9x6 board (square 0.04) seen by ``lens``, corner noise ``noise`` px (1σ per axis).

    avoid : (x0, y0, x1, y1) px: no board centre and no corner in that rectangle. flex : (w_x, w_y) the
    board's sag in squares (:mod:`aicalib_tf.geometry.board_flex`), or (K,) the terms of a board shape
    (:mod:`aicalib_tf.geometry.board_shape`), None flat. noise_of : k -> view k's
    noise px, in place of ``noise``. seed : anything ``np.random.default_rng`` takes (a Generator too).
    Corners outside the image (or with no projection) are dropped, so boards can be partial.
    """
    rng = np.random.default_rng(seed)
    cols, rows = PATTERN
    ids = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), -1).reshape(-1, 2)
    X = board_points(ids, SQUARE) if flex is None else shaped_points(board_points(ids, SQUARE), PATTERN, flex, SQUARE)
    X = X - [(cols - 1) * SQUARE / 2, (rows - 1) * SQUARE / 2, 0]
    w, h = lens.image_size
    views = []
    while len(views) < n:
        q = rng.uniform([0.1 * w, 0.1 * h], [0.9 * w, 0.9 * h])
        ray = lens.unproject(q)
        t = ray / ray[2] * rng.uniform(*distance)
        R = Rotation.from_euler("xyz", rng.uniform(-40, 40, 3) * [1, 1, 0.5], degrees=True).as_matrix()
        uv = lens.project(X @ R.T + t)
        ok = np.all(np.isfinite(uv), 1) & (uv[:, 0] > 0) & (uv[:, 0] < w - 1) & (uv[:, 1] > 0) & (uv[:, 1] < h - 1)
        if avoid is not None:
            x0, y0, x1, y1 = avoid
            inside = lambda p: (p[..., 0] >= x0) & (p[..., 0] <= x1) & (p[..., 1] >= y0) & (p[..., 1] <= y1)  # noqa: E731
            if inside(q):
                continue
            ok &= ~inside(np.nan_to_num(uv, nan=-1e9))
        if ok.sum() < min_corners:
            continue
        s = noise if noise_of is None else noise_of(len(views))
        views.append(View(f"v{len(views):02d}", uv[ok] + s * rng.standard_normal((int(ok.sum()), 2)), ids[ok]))
    return views
