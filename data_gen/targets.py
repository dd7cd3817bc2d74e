"""Marker boards for the renderer: a ChArUco board or a Kalibr AprilGrid from its text form.

``charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100`` (:mod:`data_gen.charuco`),
``aprilgrid:6x6,tag=88mm,spacing=0.3[,family=tag36h11][,first=0]`` or a Kalibr target YAML of
``target_type: aprilgrid`` (:mod:`data_gen.aprilgrid`). A Kalibr checkerboard is a chessboard: give
its pattern with ``--pattern`` instead.
"""

from __future__ import annotations

import numpy as np

from aicalib_tf.geometry.aprilgrid import AprilGrid, is_aprilgrid, load_board
from aicalib_tf.geometry.charuco import CharucoBoard
from aicalib_tf.geometry.charuco import parse_board as parse_charuco
from aicalib_tf.geometry.pose import in_frame

from .aprilgrid import AprilGridTarget, sample_aprilgrid, tag_truth
from .charuco import CharucoTarget, marker_truth, sample_charuco

__all__ = ["HELP", "parse_marker_board", "marker_target", "sample_target", "label_extras", "marker_label"]

HELP = ("a marker board instead of chessboards: charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100, "
        "aprilgrid:6x6,tag=88mm,spacing=0.3[,family=tag36h11][,first=0] or a Kalibr aprilgrid target.yaml")


def parse_marker_board(text: str) -> CharucoBoard | AprilGrid:
    """The board ``text`` names; ValueError naming the field (or the file) otherwise."""
    if not is_aprilgrid(text):
        return parse_charuco(text)
    board = load_board(text)
    if not isinstance(board, AprilGrid):
        raise ValueError(f"{text}: a Kalibr checkerboard is a chessboard; give its inner corners with --pattern "
                         f"{board.pattern_size[0]}x{board.pattern_size[1]} instead")
    return board


def marker_target(board: CharucoBoard | AprilGrid) -> CharucoTarget | AprilGridTarget:
    """The board's default paper (margin, grey levels)."""
    return AprilGridTarget(board) if isinstance(board, AprilGrid) else CharucoTarget(board)


def sample_target(rng: np.random.Generator, board: CharucoBoard | AprilGrid) -> CharucoTarget | AprilGridTarget:
    """The board on a drawn paper (margin, grey levels)."""
    return sample_aprilgrid(rng, board) if isinstance(board, AprilGrid) else sample_charuco(rng, board)


def label_extras(target, rvec, tvec, camera) -> dict:
    """What a label adds for a marker board: a ChArUco board's ``markers``, or an AprilGrid's corner
    ``ids`` (lattice (col, row) of each of the label's corners) and ``tags``, each
    {"ids", "corners" (K, 4, 2) px, "centres" (K, 2) px}; {} for a chessboard."""
    if isinstance(target, CharucoTarget):
        return {"markers": marker_truth(target, rvec, tvec, camera)}
    if isinstance(target, AprilGridTarget):
        return {"ids": target.corner_ids().tolist(), "tags": tag_truth(target, rvec, tvec, camera)}
    return {}


def marker_label(target, rvec, tvec, camera, hidden=None) -> dict:
    """:func:`label_extras` with each marker's or tag's ``visible`` flag: all four corners in frame,
    imaged by the lens and, with ``hidden`` ((N, 2) px -> (N,) bool, e.g. under an occluder), not hidden."""
    extras = label_extras(target, rvec, tvec, camera)
    truth = extras["markers" if "markers" in extras else "tags"]
    px = np.asarray(truth["corners"], dtype=np.float64).reshape(-1, 2)
    seen = in_frame(px, camera.image_size, border=0.5) & np.isfinite(px).all(axis=1)
    if hidden is not None:
        seen &= ~hidden(px)
    truth["visible"] = seen.reshape(-1, 4).all(axis=1).tolist()
    return extras
