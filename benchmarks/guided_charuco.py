"""A ChArUco board against a chessboard in the guided video path, on the same hand-held path.

    python benchmarks/guided_charuco.py --out /tmp/guided_charuco [--seeds 0 1] [--seconds 8] [--fps 15]
        [--size 1280x720] [--pace 2] [--lens mild]

Per seed, ``python -m data_gen.video`` renders two videos of the same camera, background and hand
path: one of a 9x6 chessboard of 25 mm squares, one of a ChArUco board with the same inner corners
(``charuco:10x7,square=25mm,marker=18mm,dict=DICT_4X4_50``: the paper, its margin and so the path
are the same). Each goes through ``python -m aicalib_tf.calibrate video.avi`` (the guided loop,
``--model auto``); the result is compared with the render's truth: fx error (%), principal point
error (px, the distance from the true (cx, cy)), the views kept, how many of the final views show a
partial board, and the command's wall time.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

CHESS = ("--pattern", "9x6", "--square", "25mm")
CHARUCO = "charuco:10x7,square=25mm,marker=18mm,dict=DICT_4X4_50"


def _render(out: Path, seed: int, args, board: str | None) -> Path:
    from data_gen.video import VideoConfig, write_video

    if not (out / "labels.jsonl").is_file():
        size = tuple(int(v) for v in args.size.split("x"))
        write_video(VideoConfig(out=str(out), seconds=args.seconds, fps=args.fps, size=size, lens=args.lens,
                                pattern=(9, 6), square=25.0, seed=seed, shutter=0.004, pace=args.pace, board=board),
                    progress=False)
    return out


def _calibrate(video: Path, board_args, out: Path) -> dict:
    t0 = time.monotonic()
    run = subprocess.run([sys.executable, "-m", "aicalib_tf.calibrate", str(video / "video.avi"), *board_args,
                          "--out", str(out), "--quiet"], capture_output=True, text=True)
    wall = time.monotonic() - t0
    truth = json.loads((video / "labels.jsonl").read_text().splitlines()[0])
    if run.returncode != 0:
        return {"error": (run.stderr.strip().splitlines() or ["?"])[-1], "wall": wall}
    cam = json.loads((out / "camera.json").read_text())
    K = np.asarray(cam["camera_matrix"]["data"] if isinstance(cam["camera_matrix"], dict)
                   else cam["camera_matrix"], float).reshape(3, 3)
    Kt = np.asarray(truth["K"], float)
    n_full = int(np.prod(truth["pattern_size"]))
    views = cam.get("views", [])
    partial = sum(1 for v in views if int(v["corners"]) < n_full) if views else None
    return {"fx_pct": 100 * (K[0, 0] / Kt[0, 0] - 1), "pp_px": float(np.hypot(K[0, 2] - Kt[0, 2], K[1, 2] - Kt[1, 2])),
            "kept": len(cam["meta"]["kept_frames"]), "used": len(cam["meta"].get("used_frames", [])),
            "partial": partial, "model": cam.get("distortion_model", cam.get("model")), "wall": wall}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--fps", type=float, default=15.0)
    ap.add_argument("--size", default="1280x720")
    ap.add_argument("--pace", type=float, default=2.0)
    ap.add_argument("--lens", default="mild")
    args = ap.parse_args(argv)
    root = Path(args.out)
    print(f"{'seed':>4} {'board':<9} {'fx err %':>9} {'pp err px':>10} {'kept':>5} {'used':>5} {'partial':>8} "
          f"{'model':<20} {'wall s':>7}")
    for seed in args.seeds:
        for name, board, board_args in (("chess", None, CHESS), ("charuco", CHARUCO, ("--board", CHARUCO))):
            video = _render(root / f"{name}_{seed}", seed, args, board)
            r = _calibrate(video, board_args, root / f"{name}_{seed}" / "calib")
            if "error" in r:
                print(f"{seed:>4} {name:<9} failed: {r['error']}")
                continue
            print(f"{seed:>4} {name:<9} {r['fx_pct']:>+9.3f} {r['pp_px']:>10.2f} {r['kept']:>5} {r['used']:>5} "
                  f"{str(r['partial']):>8} {str(r['model']):<20} {r['wall']:>7.1f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
