"""A slow, obviously-correct reference renderer for tests: S x S point samples per pixel, each
undistorted exactly and classified on the board, over a constant background of 0.5."""

import numpy as np

from data_gen.render import board_coordinates

BACKGROUND = 0.5


def brute_force_render(camera, board, rvec, tvec, samples_per_axis: int) -> np.ndarray:
    """(H, W) float64 image of ``board`` over a flat 0.5 background."""
    w, h = camera.image_size
    S = samples_per_axis
    offs = (np.arange(S) + 0.5) / S - 0.5
    uu, vv = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    acc = np.zeros((h, w))
    for dy in offs:
        for dx in offs:
            rays = camera.pixel_to_ray(np.stack([uu + dx, vv + dy], axis=-1))
            cls = board.classify(*board_coordinates(rays, rvec, tvec))
            acc += np.choose(cls, [board.black, board.white, BACKGROUND])
    return acc / S**2
