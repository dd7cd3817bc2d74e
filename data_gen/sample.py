"""One image with exact labels, made in memory from (preset, seed, index).

Seeding: image ``index`` belongs to camera ``index // views_per_camera``. The camera, the
board and (unless fixed) the image size come from ``default_rng([seed, camera_id, 0])``; the
pose, background, occluders and degradations from ``default_rng([seed, index, 1])``. So every
image depends only on (preset, seed, index, size, pattern): the same on any worker.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

from aicalib_tf.geometry.camera import Camera

from .background import make_background
from .board import Board, sample_board
from .camera import UNIFIED_MODELS, sample_camera, sample_fisheye, sample_unified_fisheye
from .aprilgrid import AprilGridTarget
from .charuco import CharucoTarget
from .degrade import CIRCLE_STEPS, PLANE_STEPS, apply_degradations
from .occlude import draw_occluders, occluded, sample_occluders
from .pose import corner_visibility, sample_pose
from .presets import INT_PARAMS, Preset, Rule, get_preset
from .render import lens_coverage, render_board
from .targets import marker_label, parse_marker_board, sample_target

__all__ = ["Sample", "Scene", "draw_scene", "make_sample", "make_sequence", "draw_steps", "scene_for"]

GENERATOR_VERSION = "1.0"  # pinhole renders are bit-for-bit those of 1.0 (training pools stay valid); fisheye presets are new
OUTSIDE_CIRCLE = 0.03  # grey level (0..1) outside a fisheye's image circle, before noise


@dataclass(frozen=True)
class Sample:
    """A rendered image and its labels.

    image : (H, W) uint8 grey.
    label : dict in the dataset's label format (see ``../shared/DESIGN.md``), JSON-ready.
    """

    image: np.ndarray
    label: dict

    @property
    def corners(self) -> np.ndarray:
        """(cols·rows, 2) float64 (x, y) px, OpenCV order; empty when there is no board."""
        return np.asarray(self.label["corners"], dtype=np.float64).reshape(-1, 2)

    @property
    def visible(self) -> np.ndarray:
        """(cols·rows,) bool."""
        return np.asarray(self.label["visible"], dtype=bool)


def _draw(rng: np.random.Generator, value):
    if isinstance(value, (tuple, list)) and value and all(isinstance(v, str) for v in value):
        return value[int(rng.integers(len(value)))]  # a choice among named laws
    if isinstance(value, (tuple, list)) and len(value) == 2:
        return float(rng.uniform(value[0], value[1]))
    return value


def draw_steps(rules: tuple[Rule, ...], rng: np.random.Generator) -> list[dict]:
    """Decide which degradations apply and draw their parameters: ``[{"name": ..., **params}]``."""
    steps = []
    for rule in rules:
        if rng.random() < rule.p:
            step = {"name": rule.name}
            for key, value in rule.params:
                v = _draw(rng, value)
                step[key] = int(round(v)) if key in INT_PARAMS else v
            steps.append(step)
    return steps


def scene_for(preset: Preset, seed: int, camera_id: int, size=None, pattern=None) -> tuple[Camera, Board]:
    """The camera and board shared by all views of ``camera_id``."""
    rng = np.random.default_rng([seed, camera_id, 0])
    if size is None:
        size = preset.sizes[int(rng.integers(len(preset.sizes)))]
    lens = preset.lens
    if not isinstance(lens, str):  # one lens family per camera (a preset with one family draws nothing here)
        lens = lens[int(rng.integers(len(lens)))]
    circular = preset.fisheye_circular_from_deg
    if lens == "fisheye":
        cam = sample_fisheye(rng, size, fov_deg=preset.fisheye_fov_deg, circular_from_deg=circular)
    elif lens in UNIFIED_MODELS:
        cam = sample_unified_fisheye(rng, size, lens, fov_deg=preset.fisheye_fov_deg, circular_from_deg=circular)
    else:
        cam = sample_camera(rng, size, hfov_deg=preset.hfov_deg, distortion=preset.distortion)
    if preset.board is not None:  # a ChArUco board or an AprilGrid: its print is fixed, only the paper is drawn
        return cam, sample_target(rng, parse_marker_board(preset.board))
    board = sample_board(
        rng,
        pattern_size=pattern or preset.pattern,
        cols_range=preset.cols_range,
        rows_range=preset.rows_range,
        margin_range=preset.margin_range,
        black_range=preset.paper_black,
        white_range=preset.paper_white,
    )
    if any(preset.flex) or any(preset.shape):  # after the draws: the same camera and board as the flat preset
        board = replace(board, flex=preset.flex, shape=preset.shape)
    return cam, board


def _circle_px(cam: Camera) -> dict:
    """The image circle in px: {"cx", "cy", "radius"}; for a lens without one, the frame's centre and
    half its diagonal."""
    w, h = cam.image_size
    if not cam.fisheye:
        return {"cx": (w - 1) / 2.0, "cy": (h - 1) / 2.0, "radius": math.hypot(w, h) / 2.0}
    return {"cx": float(cam.cx), "cy": float(cam.cy), "radius": float(cam.circle_radius() * math.sqrt(cam.fx * cam.fy))}


_FLAT_DEPTH = {"w0": 1.0, "wu": 0.0, "wv": 0.0, "w_near": 1.0, "w_far": 1.0}  # no board: one depth everywhere


def _depth_plane(board: Board, rvec: np.ndarray, tvec: np.ndarray, corners: np.ndarray) -> dict:
    """The board's inverse depth as a plane of the pixel: {"w0", "wu", "wv"} (w = 1/z ≈ w0 + wu·x + wv·y,
    1/board units, x, y px: the least-squares fit over its inner corners ``corners`` (N, 2) px, exact for a
    pinhole lens) and its range over them, {"w_near", "w_far"}."""
    R = cv2.Rodrigues(np.asarray(rvec, np.float64).reshape(3, 1))[0]
    inv = 1.0 / (board.object_points() @ R[2] + float(np.asarray(tvec, np.float64).ravel()[2]))
    a = np.column_stack([np.ones(len(corners)), np.asarray(corners, np.float64).reshape(-1, 2)])
    sol = np.linalg.lstsq(a, inv, rcond=None)[0]
    return {"w0": float(sol[0]), "wu": float(sol[1]), "wv": float(sol[2]), "w_near": float(inv.max()),
            "w_far": float(inv.min())}


def _occluders_leaving_corners(rng, corners, visible, p: Preset, tries: int = 10) -> list[np.ndarray]:
    """Occluders that hide some corners but leave at least a quarter of the visible ones.

    A board hidden entirely is a board-free image, which is the ``clutter`` preset's job.
    Returns [] if ``tries`` draws all hide too much.
    """
    for _ in range(tries):
        polys = sample_occluders(
            rng, corners[visible], severity=_draw(rng, p.occlusion_severity), count=int(rng.integers(1, 3))
        )
        left = visible & ~occluded(corners, polys)
        if left.sum() >= max(1, 0.25 * visible.sum()):
            return polys
    return []


@dataclass(frozen=True)
class Scene:
    """Everything one image draws before it is rendered; :meth:`render` makes the image.

    camera, board : shared by the camera's views. background : (H, W) float32 in [0, 1].
    rvec, tvec : (3,) the board's pose (None without a board). framing : the pose's framing.
    occluders : polygons (K, 2) px drawn in front, with their grey ``occluder_levels``.
    corners : (cols·rows, 2) px; visible : (cols·rows,) bool, in frame and not hidden.
    steps : the degradations (see :func:`draw_steps`); degrade_rng : the generator they draw their
    noise from, copied before each render so that every render draws the same noise.
    """

    preset: Preset
    camera: Camera
    board: Board
    background: np.ndarray
    has_board: bool
    framing: str | None
    rvec: np.ndarray | None
    tvec: np.ndarray | None
    occluders: list
    occluder_levels: list
    corners: np.ndarray
    visible: np.ndarray
    steps: list
    degrade_rng: np.random.Generator

    def render(self, rvec: np.ndarray | None = None, tvec: np.ndarray | None = None) -> np.ndarray:
        """(H, W) uint8: the image, with the board at (rvec, tvec) when given (default: its own pose).

        Everything else (background, occluders, degradations and their noise) is as drawn, so two
        poses give images that differ only where the board does.
        """
        img = self.background
        if self.has_board:
            rvec = self.rvec if rvec is None else rvec
            tvec = self.tvec if tvec is None else tvec
            img = render_board(self.camera, self.board, rvec, tvec, self.background,
                               **({} if self.preset.antialias else {"samples": 1}))
            img = draw_occluders(img, self.occluders, self.occluder_levels)
        return apply_degradations(img, self.steps, copy.deepcopy(self.degrade_rng))


def draw_scene(
    preset: str | Preset,
    seed: int,
    index: int = 0,
    *,
    size: tuple[int, int] | None = None,
    pattern: tuple[int, int] | None = None,
) -> Scene:
    """Draw image ``index`` of the dataset (preset, seed) without rendering it (see :func:`make_sample`)."""
    p = get_preset(preset)
    if index < 0 or seed < 0:
        raise ValueError(f"seed and index must be >= 0, got seed={seed}, index={index}")
    cam, board = scene_for(p, seed, index // p.views_per_camera, size, pattern)
    rng = np.random.default_rng([seed, index, 1])
    w, h = cam.image_size
    has_board = bool(rng.random() < p.board_probability)
    background = make_background(
        rng, (w, h), clutter=_draw(rng, p.clutter), checker_distractors=_draw(rng, p.checker_distractors)
    )
    coverage = lens_coverage(cam)
    if coverage is not None:  # a fisheye's image circle: nothing is imaged outside it
        background = (background * coverage + OUTSIDE_CIRCLE * (1.0 - coverage)).astype(np.float32)
    framing = rvec = tvec = None
    polys: list[np.ndarray] = []
    levels: list[float] = []
    corners, visible = np.zeros((0, 2)), np.zeros(0, bool)
    if has_board:
        framing = "partial" if rng.random() < p.partial_probability else p.pose.framing
        rvec, tvec = sample_pose(rng, cam, board, replace(p.pose, framing=framing))
        corners, visible = corner_visibility(board, rvec, tvec, cam)
        if rng.random() < p.occlusion_probability and visible.any():
            polys = _occluders_leaving_corners(rng, corners, visible, p)
            levels = [float(rng.uniform(0.05, 0.95)) for _ in polys]
            visible &= ~occluded(corners, polys)
    steps = draw_steps(p.rules, rng)
    for step in steps:
        if step["name"] in CIRCLE_STEPS:  # these follow the lens' image circle (the frame's centre for a pinhole)
            step.update(_circle_px(cam))
        elif step["name"] in PLANE_STEPS:  # these follow the board's depth
            step.update(_depth_plane(board, rvec, tvec, corners) if has_board else _FLAT_DEPTH)
    return Scene(p, cam, board, background, has_board, framing, rvec, tvec, polys, levels, corners, visible,
                 steps, rng)  # render() copies rng before each use


def make_sample(
    preset: str | Preset,
    seed: int,
    index: int = 0,
    *,
    size: tuple[int, int] | None = None,
    pattern: tuple[int, int] | None = None,
) -> Sample:
    """Render image ``index`` of the dataset (preset, seed).

    size : (width, height) to force; default: the preset's sizes.
    pattern : (cols, rows) inner corners to force; default: the preset's.
    """
    sc = draw_scene(preset, seed, index, size=size, pattern=pattern)
    cam, board = sc.camera, sc.board
    w, h = cam.image_size
    label = {
        "image_size": [w, h],
        "pattern_size": list(board.pattern_size),
        "square_size": board.square_size,
        "K": cam.K.tolist(),
        "distortion_model": cam.model,
        "dist": cam.dist.tolist(),
        "max_theta_deg": cam.to_dict()["max_theta_deg"],
        "rvec": None,
        "tvec": None,
        "corners": [],
        "visible": [],
        "condition": sc.preset.name,
        "camera_id": index // sc.preset.views_per_camera,
        "seed": seed,
        "index": index,
        "has_board": sc.has_board,
        "board": board.to_dict(),
        "framing": None,
        "occluders": [],
    }
    if sc.has_board:
        label.update(
            rvec=sc.rvec.tolist(),
            tvec=sc.tvec.tolist(),
            corners=sc.corners.tolist(),
            visible=sc.visible.tolist(),
            framing=sc.framing,
            occluders=[poly.tolist() for poly in sc.occluders],
        )
    if sc.has_board and isinstance(board, (CharucoTarget, AprilGridTarget)):
        label.update(_markers_label(sc))
    label["degradations"] = sc.steps
    return Sample(image=sc.render(), label=label)


def _markers_label(sc: Scene) -> dict:
    """A ChArUco board's ``markers`` or an AprilGrid's ``tags`` (and its corners' lattice ``ids``):
    ids, corners (M, 4, 2) px, centres and visible (all four corners in frame, imaged and not
    hidden by an occluder)."""
    hidden = (lambda px: occluded(px, sc.occluders)) if sc.occluders else None
    return marker_label(sc.board, sc.rvec, sc.tvec, sc.camera, hidden)


def make_sequence(
    preset: str | Preset = "calib",
    seed: int = 0,
    camera_id: int = 0,
    *,
    size: tuple[int, int] | None = None,
    pattern: tuple[int, int] | None = None,
) -> list[Sample]:
    """All ``views_per_camera`` views of one camera: a calibration sequence sharing ``camera_id``."""
    p = get_preset(preset)
    n = p.views_per_camera
    return [make_sample(p, seed, camera_id * n + v, size=size, pattern=pattern) for v in range(n)]
