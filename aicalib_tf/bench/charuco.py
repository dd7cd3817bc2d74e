"""ChArUco boards in the benchmark: conditions, OpenCV's CharucoDetector beside the CNN, scoring.

Conditions are the chessboard benchmark's (:mod:`aicalib_tf.bench.conditions`) with the board
replaced by a ChArUco board: clean, noise σ 40, blur σ 3, low light (exposure ×0.2 with shot and
read noise), a strong barrel lens, objects in front, the board partly out of frame. A detector is
``f(uint8 (H, W)) -> (corners (N, 2) px, ids (N,) int OpenCV ChArUco ids)``; a corner is correct
when its id's true corner is within :data:`~aicalib_tf.bench.metrics.WRONG_PX` px, else a wrong id.
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from aicalib_tf.bench.conditions import Condition
from aicalib_tf.bench.metrics import WRONG_PX
from aicalib_tf.geometry.charuco import CharucoBoard, parse_board
from data_gen.pose import PoseConfig
from data_gen.presets import Rule, get_preset

__all__ = ["BOARD", "charuco_conditions", "opencv_charuco", "cnn_charuco", "score_charuco", "CHARUCO_DETECTORS",
           "detection_table", "detection_markdown"]

BOARD = "charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100"
CHARUCO_DETECTORS = ("cnn", "opencv", "opencv-refined")
_OPTICS = Rule.of("gaussian_blur", sigma=0.6)  # as the chessboard conditions
_READ_NOISE = Rule.of("gaussian_noise", sigma=2.0)


def charuco_conditions(board: str = BOARD) -> list[Condition]:
    """The ChArUco conditions at 640×480 (seed 41), the board given by its description."""
    parse_board(board)
    clean = replace(get_preset("clean"), board=board)

    def with_rules(name, rules, **kw):
        return replace(clean, name=name, rules=rules, **kw)
    return [
        Condition("clean", clean, seed=41, description="sharp, well lit, lens blur σ 0.6 px"),
        Condition("noise40", with_rules("noise40", (_OPTICS, Rule.of("gaussian_noise", sigma=40.0))), seed=41,
                  description="Gaussian noise σ 40 grey levels"),
        Condition("blur2", with_rules("blur2", (Rule.of("gaussian_blur", sigma=2.0), _READ_NOISE)), seed=41,
                  description="Gaussian blur σ 2 px (the markers' bits still legible)"),
        Condition("blur3", with_rules("blur3", (Rule.of("gaussian_blur", sigma=3.0), _READ_NOISE)), seed=41,
                  description="Gaussian blur σ 3 px"),
        Condition("lowlight", with_rules("lowlight", (Rule.of("exposure", gain=0.2), _OPTICS,
                                                      Rule.of("shot_noise", photons=150.0), Rule.of("gaussian_noise", sigma=4.0))),
                  seed=41, description="low light: exposure ×0.2, shot noise (150 photons at white), read noise σ 4"),
        Condition("barrel", with_rules("barrel", (_OPTICS, _READ_NOISE), hfov_deg=(90.0, 120.0), distortion=("strong",)),
                  seed=41, description="wide lens (HFOV 90–120°), strong barrel"),
        Condition("occluded", replace(get_preset("occluded"), board=board), seed=41,
                  description="objects hide 8–30 % of the board"),
        Condition("partial", replace(get_preset("partial"), board=board,
                                     pose=PoseConfig(tilt_max_deg=45.0, fill=(0.5, 1.0), framing="partial")),
                  seed=41, description="board partly out of frame"),
    ]


def opencv_charuco(board: CharucoBoard, refined: bool = False):
    """``cv2.aruco.CharucoDetector`` as a detector. refined: sub-pixel marker corners, marker
    refinement against the board, more adaptive-threshold windows and smaller markers allowed;
    default parameters otherwise."""
    cb = board.to_opencv()
    det_params = cv2.aruco.DetectorParameters()
    ch_params = cv2.aruco.CharucoParameters()
    if refined:
        det_params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
        det_params.adaptiveThreshWinSizeMax = 53
        det_params.minMarkerPerimeterRate = 0.01
        det_params.polygonalApproxAccuracyRate = 0.05
        ch_params.tryRefineMarkers = True
    cd = cv2.aruco.CharucoDetector(cb, ch_params, det_params, cv2.aruco.RefineParameters())

    def f(img):
        corners, ids, _, _ = cd.detectBoard(img)
        if ids is None or len(ids) == 0:
            return np.zeros((0, 2)), np.zeros(0, np.int64)
        return np.asarray(corners, np.float64).reshape(-1, 2), np.asarray(ids, np.int64).ravel()
    return f


def cnn_charuco(board: CharucoBoard, model):
    """The CNN pipeline's ChArUco detector (:func:`aicalib_tf.detect.pipeline.detect_charuco`): the
    largest board found whose ids no other board in the image shares."""
    from aicalib_tf.detect.pipeline import detect_charuco

    def f(img):
        found = [d for d in detect_charuco(img, [board], model=model) if not d.duplicate]
        if not found:
            return np.zeros((0, 2)), np.zeros(0, np.int64)
        return found[0].corners.astype(np.float64), found[0].charuco_ids
    return f


def score_charuco(corners: np.ndarray, ids: np.ndarray, truth: np.ndarray, visible: np.ndarray) -> dict:
    """One image: found, correct, wrong ids, visible, and the correct corners' errors (px)."""
    corners = np.asarray(corners, np.float64).reshape(-1, 2)
    ids = np.asarray(ids, np.int64).ravel()
    ok_id = (ids >= 0) & (ids < len(truth))
    err = np.full(len(ids), np.inf)
    err[ok_id] = np.linalg.norm(corners[ok_id] - truth[ids[ok_id]], axis=1)
    good = err <= WRONG_PX
    return {"found": int(len(ids)), "correct": int(good.sum()), "wrong": int((~good).sum()),
            "visible": int(np.asarray(visible, bool).sum()), "errors": err[good]}


def detection_table(board_text: str, n_images: int, model, conditions=None) -> list[dict]:
    """One row per (condition, detector of :data:`CHARUCO_DETECTORS`), the first ``n_images`` images
    of each condition (``conditions``: names, default all), the detectors on the same images in
    one process: correct corners, wrong ids, visible corners, the share named, the median error
    of the correct ones (px) and the median time per image (ms)."""
    import time

    from data_gen.sample import make_sample

    board = parse_board(board_text)
    dets = {"cnn": cnn_charuco(board, model), "opencv": opencv_charuco(board),
            "opencv-refined": opencv_charuco(board, refined=True)}
    rows = []
    for cond in charuco_conditions(board_text):
        if conditions is not None and cond.name not in conditions:
            continue
        acc = {k: {"correct": 0, "wrong": 0, "visible": 0, "errors": [], "times": []} for k in dets}
        for i in range(n_images):
            s = make_sample(cond.preset, cond.seed, i, size=cond.size)
            for name, f in dets.items():
                t = time.perf_counter()
                corners, ids = f(s.image)
                acc[name]["times"].append(time.perf_counter() - t)
                sc = score_charuco(corners, ids, s.corners, s.visible)
                for key in ("correct", "wrong", "visible"):
                    acc[name][key] += sc[key]
                acc[name]["errors"].append(sc["errors"])
        for name, a in acc.items():
            e = np.concatenate(a["errors"]) if a["errors"] else np.zeros(0)
            rows.append({"condition": cond.name, "detector": name, "correct": a["correct"], "wrong": a["wrong"],
                         "visible": a["visible"], "named": a["correct"] / max(a["visible"], 1),
                         "err_median": float(np.median(e)) if e.size else float("nan"),
                         "ms": 1000 * float(np.median(a["times"])) if a["times"] else float("nan")})
    return rows


def detection_markdown(rows: list[dict]) -> str:
    """:func:`detection_table`'s rows as a Markdown table."""
    lines = ["| condition | detector | correct corners | named of visible | wrong ids | median error (px) | median ms |",
             "|---|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['condition']} | {r['detector']} | {r['correct']} | {100 * r['named']:.1f} % | {r['wrong']} | "
                     f"{r['err_median']:.3f} | {r['ms']:.0f} |")
    return "\n".join(lines)
