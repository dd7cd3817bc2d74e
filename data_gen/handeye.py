"""Render a hand-eye calibration set with exact truth: a robot's poses and its camera's board views.

    python -m data_gen.handeye --out DIR [--setup eye-in-hand|eye-to-hand] [--views 20] [--lens mild|strong]
        [--size 1280x960] [--pattern 9x6] [--square 40] [--board charuco:...] [--distance 0.3,0.7]
        [--robot-noise 0.01,0.05] [--swap 0] [--noise 2] [--seed 0]

Frames (ROS names, metres): eye-in-hand, the camera on the flange (``X = T_flange_camera``) sees a
board fixed in the cell (``Y = T_base_board``); eye-to-hand, a fixed camera (``X = T_base_camera``)
sees a board the flange holds (``Y = T_flange_board``). Each view draws the board's pose in the
camera (``C = T_camera_board``: 0.3–0.7 m away, tilted up to 40°, any roll, the whole board
inside the image), and the robot's true flange pose follows from the chain: eye-in-hand
``T_base_flange = Y·C⁻¹·X⁻¹``, eye-to-hand ``T_base_flange = X·C·Y⁻¹``.

The robot reports its pose with noise: a rotation about each base axis of σ_rot degrees (left
multiplied) and a translation of σ_t mm per axis (``--robot-noise σ_rot,σ_t``). ``--swap N``
exchanges the reported poses of N/2 pairs of rows (a time-stamp slip), as a stress test.

Lenses: ``mild`` (f ≈ 1000 px at 1280×960, k1 ≈ −0.05), ``strong`` (f ≈ 650 px at 1280×960,
strong barrel, k1 ≈ −0.3), scaled with the image width. Images get blur σ 0.6 px and read noise.

Writes DIR/images/view_NN.png, DIR/poses.csv (``image,x,y,z,qx,qy,qz,qw``: the reported
T_base_flange, quaternion x y z w) and DIR/truth.json (setup, X, Y, the camera, the true and
reported robot poses, each view's T_camera_board, the swapped rows, the noise).
"""

from __future__ import annotations

import dataclasses
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from aicalib_tf.geometry.camera import Camera
from aicalib_tf.geometry.transform import inv, matrix_to_quat, perturb, to_T

from .background import make_background
from .board import sample_board
from .degrade import apply_degradations
from .pose import corner_visibility
from .render import render_board

__all__ = ["HandEyeSetConfig", "HandEyeSet", "make_camera", "sample_handeye", "render_view", "write_handeye_set",
           "SETUPS", "LENSES"]

SETUPS = ("eye-in-hand", "eye-to-hand")
LENSES = ("mild", "strong")
_UNIT_M = {"mm": 1e-3, "cm": 1e-2, "m": 1.0, "in": 0.0254}


@dataclass(frozen=True)
class HandEyeSetConfig:
    """One set's parameters. square : chessboard square, mm. board : a ChArUco board or an AprilGrid instead.
    distance : (min, max) metres. robot_noise : (σ_rot degrees, σ_t mm) per axis. swap : rows whose
    reported poses are exchanged in pairs. noise : read noise σ, grey levels."""

    setup: str = "eye-in-hand"
    views: int = 20
    lens: str = "mild"
    size: tuple[int, int] = (1280, 960)
    pattern: tuple[int, int] = (9, 6)
    square: float = 40.0
    board: str | None = None
    distance: tuple[float, float] = (0.3, 0.7)
    robot_noise: tuple[float, float] = (0.01, 0.05)
    swap: int = 0
    noise: float = 2.0
    seed: int = 0

    def __post_init__(self):
        if self.setup not in SETUPS:
            raise ValueError(f"setup must be one of {SETUPS}, got {self.setup!r}")
        if self.lens not in LENSES:
            raise ValueError(f"lens must be one of {LENSES}, got {self.lens!r}")
        if self.views < 3 or not 0 <= self.swap <= self.views or self.swap % 2:
            raise ValueError(f"need views >= 3 and an even swap <= views, got views={self.views}, swap={self.swap}")
        if not 0 < self.distance[0] <= self.distance[1]:
            raise ValueError(f"distance must be 0 < min <= max metres, got {self.distance}")


@dataclass(frozen=True)
class HandEyeSet:
    """A set's truth. camera : the lens. board : the rendered board (units: mm). square_m : its square, metres.
    X, Y : (4, 4) metres. C : (V, 4, 4) T_camera_board. A_true, A_reported : (V, 4, 4) T_base_flange.
    swapped : indices of rows whose reported pose belongs to another view."""

    cfg: HandEyeSetConfig
    camera: Camera
    board: object
    square_m: float
    X: np.ndarray
    Y: np.ndarray
    C: np.ndarray
    A_true: np.ndarray
    A_reported: np.ndarray
    swapped: tuple[int, ...]


def make_camera(rng: np.random.Generator, lens: str, size) -> Camera:
    """The ``lens`` of the module docstring, with f and the principal point jittered by ~1%."""
    w, h = size
    f = (1000.0 if lens == "mild" else 650.0) * w / 1280.0 * (1 + rng.normal(0, 0.01))
    dist = np.array([-0.05, 0.02, 0.0, 0.0, 0.0]) if lens == "mild" else np.array([-0.3, 0.1, 0.0, 0.0, -0.015])
    dist = dist * (1 + rng.normal(0, 0.05, 5)) + np.r_[0, 0, rng.normal(0, 2e-4, 2), 0]
    K = np.array([[f, 0, (w - 1) / 2 + rng.normal(0, 0.01 * w)], [0, f * (1 + rng.normal(0, 0.002)),
                                                                   (h - 1) / 2 + rng.normal(0, 0.01 * h)], [0, 0, 1]])
    return Camera(K, dist, (int(w), int(h)))


def _in_mm(board):
    """The marker board ``board`` with its lengths in mm (the renderer's and the poses' unit); a unitless
    board's lengths are read as mm."""
    scale = _UNIT_M.get(board.unit, 1e-3) / 1e-3
    sizes = {"square": board.square, "marker": board.marker} if hasattr(board, "marker") else {"tag": board.tag}
    return dataclasses.replace(board, unit="mm", **{k: v * scale for k, v in sizes.items()})


def _board(rng, cfg: HandEyeSetConfig):
    """(board for the renderer, in mm, square in metres)."""
    if cfg.board:  # a ChArUco board or an AprilGrid, on paper drawn as data_gen's other renders draw it
        from .targets import parse_marker_board, sample_target

        b = _in_mm(parse_marker_board(cfg.board))
        target = sample_target(rng, b)
        return target, target.square_size * 1e-3
    return sample_board(rng, pattern_size=cfg.pattern, square_size=cfg.square, margin_range=(0.5, 1.0)), cfg.square * 1e-3


def _view_pose(rng, cam: Camera, board, cfg: HandEyeSetConfig, tries: int = 500) -> np.ndarray:
    """T_camera_board (metres) with the whole board inside the image (module docstring)."""
    centre_mm = board.object_points().mean(axis=0)
    w, h = cam.image_size
    for _ in range(tries):
        d = rng.uniform(*cfg.distance)
        target = np.array([rng.uniform(0.3, 0.7) * w, rng.uniform(0.3, 0.7) * h])
        ray = cam.pixel_to_ray(target[None])[0]
        ray = ray / ray[2]
        tilt, axis, roll = math.radians(rng.uniform(0, 40)), rng.uniform(0, 2 * math.pi), rng.uniform(0, 2 * math.pi)
        R = (cv2.Rodrigues(np.array([math.cos(axis), math.sin(axis), 0.0]) * tilt)[0]
             @ cv2.Rodrigues(np.array([0.0, 0.0, roll]))[0])
        t_mm = ray * d * 1e3 - R @ centre_mm
        rvec = cv2.Rodrigues(R)[0].ravel()
        _, visible = corner_visibility(board, rvec, t_mm, cam)
        if visible.all():
            return to_T(rvec, t_mm * 1e-3)
    raise RuntimeError(f"no board pose with the whole board in view after {tries} tries")


def _placement(rng, setup: str) -> tuple[np.ndarray, np.ndarray]:
    """(X, Y) of the module docstring: a camera 5–15 cm off the flange looking along its z, a board on
    the table; or a camera 1–1.5 m from the base, a board 5–10 cm off the flange."""
    small = lambda deg: rng.normal(0, math.radians(deg), 3)  # noqa: E731
    if setup == "eye-in-hand":
        X = to_T(small(8) + [0, 0, rng.uniform(-math.pi, math.pi)],
                 [rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), rng.uniform(0.05, 0.15)])
        face_up = np.diag([1.0, -1.0, -1.0])  # the board's z points down: the camera above the table looks along it
        Y = to_T([0, 0, 0], [rng.uniform(0.5, 0.8), rng.uniform(-0.2, 0.2), 0.0])
        Y[:3, :3] = to_T(small(5) + [0, 0, rng.uniform(-math.pi, math.pi)], [0, 0, 0])[:3, :3] @ face_up
    else:
        X = to_T(rng.normal(0, 1.0, 3), [rng.uniform(1.0, 1.5), rng.uniform(-0.3, 0.3), rng.uniform(0.5, 1.0)])
        Y = to_T(small(8) + [0, 0, rng.uniform(-math.pi, math.pi)], [rng.normal(0, 0.02), rng.normal(0, 0.02),
                                                                     rng.uniform(0.05, 0.1)])
    return X, Y


def sample_handeye(cfg: HandEyeSetConfig) -> HandEyeSet:
    """The truth of one set (module docstring); deterministic in ``cfg.seed``."""
    rng = np.random.default_rng([cfg.seed, 48])
    cam = make_camera(rng, cfg.lens, cfg.size)
    board, square_m = _board(rng, cfg)
    X, Y = _placement(rng, cfg.setup)
    C = np.array([_view_pose(rng, cam, board, cfg) for _ in range(cfg.views)])
    A = Y[None] @ inv(C) @ inv(X)[None] if cfg.setup == "eye-in-hand" else X[None] @ C @ inv(Y)[None]
    sr, st = math.radians(cfg.robot_noise[0]), cfg.robot_noise[1] * 1e-3
    noise = np.concatenate([rng.normal(0, sr, (cfg.views, 3)), rng.normal(0, st, (cfg.views, 3))], axis=1)
    reported = perturb(A, noise)
    swapped = tuple(sorted(int(k) for k in rng.choice(cfg.views, cfg.swap, replace=False))) if cfg.swap else ()
    order = list(swapped)
    rng.shuffle(order)
    for a, b in zip(order[0::2], order[1::2]):
        reported[[a, b]] = reported[[b, a]]
    return HandEyeSet(cfg, cam, board, square_m, X, Y, C, A, reported, swapped)


def render_view(s: HandEyeSet, k: int) -> np.ndarray:
    """View k's (H, W) uint8 image; deterministic in (seed, k)."""
    rng = np.random.default_rng([s.cfg.seed, 48, k + 1])
    rvec = cv2.Rodrigues(np.ascontiguousarray(s.C[k, :3, :3]))[0].ravel()
    t_mm = s.C[k, :3, 3] * 1e3
    bg = make_background(rng, s.camera.image_size, clutter=float(rng.uniform(0.0, 0.5)), checker_distractors=0.0)
    img = render_board(s.camera, s.board, rvec, t_mm, bg)
    return apply_degradations(img, [{"name": "gaussian_blur", "sigma": 0.6},
                                    {"name": "gaussian_noise", "sigma": s.cfg.noise}], rng)


def _pose_row(name: str, T: np.ndarray) -> str:
    q = matrix_to_quat(T[:3, :3])
    return ",".join([name] + [f"{v:.9f}" for v in T[:3, 3]] + [f"{v:.12f}" for v in q])


def truth_dict(s: HandEyeSet, names: list[str]) -> dict:
    """truth.json's content (module docstring)."""
    cam = s.camera
    x_name, y_name = (("T_flange_camera", "T_base_board") if s.cfg.setup == "eye-in-hand"
                      else ("T_base_camera", "T_flange_board"))
    return {"setup": s.cfg.setup, x_name: s.X.tolist(), y_name: s.Y.tolist(), "X": s.X.tolist(), "Y": s.Y.tolist(),
            "camera": {"model": cam.model, "K": cam.K.tolist(), "dist": cam.dist.tolist(), "image_size": list(cam.image_size)},
            "pattern_size": list(s.board.pattern_size), "square_m": s.square_m, "board": s.cfg.board,
            "images": names, "T_base_flange_true": s.A_true.tolist(), "T_base_flange_reported": s.A_reported.tolist(),
            "T_camera_board": s.C.tolist(), "swapped": [names[k] for k in s.swapped],
            "robot_noise": {"rotation_deg": s.cfg.robot_noise[0], "translation_mm": s.cfg.robot_noise[1]},
            "read_noise": s.cfg.noise, "seed": s.cfg.seed}


def write_handeye_set(cfg: HandEyeSetConfig, out) -> Path:
    """Render and write the set into ``out`` (module docstring); returns the folder."""
    from aicalib_tf.io import atomic_write_bytes, atomic_write_text
    from aicalib_tf.jsonio import dumps

    out = Path(out)
    (out / "images").mkdir(parents=True, exist_ok=True)
    s = sample_handeye(cfg)
    names = [f"view_{k:02d}.png" for k in range(cfg.views)]
    for k, name in enumerate(names):
        ok, png = cv2.imencode(".png", render_view(s, k))
        if not ok:
            raise OSError(f"{out / 'images' / name}: PNG encoding failed")
        atomic_write_bytes(out / "images" / name, png.tobytes())
    rows = ["image,x,y,z,qx,qy,qz,qw"] + [_pose_row(n, T) for n, T in zip(names, s.A_reported)]
    atomic_write_text(out / "poses.csv", "\n".join(rows) + "\n")
    atomic_write_text(out / "truth.json", dumps(truth_dict(s, names)) + "\n")
    return out


def _pair(text: str, what: str) -> tuple[float, float]:
    try:
        a, b = (float(v) for v in text.split(","))
    except ValueError:
        raise ValueError(f"{what} must be two numbers A,B, got {text!r}") from None
    return a, b


def build_parser():
    """The command line's parser (docs/cli.md is generated from it)."""
    from aicalib_tf.cli import parser

    ap = parser("python -m data_gen.handeye", __doc__)
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--setup", default="eye-in-hand", choices=SETUPS)
    ap.add_argument("--views", type=int, default=20)
    ap.add_argument("--lens", default="mild", choices=LENSES)
    ap.add_argument("--size", default="1280x960", help="WIDTHxHEIGHT (default: %(default)s)")
    ap.add_argument("--pattern", default="9x6", help="inner corners COLSxROWS (default: %(default)s)")
    ap.add_argument("--square", type=float, default=40.0, help="square size, mm (default: %(default)s)")
    ap.add_argument("--board", help="a marker board instead: charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100 or "
                    "aprilgrid:6x6,tag=88mm,spacing=0.3 (or a Kalibr target.yaml)")
    ap.add_argument("--distance", default="0.3,0.7", help="camera to board, metres MIN,MAX (default: %(default)s)")
    ap.add_argument("--robot-noise", default="0.01,0.05", help="robot σ per axis: DEGREES,MM (default: %(default)s)")
    ap.add_argument("--swap", type=int, default=0, help="rows whose reported poses are exchanged in pairs (even)")
    ap.add_argument("--noise", type=float, default=2.0, help="read noise σ, grey levels (default: %(default)s)")
    ap.add_argument("--seed", type=int, default=0)
    return ap


def main(argv: list[str] | None = None) -> int:
    """CLI entry: 0 on success, 2 on bad arguments (one line on stderr)."""
    from aicalib_tf.cli import run_main
    from aicalib_tf.geometry.pattern import check_pattern, parse_pattern

    args = build_parser().parse_args(argv)

    def body() -> int:
        size = tuple(int(v) for v in args.size.lower().split("x"))
        if len(size) != 2 or min(size) < 64:
            raise ValueError(f"--size must be WIDTHxHEIGHT, at least 64x64, got {args.size!r}")
        cfg = HandEyeSetConfig(args.setup, args.views, args.lens, size, check_pattern(parse_pattern(args.pattern)),
                               args.square, args.board, _pair(args.distance, "--distance"),
                               _pair(args.robot_noise, "--robot-noise"), args.swap, args.noise, args.seed)
        out = write_handeye_set(cfg, args.out)
        print(f"wrote {out}: images/ ({cfg.views} views), poses.csv, truth.json")
        return 0
    return run_main(body, debug=args.debug)


if __name__ == "__main__":
    sys.exit(main())
