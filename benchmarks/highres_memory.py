"""Peak memory and time of detection on 12, 24 and 48 MP photos, beside OpenCV classic in the same run.

    python benchmarks/highres_memory.py [--sizes 12,24,48] [--kinds chessboard,charuco] [--limit-gb 4]

Images: a sharp data_gen ``clean`` 9x6 chessboard (rendered at 2000×1500) and a ChArUco board
(``charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100``, its OpenCV layout warped onto a
2000×1500 frame, 4×4 supersampled), each resized bicubically to 4000×3000 (12 MP), 5656×4242
(24 MP) and 8000×6000 (48 MP), and to a quarter of each (half the width and height) for the
comparison of detections. The truth moves with the resize: x' = (x + 0.5)·k − 0.5.

Each detection runs in a child process of its own (``python benchmarks/highres_memory.py --one``)
under ``RLIMIT_AS`` (``--limit-gb``): the image is read from a PNG, the detector warmed on a small
image (model loaded, kernels compiled), then timed once. Reported per image and detector: corners
found, their RMS distance to the truth (px of the image), the detection's time and the child's
peak RSS (``ru_maxrss``: imports, model and image included). Detectors: ``detect_corners`` with
the pattern (chessboard) or the board (ChArUco), and OpenCV classic: ``cv2.findChessboardCorners``
+ ``cornerSubPix`` (11×11 window), or ``cv2.aruco.CharucoDetector.detectBoard``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

BOARD = "charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100"
BASE = (2000, 1500)
SIZES = {12: (4000, 3000), 24: (5656, 4242), 48: (8000, 6000)}


def _charuco_base():
    """(image (1500, 2000) uint8, truth (70, 2) px): the ChArUco board warped onto the frame."""
    import cv2

    from aicalib_tf.geometry.charuco import layout_image, parse_board

    board = parse_board(BOARD)
    sq, margin, s = 60, 40, 4
    flat = layout_image(board, sq, margin)
    h0, w0 = flat.shape[:2]
    src = np.float32([[0, 0], [w0, 0], [w0, h0], [0, h0]])
    dst = np.float32([[420, 260], [1620, 330], [1560, 1230], [380, 1150]])
    m = cv2.getPerspectiveTransform(src, dst)
    big = cv2.warpPerspective(flat, np.diag([s, s, 1.0]) @ m, (BASE[0] * s, BASE[1] * s), flags=cv2.INTER_LINEAR,
                              borderValue=150)
    img = cv2.resize(big, BASE, interpolation=cv2.INTER_AREA)
    cols, rows = board.pattern_size
    c, r = np.meshgrid(np.arange(cols), np.arange(rows))
    flat_pts = np.stack([margin + (c.ravel() + 1) * sq - 0.5, margin + (r.ravel() + 1) * sq - 0.5], 1)
    # the warp samples pixel centres; the area average of s×s samples sits (s − 1)/(2s) px on
    q = cv2.perspectiveTransform(flat_pts[None].astype(np.float64), m)[0] - (s - 1) / (2 * s)
    return img, q


def _images(folder: Path, sizes: list[int], kinds: list[str]) -> list[dict]:
    """Write the images and their truth; returns one job per (kind, size, full or quarter)."""
    import cv2

    from data_gen import make_sample

    bases = {}
    if "chessboard" in kinds:
        s = make_sample("clean", 3, 0, size=BASE, pattern=(9, 6))
        bases["chessboard"] = (s.image, np.asarray(s.corners, np.float64))
    if "charuco" in kinds:
        bases["charuco"] = _charuco_base()
    jobs = []
    for kind, (img, truth) in bases.items():
        for mp in sizes:
            w, h = SIZES[mp]
            for part, (ww, hh) in (("full", (w, h)), ("quarter", (w // 2, h // 2))):
                k = ww / BASE[0]
                path = folder / f"{kind}_{ww}x{hh}.png"
                if not path.exists():
                    cv2.imwrite(str(path), cv2.resize(img, (ww, hh), interpolation=cv2.INTER_CUBIC))
                np.save(folder / f"{kind}_{ww}x{hh}.npy", (truth + 0.5) * k - 0.5)
                jobs.append({"kind": kind, "mp": mp, "part": part, "size": (ww, hh), "path": str(path)})
    return jobs


def _detect(kind: str, detector: str, gray: np.ndarray) -> np.ndarray:
    """(N, 2) corners found by one detector."""
    import cv2

    if detector == "opencv" and kind == "chessboard":
        ok, c = cv2.findChessboardCorners(gray, (9, 6))
        if not ok:
            return np.zeros((0, 2))
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.01)
        return cv2.cornerSubPix(gray, c, (11, 11), (-1, -1), crit).reshape(-1, 2)
    if detector == "opencv":
        from aicalib_tf.geometry.charuco import parse_board

        cc, ci, _, _ = cv2.aruco.CharucoDetector(parse_board(BOARD).to_opencv()).detectBoard(gray)
        return np.zeros((0, 2)) if ci is None else cc.reshape(-1, 2)
    from aicalib_tf.detect.pipeline import detect_corners

    return detect_corners(gray, (9, 6) if kind == "chessboard" else BOARD).corners


def run_one(kind: str, detector: str, path: str) -> dict:
    """In the child: warm up, read the image, detect once; corners, time and peak RSS."""
    import cv2

    _detect(kind, detector, cv2.resize(cv2.imread(path, cv2.IMREAD_GRAYSCALE), (640, 480)))  # load the model
    gray = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    t = time.perf_counter()
    corners = _detect(kind, detector, gray)
    dt = time.perf_counter() - t
    truth = np.load(path[:-4] + ".npy")
    err = np.sqrt(((corners[:, None, :] - truth[None]) ** 2).sum(-1)).min(1) if len(corners) else np.zeros(0)
    return {"n": int(len(corners)), "rms": float(np.sqrt(np.mean(err**2))) if len(err) else None,
            "s": dt, "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def _child(job: dict, detector: str, limit: int) -> dict:
    code = f"import json, sys; sys.path.insert(0, {str(ROOT)!r}); from benchmarks.highres_memory import run_one; " \
           f"print(json.dumps(run_one({job['kind']!r}, {detector!r}, {job['path']!r})))"

    def limited():
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, preexec_fn=limited, cwd=ROOT,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["?"])[-1]
        return {"n": 0, "rms": None, "s": None, "rss_mb": None, "error": last}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="12,24,48", help="megapixels, of 12, 24, 48")
    ap.add_argument("--kinds", default="chessboard,charuco")
    ap.add_argument("--limit-gb", type=float, default=4.0, help="address-space limit of each child")
    a = ap.parse_args(argv)
    sizes, kinds = [int(v) for v in a.sizes.split(",")], a.kinds.split(",")
    limit = int(a.limit_gb * 2**30)
    print("| board | MP | image | detector | corners | RMS px | time s | × OpenCV | peak RSS MB |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    with tempfile.TemporaryDirectory() as tmp:
        for job in _images(Path(tmp), sizes, kinds):
            res = {d: _child(job, d, limit) for d in ("cnn", "opencv")}
            for d, r in res.items():
                ratio = r["s"] / res["opencv"]["s"] if d == "cnn" and r["s"] and res["opencv"]["s"] else None
                print(f"| {job['kind']} | {job['mp']} | {job['part']} {job['size'][0]}×{job['size'][1]} | {d} | {r['n']} | "
                      + (f"{r['rms']:.3f}" if r["rms"] is not None else "-") + " | "
                      + (f"{r['s']:.2f}" if r["s"] is not None else "-") + " | "
                      + (f"{ratio:.2f}" if ratio is not None else "") + " | "
                      + (f"{r['rss_mb']:.0f}" if r["rss_mb"] is not None else r.get("error", "-")) + " |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
