"""How OpenCV's corners differ from the detector's on real photos, and how much of it a calibration absorbs.

    python benchmarks/classic_offset.py [--sets ocam_fisheye opencv_left ...]

For each real set (as ``benchmarks/real_repeatability.py`` reads it) every photo goes through the calibrate
command's detector (CNN corners, saddle fit, board polish), and OpenCV's ``cornerSubPix`` (11×11, as its
classic corners) starts from each detected corner. Per board the difference (cornerSubPix less ours) is
fitted by a degree-2 polynomial in the corners' ids (:func:`aicalib_tf.detect.corners.refine.polish_board`'s
field: the smooth part); over all boards that smooth part is then fitted by a constant shift plus a radial
term s·ρ·û (û the unit vector from the centre, ρ the distance over R: the image circle's centre and radius,
else the frame's centre and half-diagonal). The shift is a principal point's and the radial term a focal
length's change, so a calibration takes both; what it cannot take is what is left. Printed per set: the
median per-board RMS of the smooth part, the shift (px), s (px at ρ 1) and the RMS before and after.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import real_repeatability as rr  # noqa: E402

from aicalib_tf.detect.corners.refine import board_basis, refine_subpix  # noqa: E402


def smooth_part(diff: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """(N, 2) the least-squares polynomial in the ids (N, 2) of one board's diff (N, 2): the board polish's field
    (:func:`aicalib_tf.detect.corners.refine.board_basis`)."""
    basis = board_basis(ids.astype(np.float64))
    coef, *_ = np.linalg.lstsq(basis, diff, rcond=None)
    return basis @ coef


def boards(folder: Path, pattern) -> tuple[list[tuple[np.ndarray, np.ndarray, np.ndarray]], tuple[float, float, float]]:
    """Each detected board's (corners (N, 2), ids (N, 2), cornerSubPix less corners (N, 2)) and (cx, cy, R) px."""
    from aicalib_tf.calib.workflow import make_detector
    from aicalib_tf.cnn.spec import DETECTOR_NETWORK
    from aicalib_tf.geometry.image_circle import find_image_circle, thumbnail
    from aicalib_tf.io import load_image

    files, size, _ = rr.photos(folder)
    detect = make_detector("cnn", tuple(pattern), DETECTOR_NETWORK)
    out, thumbs = [], []
    for f in files:
        gray = load_image(str(f))
        thumbs.append(np.clip(thumbnail(gray), 0.0, 1.0))
        hit = detect(gray)
        if hit is not None:
            pts = np.asarray(hit[0], np.float64)
            csp = refine_subpix(cv2.imread(str(f), cv2.IMREAD_GRAYSCALE).astype(np.float32), pts, half_window=5)[0]
            out.append((pts, np.asarray(hit[1]), csp - pts))
    circle = find_image_circle(np.mean(thumbs, axis=0), size)[0]
    if circle is not None:
        return out, (circle.cx, circle.cy, circle.radius)
    return out, ((size[0] - 1) / 2, (size[1] - 1) / 2, 0.5 * float(np.hypot(*size)))


def decompose(found, centre) -> dict:
    """The smooth parts' median per-board RMS, the pooled shift + radial fit and the RMS it leaves (px)."""
    cx, cy, radius = centre
    smooth = [smooth_part(d, ids) for _, ids, d in found]
    f = np.concatenate(smooth)
    o = np.concatenate([p for p, _, _ in found]) - [cx, cy]
    radial = o / radius  # ρ·û
    x = np.zeros((2 * len(f), 3))
    x[: len(f), 0], x[len(f):, 1] = 1.0, 1.0
    x[:, 2] = np.concatenate([radial[:, 0], radial[:, 1]])
    y = np.concatenate([f[:, 0], f[:, 1]])
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    left = y - x @ coef
    return {"board_rms": float(np.median([np.sqrt(np.mean(np.sum(s * s, axis=1))) for s in smooth])),
            "shift": coef[:2], "scale": float(coef[2]), "rms": float(np.sqrt(2 * np.mean(y * y))),
            "left": float(np.sqrt(2 * np.mean(left * left))), "boards": len(found)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sets", nargs="+", default=list(rr.SETS), choices=list(rr.SETS))
    ap.add_argument("--data", default=str(rr.SHARED))
    args = ap.parse_args(argv)
    print("| set | boards | smooth RMS a board | shift px | s (px at ρ 1) | RMS | left |\n|---|---|---|---|---|---|---|")
    for name, folder in rr.find_sets(args.sets, Path(args.data)):
        found, centre = boards(folder, rr.SETS[name][0])
        r = decompose(found, centre)
        print(f"| {name} | {r['boards']} | {r['board_rms']:.3f} | ({r['shift'][0]:+.3f}, {r['shift'][1]:+.3f}) | "
              f"{r['scale']:+.3f} | {r['rms']:.3f} | {r['left']:.3f} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
