"""ChArUco boards: the CNN pipeline against OpenCV's CharucoDetector (default and refined parameters).

    python benchmarks/charuco.py [--images 10] [--board charuco:11x8,...] [--calib 2] [--out DIR]

For every condition of :func:`aicalib_tf.bench.charuco.charuco_conditions` (the first ``--images``
images of each) the three detectors run on the same images in one process: correct corners
(id right, within 2 px), wrong ids, the median corner error of the correct ones, the share of
visible corners named, and the median time per image. Then ``--calib`` calibration sequences
(data_gen ``calib``, 12 views each, 640×480) are rendered twice at the same poses, once with the
ChArUco board and once with a chessboard of the same squares, and calibrated from the CNN's
detections (plumb_bob): focal error (%), the mean projection error against the true lens over the
image and over the area the boards covered (px), and the corners' RMS error against their true
places (px; a chessboard corner is matched to the nearest true corner within 2 px, its ids being
the chessboard's own order), then a summary: mean and median projection error per board and the cameras where ChArUco is at least as
accurate. Prints Markdown for docs/benchmark.md.
"""

from __future__ import annotations

import argparse
import copy
import platform
import sys
import time
from datetime import date

import numpy as np

MATCH_PX = 2.0  # a detected corner within this of a true corner is that corner



def _chessboard_twin(scene):
    """The scene's image with a chessboard of the ChArUco board's squares and paper at the same pose."""
    from data_gen.board import Board
    from data_gen.degrade import apply_degradations
    from data_gen.render import render_board

    t = scene.board
    chess = Board(t.pattern_size, t.square_size, t.margin, t.black, t.white)
    img = render_board(scene.camera, chess, scene.rvec, scene.tvec, scene.background)
    return apply_degradations(img, scene.steps, copy.deepcopy(scene.degrade_rng)), chess


def _nearest_errors(corners: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(K,) px from each detected corner (N, 2) to the nearest true corner (truth (M, 2) px), for
    those within MATCH_PX (K ≤ N)."""
    d = np.linalg.norm(np.asarray(corners, np.float64)[:, None] - np.asarray(truth, np.float64)[None], axis=2).min(axis=1)
    return d[d <= MATCH_PX]


def calibration_table(board_text: str, sequences: int, model) -> list[dict]:
    """ChArUco against chessboard sequences of the same views: focal error (%) and RMS projection error (px)."""
    from aicalib_tf.bench.metrics import calibration_errors
    from aicalib_tf.calib.fit import View, calibrate_camera
    from aicalib_tf.detect.pipeline import detect_charuco, detect_corners
    from data_gen.presets import get_preset
    from data_gen.sample import draw_scene

    preset = get_preset("calib", board=board_text, views_per_camera=12, sizes=((640, 480),))
    rows = []
    for cam_id in range(sequences):
        views = {"charuco": [], "chessboard": []}
        seen = []  # every visible true corner of the sequence: the area the boards covered
        errors = {"charuco": [], "chessboard": []}
        for v in range(preset.views_per_camera):
            sc = draw_scene(preset, 7, cam_id * preset.views_per_camera + v)
            seen.append(sc.corners[sc.visible])
            found = [d for d in detect_charuco(sc.render(), [sc.board.board], model=model) if not d.duplicate]
            if found and len(found[0].corners) >= 6:
                views["charuco"].append(View(f"v{v}", found[0].corners, found[0].ids))
                truth = sc.corners[found[0].charuco_ids]
                errors["charuco"].append(np.linalg.norm(found[0].corners - truth, axis=1))
            img, chess = _chessboard_twin(sc)
            det = detect_corners(img, chess.pattern_size, model=model)
            if det.found:
                views["chessboard"].append(View(f"v{v}", det.corners, det.ids))
                errors["chessboard"].append(_nearest_errors(det.corners, sc.corners))
        cam = sc.camera
        for kind, vs in views.items():
            cal = calibrate_camera(vs, sc.board.pattern_size, sc.board.square_size, cam.image_size, model="plumb_bob")
            err = calibration_errors(cal.K, cal.dist, cam.K, cam.dist, cam.image_size, model="plumb_bob",
                                     model_true=cam.model, seen=np.concatenate(seen))
            rows.append({"camera": cam_id, "board": kind, "views": len(cal.views), "corners": int(sum(cal.corner_counts)),
                         "fx_pct": err["fx_pct"], "proj_px": err["proj_err_mean_px"],
                         "seen_px": err["proj_err_seen_mean_px"], "rms": cal.rms,
                         "corner_rms": float(np.sqrt(np.mean(np.square(np.concatenate(errors[kind] or [[np.nan]])))))})
    return rows


def _markdown(det_rows: list[dict], cal_rows: list[dict]) -> str:
    from aicalib_tf.bench.charuco import detection_markdown

    lines = [detection_markdown(det_rows)] if det_rows else []
    if cal_rows:
        lines += ["", "| camera | board | views used | corners | focal error (%) | projection error, mean (px) | "
                  "over the boards' area (px) | RMS (px) | corner error, RMS (px) |",
                  "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
        for r in cal_rows:
            lines.append(f"| {r['camera']} | {r['board']} | {r['views']} | {r['corners']} | {r['fx_pct']:+.3f} | "
                         f"{r['proj_px']:.3f} | {r['seen_px']:.3f} | {r['rms']:.3f} | {r['corner_rms']:.3f} |")
        lines += ["", calibration_summary(cal_rows)]
    return "\n".join(lines)


def calibration_summary(cal_rows: list[dict]) -> str:
    """One line: per board the mean and median projection error (px), mean |focal error| (%), corners
    per sequence; and in how many cameras ChArUco's projection error is at most the chessboard's."""
    by = {k: [r for r in cal_rows if r["board"] == k] for k in ("charuco", "chessboard")}
    parts = []
    for k, rs in by.items():
        p = np.array([r["proj_px"] for r in rs])
        seen = np.array([r["seen_px"] for r in rs])
        parts.append(f"{k}: projection error mean {p.mean():.3f} px (median {np.median(p):.3f}; over the boards' area "
                     f"{seen.mean():.3f}, median {np.median(seen):.3f}), "
                     f"|focal error| {np.mean([abs(r['fx_pct']) for r in rs]):.3f} %, "
                     f"{np.mean([r['corners'] for r in rs]):.0f} corners and {np.mean([r['views'] for r in rs]):.1f} views per sequence")
    wins = sum(a["proj_px"] <= b["proj_px"] for a, b in zip(by["charuco"], by["chessboard"]))
    wins_seen = sum(a["seen_px"] <= b["seen_px"] for a, b in zip(by["charuco"], by["chessboard"]))
    return "; ".join(parts) + (f"; ChArUco at least as accurate in {wins} of {len(by['charuco'])} cameras "
                               f"({wins_seen} over the boards' area).")


def main(argv=None) -> int:
    from aicalib_tf.bench.charuco import BOARD, detection_table
    from aicalib_tf.cnn.model import load_model

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--images", type=int, default=10, help="images per condition (default: %(default)s)")
    ap.add_argument("--board", default=BOARD)
    ap.add_argument("--calib", type=int, default=2, help="calibration sequences (default: %(default)s)")
    a = ap.parse_args(argv)
    model = load_model("default")
    t0 = time.perf_counter()
    det_rows = detection_table(a.board, a.images, model) if a.images else []
    cal_rows = calibration_table(a.board, a.calib, model) if a.calib else []
    print(f"python benchmarks/charuco.py --images {a.images} --calib {a.calib}; {date.today()}; "
          f"{platform.machine()} {platform.processor() or ''}; {time.perf_counter() - t0:.0f} s\n")
    print(_markdown(det_rows, cal_rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
