"""ChArUco boards: the CNN pipeline against OpenCV's CharucoDetector (default and refined parameters).

    python benchmarks/charuco.py [--images 10] [--board charuco:11x8,...] [--calib 2] [--out DIR]

For every condition of :func:`aicalib_tf.bench.charuco.charuco_conditions` (the first ``--images``
images of each) the three detectors run on the same images in one process: correct corners
(id right, within 2 px), wrong ids, the median corner error of the correct ones, the share of
visible corners named, and the median time per image. Then ``--calib`` calibration sequences
(data_gen ``calib``, 12 views each, 640×480) are rendered twice at the same poses, once with the
ChArUco board and once with a chessboard of the same squares, and calibrated from the CNN's
detections (plumb_bob): focal error (%) and the RMS of the projection error against the true
lens over the image (px). Prints a Markdown table for docs/benchmark.md.
"""

from __future__ import annotations

import argparse
import copy
import platform
import sys
import time
from datetime import date



def _chessboard_twin(scene):
    """The scene's image with a chessboard of the ChArUco board's squares and paper at the same pose."""
    from data_gen.board import Board
    from data_gen.degrade import apply_degradations
    from data_gen.render import render_board

    t = scene.board
    chess = Board(t.pattern_size, t.square_size, t.margin, t.black, t.white)
    img = render_board(scene.camera, chess, scene.rvec, scene.tvec, scene.background)
    return apply_degradations(img, scene.steps, copy.deepcopy(scene.degrade_rng)), chess


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
        for v in range(preset.views_per_camera):
            sc = draw_scene(preset, 7, cam_id * preset.views_per_camera + v)
            found = [d for d in detect_charuco(sc.render(), [sc.board.board], model=model) if not d.duplicate]
            if found and len(found[0].corners) >= 6:
                views["charuco"].append(View(f"v{v}", found[0].corners, found[0].ids))
            img, chess = _chessboard_twin(sc)
            det = detect_corners(img, chess.pattern_size, model=model)
            if det.found:
                views["chessboard"].append(View(f"v{v}", det.corners, det.ids))
        cam = sc.camera
        for kind, vs in views.items():
            cal = calibrate_camera(vs, sc.board.pattern_size, sc.board.square_size, cam.image_size, model="plumb_bob")
            err = calibration_errors(cal.K, cal.dist, cam.K, cam.dist, cam.image_size, model="plumb_bob",
                                     model_true=cam.model)
            rows.append({"camera": cam_id, "board": kind, "views": len(cal.views), "corners": int(sum(cal.corner_counts)),
                         "fx_pct": err["fx_pct"], "proj_px": err["proj_err_mean_px"], "rms": cal.rms})
    return rows


def _markdown(det_rows: list[dict], cal_rows: list[dict]) -> str:
    from aicalib_tf.bench.charuco import detection_markdown

    lines = [detection_markdown(det_rows), "", "| camera | board | views used | corners | focal error (%) | "
             "projection error, mean (px) | RMS (px) |", "|---|---|---:|---:|---:|---:|---:|"]
    for r in cal_rows:
        lines.append(f"| {r['camera']} | {r['board']} | {r['views']} | {r['corners']} | {r['fx_pct']:+.3f} | "
                     f"{r['proj_px']:.3f} | {r['rms']:.3f} |")
    return "\n".join(lines)


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
    det_rows = detection_table(a.board, a.images, model)
    cal_rows = calibration_table(a.board, a.calib, model) if a.calib else []
    print(f"python benchmarks/charuco.py --images {a.images} --calib {a.calib}; {date.today()}; "
          f"{platform.machine()} {platform.processor() or ''}; {time.perf_counter() - t0:.0f} s\n")
    print(_markdown(det_rows, cal_rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
