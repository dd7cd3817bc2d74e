"""Render a hand-held calibration video with exact truth for every frame.

    python -m data_gen.video --out DIR [--seconds 60] [--fps 30] [--size 1280x720]
        [--lens mild|strong|fisheye150] [--pattern 9x6] [--square 25] [--seed 0]
        [--shutter 0.0167] [--rolling-shutter 0] [--noise 2] [--format avi|mp4] [--y4m] [--workers N] [--pace 1]
        [--rig-baseline MM] [--board charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100 | aprilgrid:6x6,tag=88mm,spacing=0.3]

A board moves along a smooth hand-held path (:mod:`data_gen.path`: rests at poses spread over the
image with varied tilts, minimum-jerk moves between them, some poses cut by the frame, some out
of view). The camera, board and renderer are data_gen's (:mod:`data_gen.render`, lenses from
:mod:`aicalib_tf.geometry`). Motion blur comes from the real motion: a frame averages the board
at sub-frame times over the exposure (``--shutter`` s; one sub-frame per 0.7 px of the fastest
corner's motion, at most 16). The board is rendered once per frame, at the middle of the
exposure, and moved to each sub-frame time by the exact per-pixel map of the board plane
(computed on an 8-px grid of rays and interpolated), then composited over the static background.
``--rolling-shutter T`` reads the rows out over T s (row y at y/H·T after row 0). Optics blur
(σ 0.5 px) and read noise (``--noise`` grey levels) follow; the video codec adds its own loss.

Writes into DIR: video.avi (Motion JPEG, quality 95) or video.mp4 (mp4v), both read back by
``cv2.VideoCapture``; with ``--y4m`` also video.y4m (YUV4MPEG2 4:2:0, grey: what Chromium's
fake camera plays); labels.jsonl (one strict JSON object per frame: index, time_s, image_size,
pattern_size, square_size, K, distortion_model, dist, rvec, tvec at the middle of the exposure,
corners (every inner corner in OpenCV order, null where the lens does not image it; with rolling
shutter, where each corner's row was read), visible, motion_px (the fastest corner's motion
during the exposure) and subframes) and meta.json (the arguments). Frames are rendered in
``--workers`` processes; the same arguments give the same frames whatever their number.

``--rig-baseline B`` renders a synchronized stereo pair instead: camera 0 as above and a second
camera ``B`` board units to its right, converging by a few degrees (placed as
:func:`data_gen.rig.rig_placement` places a rig's cameras, its own lens drawn alike), seeing the
same board path at the same instants. It writes video_cam0/video_cam1 and labels_cam0/labels_cam1
(the same fields, each in its camera's frame), and meta.json's ``rig`` holds R (2, 3, 3) and T
(2, 3) with X_k = R_k·X_0 + T_k (board units) and the baseline |T_1|.

``--board charuco:...`` films a ChArUco board (:mod:`data_gen.charuco`) instead of the chessboard:
its inner corners replace --pattern and --square (corner ids are OpenCV's ChArUco ids), and each
label also holds ``board`` (the description). ``--board aprilgrid:...`` (or a Kalibr target YAML)
films a Kalibr AprilGrid (:mod:`data_gen.aprilgrid`): the corners are its tag corners, and each label
also holds their lattice ``ids``.
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np

from aicalib_tf.geometry.pattern import check_pattern, parse_pattern
from aicalib_tf.geometry.pose import in_frame

from .background import make_background
from .board import Board
from .camera import sample_camera, sample_fisheye
from .dataset import check_pixels
from .degrade import gaussian_blur, gaussian_noise
from .path import HandPath, RigPath, hand_path
from .pose import corner_visibility
from .render import lens_coverage, render_board
from .rig import rig_placement
from .sample import OUTSIDE_CIRCLE
from .targets import HELP as BOARD_HELP
from .targets import marker_target, parse_marker_board

__all__ = ["VideoConfig", "VideoScene", "make_scene", "rig_pose", "render_frame", "frame_truth", "write_video", "write_y4m_header",
           "y4m_frame", "LENSES", "main"]

LENSES = ("mild", "strong", "fisheye150")
_STEP = 8  # px between the rays of the per-pixel motion map
_MAX_SUBFRAMES = 16
MAX_FRAMES = 1_000_000  # frames of one video (--seconds × --fps), the bound --count has on a dataset


@dataclass(frozen=True)
class VideoConfig:
    """What :func:`write_video` renders (the command line's options)."""

    out: str
    seconds: float = 60.0
    fps: float = 30.0
    size: tuple[int, int] = (1280, 720)
    lens: str = "mild"
    pattern: tuple[int, int] = (9, 6)
    square: float = 25.0
    seed: int = 0
    shutter: float = 1.0 / 60.0  # exposure, s
    rolling_shutter: float = 0.0  # readout time of the whole frame, s (0: global shutter)
    noise: float = 2.0  # read noise σ, grey levels
    format: str = "avi"
    y4m: bool = False
    workers: int = 1
    pace: float = 1.0  # the hand's speed: rests and moves last 1/pace as long (short test videos: 3)
    rig_baseline: float = 0.0  # board units between two cameras (0: one camera)
    board: str | None = None  # a marker board (data_gen.targets): its corners replace pattern and square

    def __post_init__(self):
        if self.board:  # a bad description is a ValueError naming the field
            b = marker_target(parse_marker_board(self.board))
            object.__setattr__(self, "pattern", b.pattern_size)
            object.__setattr__(self, "square", float(b.square_size))
        if self.lens not in LENSES:
            raise ValueError(f"--lens must be one of {', '.join(LENSES)}, got {self.lens!r}")
        if self.format not in ("avi", "mp4"):
            raise ValueError(f"--format must be avi or mp4, got {self.format!r}")
        if not (self.seconds > 0 and self.fps > 0 and self.pace > 0 and self.shutter >= 0 and self.rolling_shutter >= 0
                and self.rig_baseline >= 0):
            raise ValueError("--seconds, --fps and --pace must be > 0, --shutter, --rolling-shutter and "
                             "--rig-baseline >= 0")
        if not self.seconds * self.fps <= MAX_FRAMES:  # --seconds 1e9 would render for ever, as --count 1e9 would
            raise ValueError(f"--seconds × --fps must give at most {MAX_FRAMES:,} frames, got {self.seconds * self.fps:.3g}")
        check_pixels(*self.size)
        if self.shutter > 1.0 / self.fps:
            raise ValueError(f"--shutter {self.shutter:g} s is longer than a frame (1/{self.fps:g} s)")


@dataclass(frozen=True)
class VideoScene:
    """Everything every frame shares: camera, board, background (H, W) float32, path, and the rays
    (Hc, Wc, 3) of the motion map's grid (every ``_STEP`` px, NaN where not imaged)."""

    cfg: VideoConfig
    camera: object
    board: Board
    background: np.ndarray
    path: HandPath
    rays: np.ndarray
    upsample: tuple[np.ndarray, np.ndarray]  # (H, W) float32 grid coordinates of each pixel


def _camera(lens: str, size, rng):
    if lens == "fisheye150":
        return sample_fisheye(rng, size, fov_deg=(150.0, 150.0))
    return sample_camera(rng, size, hfov_deg=(55.0, 75.0) if lens == "mild" else (80.0, 100.0), distortion=lens)


def rig_pose(cfg: VideoConfig) -> tuple[np.ndarray, np.ndarray]:
    """(R (2, 3, 3), T (2, 3)) of the stereo pair ``cfg.rig_baseline`` apart, from ``cfg.seed`` alone."""
    return rig_placement(np.random.default_rng([cfg.seed, 17]), 2, cfg.rig_baseline, (2.0, 6.0))


def _background(rng, cam) -> np.ndarray:
    bg = make_background(rng, cam.image_size, clutter=0.3, checker_distractors=0.0)
    cover = lens_coverage(cam)
    return bg if cover is None else (bg * cover + OUTSIDE_CIRCLE * (1.0 - cover)).astype(np.float32)


def make_scene(cfg: VideoConfig, camera: int = 0) -> VideoScene:
    """The video's camera, board, background and path, from ``cfg.seed`` alone; ``camera`` 1: the
    second camera of the stereo pair (``cfg.rig_baseline``), its own lens and background, the same path."""
    rng = np.random.default_rng([cfg.seed, 11])
    cam = _camera(cfg.lens, cfg.size, rng)
    board = marker_target(parse_marker_board(cfg.board)) if cfg.board else Board(check_pattern(cfg.pattern), float(cfg.square))
    bg = _background(rng, cam)
    path = hand_path(rng, cam, board, cfg.seconds + 1.0 / cfg.fps, dwell_s=(0.25 / cfg.pace, 0.6 / cfg.pace),
                     move_s=(0.8 / cfg.pace, 1.8 / cfg.pace))
    if camera:
        R, T = rig_pose(cfg)
        other = np.random.default_rng([cfg.seed, 19])
        cam = _camera(cfg.lens, cfg.size, other)
        bg, path = _background(other, cam), RigPath(path, R[1], T[1])
    w, h = cam.image_size
    xs, ys = np.arange(0, w + _STEP, _STEP, dtype=np.float64), np.arange(0, h + _STEP, _STEP, dtype=np.float64)
    rays = cam.pixel_to_ray(np.stack(np.meshgrid(xs, ys), axis=-1))
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32) / _STEP, np.arange(h, dtype=np.float32) / _STEP)
    return VideoScene(cfg, cam, board, bg, path, rays, (gx, gy))


def _corners_at(scene: VideoScene, t0: float) -> tuple[np.ndarray, np.ndarray]:
    """(corners (N, 2) px, visible (N,)) as the frame starting at ``t0`` s images them: the pose at the
    middle of each corner's row's exposure (rolling shutter: fixed point over the row, 3 rounds)."""
    cfg, cam, board = scene.cfg, scene.camera, scene.board
    mid = t0 + cfg.shutter / 2
    if cfg.rolling_shutter <= 0:
        return corner_visibility(board, *scene.path.pose(mid), cam)
    h, obj = cam.image_size[1], board.object_points()
    y = np.full(len(obj), h / 2.0)
    for _ in range(3):
        times = mid + cfg.rolling_shutter * np.clip(np.nan_to_num(y, nan=h / 2), 0, h) / h
        P = np.array([R @ X + t for X, (R, t) in zip(obj, (scene.path.matrix(t) for t in times))])
        uv = cam.lens.project(P)
        y = uv[:, 1]
    visible = cam.imaged(P) & in_frame(uv, cam.image_size, border=0.5)
    return uv, visible


def _plane_map(scene: VideoScene, times: np.ndarray, Rm, tm) -> np.ndarray:
    """(Hc, Wc, 2) px: where the board point seen at each grid pixel at ``times`` (Hc,) s (one per
    grid row) was imaged at the middle pose (Rm, tm); NaN off the plane or not imaged."""
    Hi = np.empty((len(times), 3, 3))
    for k, t in enumerate(times):
        if k and t == times[k - 1]:  # a global shutter: one pose for every row
            Hi[k] = Hi[k - 1]
            continue
        R, tv = scene.path.matrix(t)
        Hi[k] = np.linalg.inv(np.column_stack([R[:, 0], R[:, 1], tv]))
    q = np.einsum("yij,yxj->yxi", Hi, scene.rays)
    with np.errstate(divide="ignore", invalid="ignore"):
        front = q[..., 2] > 0
        X, Y = np.where(front, q[..., 0] / q[..., 2], np.nan), np.where(front, q[..., 1] / q[..., 2], np.nan)
    P = X[..., None] * Rm[:, 0] + Y[..., None] * Rm[:, 1] + tm
    return scene.camera.project(P)


def _upsample(scene: VideoScene, grid: np.ndarray, fill: float) -> np.ndarray:
    """(Hc, Wc) values on the ray grid -> (H, W) float32, bilinear; NaN becomes ``fill``."""
    g = np.nan_to_num(grid, nan=fill).astype(np.float32)
    return cv2.remap(g, *scene.upsample, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def _paper_alpha(scene: VideoScene, Rm, tm) -> np.ndarray:
    """(H, W) float32 share of each pixel covered by the paper at the middle pose (a 1-px ramp at its edge)."""
    Hi = np.linalg.inv(np.column_stack([Rm[:, 0], Rm[:, 1], tm]))
    q = scene.rays @ Hi.T
    with np.errstate(divide="ignore", invalid="ignore"):
        X, Y = np.where(q[..., 2] > 0, q[..., 0] / q[..., 2], np.nan), np.where(q[..., 2] > 0, q[..., 1] / q[..., 2], np.nan)
    x0, y0, x1, y1 = scene.board.paper_bounds()
    inside = np.minimum.reduce([X - x0, x1 - X, Y - y0, y1 - Y])  # board units, > 0 on the paper
    gy, gx = np.gradient(np.nan_to_num(X)), np.gradient(np.nan_to_num(Y))
    per_px = np.maximum(np.hypot(*gy), np.hypot(*gx)) / _STEP  # board units per px
    d = _upsample(scene, inside / np.maximum(per_px, 1e-9), -1e3)
    return np.clip(0.5 + d, 0.0, 1.0)


def frame_truth(scene: VideoScene, index: int) -> dict:
    """Frame ``index``'s label dict (JSON-ready) without rendering it: the pose at the middle of the
    exposure, the corners, which are visible, and the fastest corner's motion during the exposure."""
    cfg, cam = scene.cfg, scene.camera
    t0 = index / cfg.fps
    Rm, tvm = scene.path.matrix(t0 + cfg.shutter / 2 + cfg.rolling_shutter / 2)
    corners, visible = _corners_at(scene, t0)
    a, _ = corner_visibility(scene.board, *scene.path.pose(t0), cam)
    b, _ = corner_visibility(scene.board, *scene.path.pose(t0 + cfg.shutter), cam)
    moved = np.linalg.norm(a - b, axis=1)[visible] if visible.any() else np.zeros(1)
    motion = float(np.nanmax(np.nan_to_num(moved, nan=0.0), initial=0.0))
    return {"index": index, "time_s": t0, "image_size": list(cam.image_size),
            "pattern_size": list(scene.board.pattern_size), "square_size": scene.board.square_size,
            "K": cam.K.tolist(), "distortion_model": cam.model, "dist": cam.dist.tolist(),
            "rvec": cv2.Rodrigues(Rm)[0].ravel().tolist(), "tvec": tvm.tolist(),
            "corners": [[float(x), float(y)] if np.isfinite(x) and np.isfinite(y) else None for x, y in corners],
            "visible": visible.tolist(), "has_board": bool(visible.any()), "motion_px": motion,
            "subframes": int(np.clip(math.ceil(motion / 0.7), 1, _MAX_SUBFRAMES)),
            **({"board": cfg.board} if cfg.board else {}),
            **({"ids": scene.board.corner_ids().tolist()} if hasattr(scene.board, "corner_ids") else {})}


def render_frame(scene: VideoScene, index: int) -> tuple[np.ndarray, dict]:
    """Frame ``index``: ((H, W) uint8 grey, its label dict (:func:`frame_truth`), JSON-ready)."""
    cfg, cam = scene.cfg, scene.camera
    label = frame_truth(scene, index)
    t0 = label["time_s"]
    tm = t0 + cfg.shutter / 2 + cfg.rolling_shutter / 2
    Rm, tvm = scene.path.matrix(tm)
    rvm = cv2.Rodrigues(Rm)[0].ravel()
    n = label["subframes"]
    sharp = render_board(cam, scene.board, rvm, tvm, scene.background, samples=34, junction_samples=89)
    img = sharp
    if n > 1 or cfg.rolling_shutter > 0:
        alpha = _paper_alpha(scene, Rm, tvm)
        layer = sharp - scene.background * (1.0 - alpha)
        rows = scene.rays.shape[0]
        row_t = cfg.rolling_shutter * np.minimum(np.arange(rows) * _STEP, cam.image_size[1]) / cam.image_size[1]
        acc, acc_a = np.zeros_like(sharp), np.zeros_like(sharp)
        for k in range(n):
            m = _plane_map(scene, t0 + (k + 0.5) / n * cfg.shutter + row_t, Rm, tvm)
            mx, my = _upsample(scene, m[..., 0], -1e4), _upsample(scene, m[..., 1], -1e4)
            acc += cv2.remap(layer, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            acc_a += cv2.remap(alpha, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        img = acc / n + scene.background * (1.0 - acc_a / n)
    rng = np.random.default_rng([cfg.seed, 13, index])
    img = gaussian_noise(gaussian_blur(img, rng, sigma=0.5), rng, sigma=cfg.noise)
    gray = np.clip(np.rint(img * 255.0), 0, 255).astype(np.uint8)
    return gray, label


def write_y4m_header(fh, size, fps: float) -> None:
    """The YUV4MPEG2 stream header (4:2:0, progressive, square pixels)."""
    num, den = (int(round(fps * 1000)), 1000) if fps != int(fps) else (int(fps), 1)
    fh.write(f"YUV4MPEG2 W{size[0]} H{size[1]} F{num}:{den} Ip A1:1 C420jpeg\n".encode())


def y4m_frame(gray: np.ndarray) -> bytes:
    """One YUV4MPEG2 frame of a (H, W) uint8 grey image (H and W even): FRAME, Y, then neutral U and V."""
    h, w = gray.shape
    return b"FRAME\n" + gray.tobytes() + bytes([128]) * (2 * ((w + 1) // 2) * ((h + 1) // 2))


_SCENE: VideoScene | None = None


def _init_worker(cfg: VideoConfig, camera: int) -> None:
    global _SCENE
    _SCENE = make_scene(cfg, camera)


def _work(index: int):
    return render_frame(_SCENE, index)


def _frames(cfg: VideoConfig, count: int, camera: int = 0):
    if cfg.workers <= 1:
        scene = make_scene(cfg, camera)
        return (render_frame(scene, i) for i in range(count))
    import multiprocessing as mp

    pool = mp.get_context("spawn").Pool(cfg.workers, initializer=_init_worker, initargs=(cfg, camera))
    return pool.imap(_work, range(count), chunksize=4)


def _write_camera(cfg: VideoConfig, out: Path, count: int, camera: int, suffix: str, progress: bool) -> str:
    """Render one camera's frames into out/video{suffix}.avi|mp4, labels{suffix}.jsonl (and .y4m); returns the video's name."""
    from tqdm import tqdm

    from aicalib_tf.io import atomic_write_text

    w, h = cfg.size
    name = out / f"video{suffix}.{cfg.format}"
    writer = cv2.VideoWriter(str(name), cv2.VideoWriter_fourcc(*("MJPG" if cfg.format == "avi" else "mp4v")),
                             cfg.fps, (w, h))
    if not writer.isOpened():
        raise OSError(f"{name}: OpenCV cannot write this video format here")
    if cfg.format == "avi":
        writer.set(cv2.VIDEOWRITER_PROP_QUALITY, 95)
    labels = []
    y4m = open(out / f"video{suffix}.y4m", "wb") if cfg.y4m else None
    try:
        if y4m:
            write_y4m_header(y4m, (w, h), cfg.fps)
        for gray, label in tqdm(_frames(cfg, count, camera), total=count, desc=f"render{suffix}", unit="frame",
                                disable=not progress):
            writer.write(cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR))
            if y4m:
                y4m.write(y4m_frame(gray))
            labels.append(json.dumps(label, allow_nan=False))
    finally:
        writer.release()
        if y4m:
            y4m.close()
    atomic_write_text(out / f"labels{suffix}.jsonl", "\n".join(labels) + "\n")
    return name.name


def write_video(cfg: VideoConfig, *, progress: bool = True) -> Path:
    """Render every frame and write DIR/video.avi|mp4, labels.jsonl, meta.json (and video.y4m); returns DIR.
    With ``cfg.rig_baseline``: video_cam0/video_cam1, labels_cam0/labels_cam1 and the rig in meta.json."""
    from aicalib_tf.io import atomic_write_text

    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    count = int(round(cfg.seconds * cfg.fps))
    meta = dict(asdict(VideoConfig(**{**asdict(cfg), "out": str(out)})), frames=count)
    if cfg.rig_baseline > 0:
        R, T = rig_pose(cfg)
        meta["videos"] = [_write_camera(cfg, out, count, k, f"_cam{k}", progress) for k in (0, 1)]
        meta["rig"] = {"R": R.tolist(), "T": T.tolist(), "baseline": float(np.linalg.norm(T[1]))}
    else:
        meta["video"] = _write_camera(cfg, out, count, 0, "", progress)
    atomic_write_text(out / "meta.json", json.dumps(meta, indent=1, allow_nan=False) + "\n")
    return out


def build_parser():
    """The command line's parser (docs/cli.md is generated from it)."""
    import argparse

    ap = argparse.ArgumentParser(prog="python -m data_gen.video", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="output folder")
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--size", default="1280x720", help="WIDTHxHEIGHT (default: %(default)s)")
    ap.add_argument("--lens", default="mild", choices=LENSES)
    ap.add_argument("--pattern", default="9x6", help="inner corners COLSxROWS (default: %(default)s)")
    ap.add_argument("--square", type=float, default=25.0, help="square size, board units (default: %(default)s)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--shutter", type=float, default=1.0 / 60.0, help="exposure, s (default: 1/60)")
    ap.add_argument("--rolling-shutter", type=float, default=0.0, help="frame readout time, s (default: 0, global)")
    ap.add_argument("--noise", type=float, default=2.0, help="read noise σ, grey levels (default: %(default)s)")
    ap.add_argument("--format", default="avi", choices=("avi", "mp4"))
    ap.add_argument("--y4m", action="store_true", help="also write video.y4m (YUV4MPEG2)")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--pace", type=float, default=1.0, help="hand speed factor (default: %(default)s)")
    ap.add_argument("--rig-baseline", type=float, default=0.0,
                    help="render a stereo pair this many board units apart (default: one camera)")
    ap.add_argument("--board", help=BOARD_HELP.replace("instead of chessboards", "to film instead"))
    ap.add_argument("--quiet", action="store_true")
    return ap


def main(argv: list[str] | None = None) -> int:
    """CLI entry: 0 on success, 2 on bad arguments (one line on stderr)."""
    args = build_parser().parse_args(argv)
    try:
        size = tuple(int(v) for v in args.size.lower().split("x"))
        if len(size) != 2 or min(size) < 32 or size[0] % 2 or size[1] % 2:
            raise ValueError(f"--size must be WIDTHxHEIGHT, even, at least 32x32, got {args.size!r}")
        cfg = VideoConfig(out=args.out, seconds=args.seconds, fps=args.fps, size=size, lens=args.lens,
                          pattern=check_pattern(parse_pattern(args.pattern)), square=args.square, seed=args.seed,
                          shutter=args.shutter, rolling_shutter=args.rolling_shutter, noise=args.noise,
                          format=args.format, y4m=args.y4m, workers=args.workers, pace=args.pace,
                          rig_baseline=args.rig_baseline, board=args.board)
        out = write_video(cfg, progress=not args.quiet)
    except (ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    names = ("video_cam0", "video_cam1") if cfg.rig_baseline > 0 else ("video",)
    print(f"wrote {out}: " + ", ".join(f"{n}.{cfg.format}" for n in names) + ", labels, meta.json"
          + (", y4m" if cfg.y4m else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
