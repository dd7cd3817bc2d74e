"""A hand-held board path: smooth board poses over time, like a person showing a board to a camera.

The path visits key poses drawn by :func:`data_gen.pose.sample_pose` (the board aimed at points
spread over the image, tilted about random axes; a quarter of them cut by the frame, and about
one in ten moved out of view altogether). At each key pose the hand rests (a short dwell), then
moves to the next along a minimum-jerk profile (10s³ − 15s⁴ + 6s⁵: zero speed and acceleration at
both ends, peak speed 1.875× the mean), rotation along the shortest arc and translation along a
straight line in the camera frame. A small tremor (a few slow sinusoids, ~0.2° and ~0.3 mm) rides
on top, so that a resting board is never perfectly still. Poses map board to camera (``T_cam_board``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

from aicalib_tf.geometry.camera import Camera

from .board import Board
from .pose import PoseConfig, corner_visibility, sample_pose

__all__ = ["HandPath", "RigPath", "hand_path", "HAND_POSES"]

HAND_POSES = PoseConfig(tilt_max_deg=50.0, fill=(0.3, 0.7), framing="inside", roll_deg=(-25.0, 25.0))


@dataclass(frozen=True)
class HandPath:
    """Key poses and times of a path; :meth:`pose` evaluates it at any time.

    times : (K, 2) float64 s, [arrive, leave] at each key pose (the hand rests in between).
    rotations : (K, 3, 3) board-to-camera rotations. translations : (K, 3) board units.
    tremor : (6, 3, 3) amplitude, frequency (Hz) and phase of three sinusoids per axis
        (rotation rad on axes 0-2, translation in board units on axes 3-5), stacked as
        [amplitude, frequency, phase] along the last axis.
    """

    times: np.ndarray
    rotations: np.ndarray
    translations: np.ndarray
    tremor: np.ndarray

    @property
    def duration(self) -> float:
        """Seconds from the first arrival to the last departure."""
        return float(self.times[-1, 1])

    def pose(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(rvec (3,), tvec (3,)) at time ``t`` s (clamped to the path)."""
        R, tv = self._pose(float(t))
        return cv2.Rodrigues(R)[0].ravel(), tv

    def matrix(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(R (3, 3), t (3,)) at time ``t`` s."""
        return self._pose(float(t))

    def _pose(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        k = int(np.searchsorted(self.times[:, 0], t, side="right")) - 1
        k = min(max(k, 0), len(self.times) - 1)
        arrive, leave = self.times[k]
        if t <= leave or k == len(self.times) - 1:
            R, tv = self.rotations[k], self.translations[k]
        else:
            s = (t - leave) / (self.times[k + 1, 0] - leave)
            m = s * s * s * (10.0 - 15.0 * s + 6.0 * s * s)
            step = cv2.Rodrigues(self.rotations[k].T @ self.rotations[k + 1])[0].ravel()
            R = self.rotations[k] @ cv2.Rodrigues(m * step)[0]
            tv = (1.0 - m) * self.translations[k] + m * self.translations[k + 1]
        amp, freq, phase = self.tremor[..., 0], self.tremor[..., 1], self.tremor[..., 2]
        wobble = np.sum(amp * np.sin(2.0 * math.pi * freq * t + phase), axis=1)  # (6,)
        return cv2.Rodrigues(wobble[:3])[0] @ R, tv + wobble[3:]


@dataclass(frozen=True)
class RigPath:
    """A hand path seen from another camera of a rig: every pose (board to camera 0) mapped by
    X_k = R·X_0 + T (R (3, 3), T (3,) board units); :meth:`pose` and :meth:`matrix` as :class:`HandPath`'s."""

    path: HandPath
    R: np.ndarray
    T: np.ndarray

    def matrix(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(R (3, 3), t (3,)) of the board in this camera at time ``t`` s."""
        R0, t0 = self.path.matrix(t)
        return self.R @ R0, self.R @ t0 + self.T

    def pose(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(rvec (3,), tvec (3,)) at time ``t`` s."""
        R, tv = self.matrix(t)
        return cv2.Rodrigues(R)[0].ravel(), tv


def _out_of_view(camera: Camera, board: Board, R: np.ndarray, t: np.ndarray, rng) -> np.ndarray | None:
    """A translation that moves the board sideways out of the image (no corner visible), or None."""
    x0, y0, x1, y1 = board.paper_bounds()
    width = max(x1 - x0, y1 - y0)
    angle = rng.uniform(0.0, 2.0 * math.pi)
    direction = np.array([math.cos(angle), math.sin(angle), 0.0])
    rvec = cv2.Rodrigues(R)[0]
    for k in np.arange(1.0, 8.0, 0.5):
        moved = t + k * width * direction
        if not corner_visibility(board, rvec, moved, camera)[1].any():
            return moved
    return None


def hand_path(rng: np.random.Generator, camera: Camera, board: Board, seconds: float, *,
              poses: PoseConfig = HAND_POSES, partial: float = 0.25, leave: float = 0.1,
              dwell_s=(0.25, 0.6), move_s=(0.8, 1.8)) -> HandPath:
    """Draw a path of at least ``seconds`` s (module docstring).

    partial : share of key poses cut by the frame; leave : share moved out of view. dwell_s,
    move_s : ranges (s) of the rest at a key pose and of the move to the next one.
    """
    if not seconds > 0:
        raise ValueError(f"seconds must be > 0, got {seconds!r}")
    times, rots, trans = [], [], []
    clock = 0.0
    while clock < seconds or len(times) < 2:
        framing = "partial" if rng.random() < partial else poses.framing
        rvec, tvec = sample_pose(rng, camera, board, replace(poses, framing=framing))
        R = cv2.Rodrigues(np.asarray(rvec, np.float64))[0]
        tvec = np.asarray(tvec, np.float64)
        if times and rng.random() < leave:
            moved = _out_of_view(camera, board, R, tvec, rng)
            tvec = tvec if moved is None else moved
        dwell = rng.uniform(*dwell_s)
        times.append([clock, clock + dwell])
        rots.append(R)
        trans.append(tvec)
        clock += dwell + rng.uniform(*move_s)
    scale = float(np.median([t[2] for t in trans]))  # board distance, board units
    amp = np.concatenate([np.full((3, 3), math.radians(0.07)), np.full((3, 3), 3e-4 * scale)])
    amp = amp * rng.uniform(0.5, 1.0, size=(6, 3))
    freq = rng.uniform(0.3, 4.0, size=(6, 3))
    phase = rng.uniform(0.0, 2.0 * math.pi, size=(6, 3))
    return HandPath(np.array(times), np.array(rots), np.array(trans), np.stack([amp, freq, phase], axis=-1))
