"""Board poses like a person waving a printed board in front of a camera.

A pose is ``(rvec, tvec)`` mapping board coordinates to camera coordinates (``T_cam_board``),
as in ``cv2.projectPoints``. The camera looks along +z; x right, y down.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from aicalib_tf.geometry.camera import Camera
from aicalib_tf.geometry.pose import in_frame, project_points

from .board import Board

__all__ = ["PoseConfig", "sample_pose", "corner_visibility", "imaged_mask", "paper_circle_fill", "FRAMING"]

FRAMING = ("inside", "partial", "any")


@dataclass(frozen=True)
class PoseConfig:
    """How poses are drawn.

    tilt_max_deg : largest angle between the board normal and the optical axis (degrees).
    fill : range of the paper's apparent diagonal as a fraction of the image diagonal.
    framing : "inside" (whole paper in frame), "partial" (some inner corners cut by the frame,
        at least ``min_visible_fraction`` of them in frame) or "any".
    max_view_angle_deg : largest angle between the board normal and any line of sight.
    circle_fill : for a fisheye, None or the range of :func:`paper_circle_fill` (the paper's
        extent in the image over the image circle's diameter); when set it replaces ``fill``, the
        distance is solved to give a drawn value exactly, and the board is aimed so that it may
        reach the rim.
    rim_share : with ``circle_fill``, the share of close-ups aimed so that the paper's far side lies on the
        image circle's rim, where its corners sit 80–100° off axis; 0 draws nothing. rim_reach : where those
        aim, as a share of the farthest aim that keeps the paper inside the circle (above 1: past the rim, for
        framing "any"; the circle then cuts the paper).
    """

    tilt_max_deg: float = 60.0
    fill: tuple[float, float] = (0.25, 0.8)
    framing: str = "inside"
    min_visible_fraction: float = 0.3
    max_view_angle_deg: float = 80.0
    roll_deg: tuple[float, float] = (0.0, 360.0)
    circle_fill: tuple[float, float] | None = None
    rim_share: float = 0.0
    rim_reach: tuple[float, float] = (0.9, 1.0)

    def __post_init__(self):
        if self.framing not in FRAMING:
            raise ValueError(f"framing must be one of {FRAMING}, got {self.framing!r}")


def _rotation(tilt: float, tilt_axis: float, roll: float) -> np.ndarray:
    """Roll about the board normal, then tilt about an in-plane axis at angle ``tilt_axis``."""
    r_roll, _ = cv2.Rodrigues(np.array([0.0, 0.0, roll]))
    axis = np.array([math.cos(tilt_axis), math.sin(tilt_axis), 0.0])
    r_tilt, _ = cv2.Rodrigues(axis * tilt)
    return r_tilt @ r_roll


def imaged_mask(points_cam: np.ndarray, camera: Camera) -> np.ndarray:
    """(N,) bool: points (N, 3) the lens images: in front of it (for a fisheye: within its
    ``max_theta``, which may exceed 90°), inside the model's monotonic domain and the image circle."""
    return camera.imaged(points_cam)


def corner_visibility(board: Board, rvec, tvec, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Project the inner corners and flag those a detector could see, occluders aside.

    Returns (corners (cols·rows, 2) float64 px from :func:`aicalib_tf.geometry.pose.project_points`,
    visible (cols·rows,) bool): imaged by the lens (:func:`imaged_mask`: in front, in the
    monotonic domain, inside a fisheye's image circle) and within the hull of the pixel centres. The pose sampler and the labels both use this one rule.
    """
    obj = board.object_points()
    R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    corners = project_points(obj, rvec, tvec, camera)
    imaged = imaged_mask(obj @ R.T + np.asarray(tvec, dtype=np.float64).ravel(), camera)
    return corners, imaged & in_frame(corners, camera.image_size, border=0.5)


def _paper_outline(board: Board, fisheye: bool) -> np.ndarray:
    """(M, 3) board-frame points of the paper's outline: its 4 corners, plus 7 points along each
    edge for a fisheye, whose straight edges bow out of the corners' hull."""
    x0, y0, x1, y1 = board.paper_bounds()
    corners = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]], dtype=np.float64)
    if not fisheye:
        return corners
    s = np.linspace(0.0, 1.0, 9)[1:-1, None]
    edges = [a + s * (b - a) for a, b in zip(corners, np.roll(corners, -1, axis=0))]
    return np.concatenate([corners] + edges)


def paper_circle_fill(board: Board, R: np.ndarray, t: np.ndarray, camera: Camera) -> float:
    """How much of a fisheye's image circle the paper fills: the largest distance (px) between two
    projected points of its outline (4 corners and 7 points along each edge) over the circle's
    diameter (px, ``2·circle_radius·sqrt(fx·fy)``). R : (3, 3), t : (3,) board -> camera.
    NaN where an outline point is not imaged (behind the lens or beyond its circle)."""
    paper = _paper_outline(board, True)
    cam_pts = paper @ np.asarray(R, dtype=np.float64).T + np.asarray(t, dtype=np.float64).ravel()
    if not np.all(camera.imaged(cam_pts)):
        return float("nan")
    px = camera.project(cam_pts)
    extent = float(np.max(np.linalg.norm(px[:, None, :] - px[None, :, :], axis=2)))
    return extent / (2.0 * camera.circle_radius() * math.sqrt(camera.fx * camera.fy))


def _distance_for_fill(board: Board, R: np.ndarray, centre_ray: np.ndarray, camera: Camera, fill: float) -> float | None:
    """Range (board units) along the unit ``centre_ray`` at which the paper's centre gives
    :func:`paper_circle_fill` = ``fill`` (bisection on the log of the range); None if no range does."""
    def fill_at(z: float) -> float:
        return paper_circle_fill(board, R, z * centre_ray - R @ board.centre(), camera)

    x0, y0, x1, y1 = board.paper_bounds()
    diag = math.hypot(x1 - x0, y1 - y0)
    near, far = 0.05 * diag, 50.0 * diag
    if not fill_at(far) < fill:
        return None
    # the near end: the closest range whose whole outline is still imaged
    for _ in range(40):
        if np.isfinite(fill_at(near)):
            break
        near *= 1.25
    else:
        return None
    if not fill_at(near) > fill:
        return None
    for _ in range(40):
        mid = math.sqrt(near * far)
        f = fill_at(mid)
        if not np.isfinite(f) or f > fill:
            near = mid
        else:
            far = mid
    return far


def _acceptable(camera: Camera, board: Board, R: np.ndarray, t: np.ndarray, cfg: PoseConfig) -> bool:
    paper = _paper_outline(board, camera.fisheye)
    paper_cam = paper @ R.T + t
    if camera.fisheye:
        if not np.all(camera.imaged(paper_cam)):
            return False
    elif np.any(paper_cam[:, 2] <= 0):
        return False
    # The camera must see the printed side, at a bounded grazing angle everywhere.
    normal = R[:, 2]
    cosang = (paper_cam @ normal) / np.linalg.norm(paper_cam, axis=1)
    if np.any(cosang < math.cos(math.radians(cfg.max_view_angle_deg))):
        return False
    rvec = cv2.Rodrigues(R)[0]
    if cfg.circle_fill is not None and camera.fisheye:
        f = paper_circle_fill(board, R, t, camera)
        if not cfg.circle_fill[0] - 1e-6 <= f <= cfg.circle_fill[1] + 1e-6:
            return False
    if cfg.framing == "inside":
        if not np.all(imaged_mask(paper_cam, camera)):
            return False
        return bool(np.all(in_frame(project_points(paper, rvec, t, camera), camera.image_size)))
    frac = corner_visibility(board, rvec, t, camera)[1].mean()
    if cfg.framing == "partial":
        return bool(cfg.min_visible_fraction <= frac < 1.0)
    return bool(frac >= cfg.min_visible_fraction)


def sample_pose(
    rng: np.random.Generator, camera: Camera, board: Board, cfg: PoseConfig = PoseConfig(), *, max_tries: int = 400
) -> tuple[np.ndarray, np.ndarray]:
    """Draw ``(rvec, tvec)``, each (3,) float64, satisfying ``cfg``.

    The board centre is aimed at a pixel drawn uniformly over the image (so boards reach the
    image corners), its distance set by the apparent size ``cfg.fill``; then it is rolled
    about its normal and tilted about a random in-plane axis by up to ``cfg.tilt_max_deg``.
    """
    w, h = camera.image_size
    # Apparent size is relative to the diagonal of a square of the image's area, so that very
    # elongated images (2000x200) do not ask for boards that cannot fit.
    diag_px = math.sqrt(2.0 * w * h)
    x0, y0, x1, y1 = board.paper_bounds()
    paper_diag = math.hypot(x1 - x0, y1 - y0)
    f = math.sqrt(camera.fx * camera.fy)
    for attempt in range(max_tries):
        fill = rng.uniform(*cfg.fill)
        if cfg.framing == "inside":
            fill *= max(0.1, 1.0 - attempt / max_tries)  # shrink if big boards keep failing
        tilt = math.radians(cfg.tilt_max_deg) * math.sqrt(rng.uniform())  # favour larger tilts a bit
        tilt_axis = rng.uniform(0.0, 2.0 * math.pi)
        roll = math.radians(rng.uniform(*cfg.roll_deg))
        R = _rotation(tilt, tilt_axis, roll)
        if cfg.circle_fill is not None and camera.fisheye:
            R, t = _close_up(rng, camera, board, R, cfg.circle_fill, cfg.rim_share, cfg.rim_reach)
            if t is not None and _acceptable(camera, board, R, t, cfg):
                return cv2.Rodrigues(R)[0].ravel(), t
            continue
        if camera.fisheye:
            target = _fisheye_target(rng, camera, cfg.framing == "partial")
        elif cfg.framing == "partial":
            target = np.array([rng.uniform(-0.3, 1.3) * w, rng.uniform(-0.3, 1.3) * h])
        else:
            target = np.array([rng.uniform(0.0, w - 1.0), rng.uniform(0.0, h - 1.0)])
        ray = camera.pixel_to_ray(target)
        if not np.all(np.isfinite(ray)):
            continue
        # Distance from the apparent size; distortion and tilt change it a little, which is fine.
        # Pinhole rays are (x/z, y/z, 1), so this is depth; fisheye rays are unit: range.
        z = f * paper_diag / (fill * diag_px)
        centre_cam = z * ray
        t = centre_cam - R @ board.centre()
        if _acceptable(camera, board, R, t, cfg):
            return cv2.Rodrigues(R)[0].ravel(), t
    raise RuntimeError(
        f"no acceptable pose for a {board.cols}x{board.rows} board with framing={cfg.framing!r} "
        f"after {max_tries} tries; widen PoseConfig.fill or tilt"
    )


def _close_up(rng: np.random.Generator, camera: Camera, board: Board, R: np.ndarray,
              circle_fill: tuple[float, float], rim_share: float = 0.0,
              rim_reach: tuple[float, float] = (0.9, 1.0)) -> tuple[np.ndarray, np.ndarray | None]:
    """(R (3, 3), t (3,) or None) for a board held close to a fisheye, filling a drawn fraction of
    its image circle (:func:`paper_circle_fill`). Its centre is aimed at a pixel up to ``1 - fill``
    of the circle's radius from the circle's centre (so its far side may reach the rim), and it
    faces that line of sight as a person holding it towards the lens does: ``R`` (roll and tilt
    about the optical axis) is turned so that its tilt is measured from the line of sight; a share
    ``rim_share`` is aimed at ``rim_reach`` of that reach (1: the far side on the rim). t is None when no range
    gives that fill."""
    fill = rng.uniform(*circle_fill)
    a = rng.uniform(0.0, 2.0 * math.pi)
    rim = rim_share > 0 and rng.random() < rim_share  # no draw without a rim share: other presets' poses stay
    s = (1.0 - fill) * (rng.uniform(*rim_reach) if rim else math.sqrt(rng.uniform()))
    rho = camera.circle_radius()
    uv = np.array([camera.cx + s * rho * camera.fx * math.cos(a), camera.cy + s * rho * camera.fy * math.sin(a)])
    ray = camera.pixel_to_ray(uv)
    if not np.all(np.isfinite(ray)):
        return R, None
    ray = ray / np.linalg.norm(ray)
    axis = np.cross([0.0, 0.0, 1.0], ray)
    angle = math.atan2(float(np.linalg.norm(axis)), float(ray[2]))
    if angle > 1e-9:
        R = cv2.Rodrigues(axis / np.linalg.norm(axis) * angle)[0] @ R
    z = _distance_for_fill(board, R, ray, camera, fill)
    return R, None if z is None else z * ray - R @ board.centre()


def _fisheye_target(rng: np.random.Generator, camera: Camera, partial: bool) -> np.ndarray:
    """(2,) px where a fisheye view aims the board centre: uniform over the imaged part of the
    frame, and a third of the time in the outer ring of the image circle (0.7–1.0 of its
    radius; 0.85–1.0 for partial framing, whose boards then run past the rim), so boards reach the
    rim where the lens bends most."""
    w, h = camera.image_size
    rho = camera.circle_radius()
    for _ in range(50):
        if rng.random() < 1.0 / 3.0:
            a = rng.uniform(0.0, 2.0 * math.pi)
            s = rng.uniform(0.85, 1.0) if partial else rng.uniform(0.7, 1.0)
            uv = np.array([camera.cx + s * rho * camera.fx * math.cos(a), camera.cy + s * rho * camera.fy * math.sin(a)])
        else:
            lo, hi = (-0.3, 1.3) if partial else (0.0, 1.0)
            uv = np.array([rng.uniform(lo, hi) * (w - 1.0), rng.uniform(lo, hi) * (h - 1.0)])
        if partial or (camera.inside_circle(uv) and 0 <= uv[0] <= w - 1 and 0 <= uv[1] <= h - 1):
            return uv
    return np.array([camera.cx, camera.cy])
