"""Camera rigs with exact truth: two or three cameras with known relative poses see one board at once.

A rig is a row of cameras along camera 0's x axis: camera k's centre is c_k (cam0 frame, board
units), each neighbour ``baseline`` further (plus a little height and depth), each camera turned
in about its y axis by up to ``vergence_deg`` in all (the cameras converge) and by a fraction of a
degree about the other axes, as a real mount is. Camera k maps camera 0's frame as
X_k = R_k·X_0 + T_k with T_k = −R_k·c_k (OpenCV's stereo convention). Lenses are drawn per camera
(:func:`data_gen.camera.sample_camera` for "pinhole", :func:`data_gen.camera.sample_fisheye` for
"fisheye", full-frame 150–175°, and for "circular", 180–195° with the whole image circle inside the
frame, its outside black). The board is a chessboard whose square grows with the baseline (the
board a user would pick), or a marker board (a ChArUco board or a Kalibr AprilGrid, drawn as the
single-camera renders draw it, :mod:`data_gen.targets`) whose size sets the baseline, so every
camera sees it from a distance where it fills a good part of the image. A marker board's labels add
its markers' or tags' truth (:func:`data_gen.targets.marker_label`).

Each frame draws the board's pose for one camera (in turn, so every camera's image gets covered),
then keeps it only if every camera sees at least ``min_visible`` of the inner corners: boards may be
cut by the frame in the other cameras, as happens with real rigs. Images get the calibration
sequences' optics (blur σ 0.6) and read noise (σ grey levels).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

from aicalib_tf.geometry.camera import Camera

from .aprilgrid import AprilGridTarget
from .background import make_background
from .board import Board, sample_board
from .camera import sample_camera, sample_fisheye
from .charuco import CharucoTarget
from .degrade import apply_degradations
from .pose import PoseConfig, corner_visibility, sample_pose
from .render import lens_coverage, render_board
from .sample import OUTSIDE_CIRCLE, Sample
from .targets import marker_label, sample_target

__all__ = ["RigTruth", "sample_rig", "rig_placement", "rig_frame_poses", "make_rig_sequence", "RIG_LENSES"]

RIG_LENSES = ("pinhole", "fisheye", "circular")
_POSE = PoseConfig(tilt_max_deg=45.0, fill=(0.25, 0.6), framing="inside")


@dataclass(frozen=True)
class RigTruth:
    """cameras : C :class:`Camera`. R : (C, 3, 3), T : (C, 3): X_k = R_k·X_0 + T_k (board units).
    board : the board (a chessboard :class:`Board`, a :class:`CharucoTarget` or an :class:`AprilGridTarget`)."""

    cameras: tuple
    R: np.ndarray
    T: np.ndarray
    board: Board

    @property
    def marker_board(self) -> bool:
        """Whether the board is a marker board (its labels add its markers' or tags' truth)."""
        return isinstance(self.board, (AprilGridTarget, CharucoTarget))

    def baseline(self, k: int = 1) -> float:
        """|T_k|, board units."""
        return float(np.linalg.norm(self.T[k]))


def _camera(rng, lens: str, size) -> Camera:
    if lens == "fisheye":
        return sample_fisheye(rng, size, fov_deg=(150.0, 175.0))
    if lens == "circular":
        return sample_fisheye(rng, size, fov_deg=(180.0, 195.0))
    if lens == "pinhole":
        return sample_camera(rng, size, hfov_deg=(55.0, 90.0), distortion=("mild", "strong"))
    raise ValueError(f"rig lens must be one of {RIG_LENSES}, got {lens!r}")


def rig_placement(rng: np.random.Generator, count: int, baseline: float, vergence_deg=(0.0, 10.0)):
    """(R (C, 3, 3), T (C, 3)) of ``count`` cameras in a row, ``baseline`` apart (board units) along
    camera 0's x axis, converging by up to ``vergence_deg`` in all (module docstring); R[0] = I, T[0] = 0."""
    R, T = np.zeros((count, 3, 3)), np.zeros((count, 3))
    R[0] = np.eye(3)
    verge = math.radians(rng.uniform(*vergence_deg))
    b = float(baseline)
    for k in range(1, count):
        centre = np.array([k * b, rng.normal(0, 0.02 * b), rng.normal(0, 0.02 * b)])
        turn = np.array([rng.normal(0, 0.005), verge * k / (count - 1), rng.normal(0, 0.005)])  # converge: turn left
        R[k] = cv2.Rodrigues(turn)[0]
        T[k] = -R[k] @ centre
    return R, T


def sample_rig(rng: np.random.Generator, lenses=("pinhole", "pinhole"), size=(1280, 960), *,
               baseline=(50.0, 500.0), vergence_deg=(0.0, 10.0), pattern=(9, 6), board=None) -> RigTruth:
    """Draw a rig of len(lenses) cameras (module docstring); baseline in mm (the board's unit), degrees.

    board : a marker board (a :class:`~aicalib_tf.geometry.charuco.CharucoBoard` or an
    :class:`~aicalib_tf.geometry.aprilgrid.AprilGrid`, :mod:`data_gen.targets`) to show instead of a
    chessboard of ``pattern``, on paper drawn as the single-camera renders draw it
    (:func:`data_gen.targets.sample_target`). Its size is its own, and the baseline is drawn as the
    chessboard's square would be, 8 squares (within ``baseline``'s range): a ChArUco board's square,
    an AprilGrid's printed width over 10 (a 9x6 chessboard is 10 squares wide)."""
    C = len(lenses)
    if C < 2:
        raise ValueError(f"a rig has at least 2 cameras, got {C}")
    b = float(rng.uniform(*baseline))
    cams = tuple(_camera(rng, lens, size) for lens in lenses)
    if board is None:  # (this order of draws keeps the chessboard rigs as they were)
        R, T = rig_placement(rng, C, b, vergence_deg)
        target = replace(sample_board(rng, pattern_size=pattern), square_size=float(np.clip(b / 8.0, 15.0, 60.0)))
    else:
        target = sample_target(rng, board)
        b = float(np.clip(8.0 * _square_of(target) * rng.uniform(0.8, 1.25), *baseline))
        R, T = rig_placement(rng, C, b, vergence_deg)
    return RigTruth(cams, R, T, target)


def _square_of(target) -> float:
    """The square of the chessboard a marker board stands in for (:func:`sample_rig`), board units."""
    if isinstance(target, AprilGridTarget):
        x0, _, x1, _ = target.printed_bounds()
        return (x1 - x0) / 10.0
    return target.square_size


def _to_camera(truth: RigTruth, k: int, R0, t0) -> tuple[np.ndarray, np.ndarray]:
    """The board's pose (rvec, tvec) in camera k from its pose (R0 (3, 3), t0 (3,)) in camera 0."""
    R = truth.R[k] @ R0
    return cv2.Rodrigues(R)[0].ravel(), truth.R[k] @ t0 + truth.T[k]


def rig_frame_poses(rng, truth: RigTruth, reference: int, *, min_visible: float = 0.3, tries: int = 200):
    """[(rvec, tvec)] per camera of one board pose drawn for camera ``reference`` that every camera sees
    at least ``min_visible`` of; RuntimeError after ``tries``."""
    for _ in range(tries):
        rv, tv = sample_pose(rng, truth.cameras[reference], truth.board, _POSE)
        Rr = cv2.Rodrigues(np.asarray(rv, np.float64).reshape(3, 1))[0]
        R0, t0 = truth.R[reference].T @ Rr, truth.R[reference].T @ (np.asarray(tv) - truth.T[reference])
        poses = [_to_camera(truth, k, R0, t0) for k in range(len(truth.cameras))]
        if all(corner_visibility(truth.board, r, t, cam)[1].mean() >= min_visible
               for (r, t), cam in zip(poses, truth.cameras)):
            return poses
    raise RuntimeError(f"no board pose seen by every camera of the rig after {tries} tries")


def _render(rng, cam: Camera, board: Board, rvec, tvec, noise: float) -> np.ndarray:
    bg = make_background(rng, cam.image_size, clutter=float(rng.uniform(0.0, 0.5)), checker_distractors=0.0)
    cov = lens_coverage(cam)
    if cov is not None:
        bg = (bg * cov + OUTSIDE_CIRCLE * (1.0 - cov)).astype(np.float32)
    img = render_board(cam, board, rvec, tvec, bg)
    return apply_degradations(img, [{"name": "gaussian_blur", "sigma": 0.6}, {"name": "gaussian_noise", "sigma": noise}], rng)


def _label(truth, k, rvec, tvec, seed, frame) -> dict:
    cam = truth.cameras[k]
    corners, visible = corner_visibility(truth.board, rvec, tvec, cam)
    return {"image_size": list(cam.image_size), "pattern_size": list(truth.board.pattern_size),
            "square_size": truth.board.square_size, "K": cam.K.tolist(), "distortion_model": cam.model,
            "dist": cam.dist.tolist(), "rvec": np.asarray(rvec).tolist(), "tvec": np.asarray(tvec).tolist(),
            "corners": corners.tolist(), "visible": visible.tolist(), "has_board": True, "rig_id": seed,
            "camera_index": k, "index": frame, "R_rig": truth.R[k].tolist(), "T_rig": truth.T[k].tolist(),
            **(marker_label(truth.board, rvec, tvec, cam) if truth.marker_board else {})}


def make_rig_sequence(seed: int, pairs: int = 20, lenses=("pinhole", "pinhole"), size=(1280, 960), *,
                      noise: float = 2.0, **rig_args) -> tuple[RigTruth, list[list[Sample]]]:
    """A rig and ``pairs`` frames of it: (truth, frames), frames[f][k] the :class:`Sample` of camera k.

    noise : read noise σ, grey levels. rig_args : passed to :func:`sample_rig`. Deterministic in ``seed``.
    """
    truth = sample_rig(np.random.default_rng([seed, 7]), lenses, size, **rig_args)
    frames = []
    for f in range(pairs):
        rng = np.random.default_rng([seed, 7, f + 1])
        poses = rig_frame_poses(rng, truth, f % len(lenses))
        frames.append([Sample(_render(rng, cam, truth.board, r, t, noise), _label(truth, k, r, t, seed, f))
                       for k, (cam, (r, t)) in enumerate(zip(truth.cameras, poses))])
    return truth, frames
