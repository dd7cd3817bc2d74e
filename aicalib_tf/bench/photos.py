"""The benchmark on a user's real photos, without ground truth (``evaluate --images DIR``).

Per photo and detector: whether a full (or partial) board was found and how long it took.
Between detectors: how far apart their full boards are on the same photo (after the board's
symmetries). Per detector: the calibration its boards give (aicalib_tf.calib.workflow).

``--degrade`` applies seeded degradations to every photo (:data:`PHOTO_DEGRADATIONS`) and
scores each detector against a reference board found on the clean photo. The reference rule
(:func:`consensus_reference`): the largest group of detectors whose full boards agree pairwise
within 1 px (max over corners) gives the mean of their boards. Detectors sharing one corner
localiser (cnn and report: the same saddle refinement) count as one vote, in the group size and
in the mean, so the reference does not lean towards the CNN. When only one detector (family)
finds a full board, its board is the reference ("single"); of two equally large groups the
tighter one (smaller worst pairwise distance) wins; when several find boards but no two agree, the photo has
no reference and is left out of the degradation scores (counted). A degraded photo's full board is a hit when every corner is within 2 px of
the reference; its deviation is the per-corner distance to it.
"""

from __future__ import annotations

from collections import Counter
from itertools import combinations
from pathlib import Path

import numpy as np

from aicalib_tf.bench.metrics import (
    WRONG_PX,
    align_to_truth,
    board_detection_outcome,
    detection_agreement,
    partial_board_stats,
)
from aicalib_tf.io import ImageError, load_image
from data_gen import degrade as dg

__all__ = ["PHOTO_DEGRADATIONS", "IMAGE_EXTENSIONS", "list_images", "degrade_photo", "consensus_reference",
           "run_photos"]

IMAGE_EXTENSIONS = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp", ".pgm", ".ppm")
AGREE_PX = 1.0


def _low_light(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Under-exposed ×0.25 with photon (1000 at white) and read (σ 2) noise, 8-bit ADC, then gain ×4."""
    dark = dg.gaussian_noise(dg.shot_noise(dg.exposure(img, rng, gain=0.25), rng, photons=1000.0), rng, sigma=2.0)
    return dg.quantize(dg.quantize(dark).astype(np.float32) / 255.0 * 4.0)


def _steps(*steps):
    return lambda img, rng: dg.apply_degradations(img, list(steps), rng)


# name -> (description, f(float32 gray [0, 1], rng) -> uint8)
PHOTO_DEGRADATIONS = {
    "clean": ("the photo as it is", _steps()),
    "noise20": ("Gaussian noise σ 20", _steps({"name": "gaussian_noise", "sigma": 20.0})),
    "noise40": ("Gaussian noise σ 40", _steps({"name": "gaussian_noise", "sigma": 40.0})),
    "blur2.5": ("Gaussian blur σ 2.5 px", _steps({"name": "gaussian_blur", "sigma": 2.5})),
    "jpeg8": ("JPEG quality 8", _steps({"name": "jpeg", "quality": 8})),
    "lowlight": ("under-exposed ×0.25, shot + read noise, 8-bit, gain ×4", _low_light),
    "shading": ("illumination gradient 70 % and a shadow 60 %",
                _steps({"name": "illumination_gradient", "strength": 0.7},
                       {"name": "shadow", "strength": 0.6, "softness": 2.0})),
    "saltpepper3": ("3 % salt-and-pepper", _steps({"name": "salt_pepper", "fraction": 0.03})),
}


def list_images(folder: Path) -> list[Path]:
    """Image files directly in ``folder`` (by extension), sorted; ValueError if there are none."""
    files = sorted(p for p in Path(folder).iterdir() if p.is_file() and p.suffix.lower() in IMAGE_EXTENSIONS)
    if not files:
        raise ValueError(f"{folder}: no images ({', '.join(IMAGE_EXTENSIONS)})")
    return files


def degrade_photo(gray: np.ndarray, name: str, rng: np.random.Generator) -> np.ndarray:
    """Apply degradation ``name`` of :data:`PHOTO_DEGRADATIONS` to (H, W) float32 [0, 1]; returns uint8."""
    if name not in PHOTO_DEGRADATIONS:
        raise ValueError(f"unknown degradation {name!r}; choose from {', '.join(PHOTO_DEGRADATIONS)}")
    return PHOTO_DEGRADATIONS[name][1](np.asarray(gray, np.float32), rng)


FAMILIES = {"report": "cnn"}  # the report model feeds the same saddle refinement: one localiser, one vote


def consensus_reference(boards: dict, pattern: tuple[int, int], agree_px: float = AGREE_PX,
                        families: dict | None = None):
    """The reference board of a clean photo from the detectors' full boards (module docstring rule).

    boards : {detector: (cols·rows, 2) px} full boards only.
    families : {detector: family}; detectors of one family (default: cnn and report, which share
        the CNN pipeline's corner refinement) count as one vote in the group size and the mean.
    Returns (reference (cols·rows, 2) px or None, rule: "consensus" | "single" | "disagree" | "none",
    members: the detectors it came from).
    """
    fam = {d: (FAMILIES if families is None else families).get(d, d) for d in boards}
    names = list(boards)
    if not names:
        return None, "none", []
    if len(set(fam.values())) == 1:  # one localiser: its boards must agree among themselves
        ref = np.asarray(boards[names[0]], np.float64)
        if any(detection_agreement(ref, boards[m], pattern)["max_px"] > agree_px for m in names[1:]):
            return None, "disagree", []
        return np.mean([align_to_truth(boards[m], ref, pattern) for m in names], axis=0), "single", names
    dist = {}
    for a, b in combinations(names, 2):
        dist[a, b] = dist[b, a] = detection_agreement(boards[a], boards[b], pattern)["max_px"]
    # the group agreeing pairwise with the most families; among equal ones the tightest (smallest worst pair)
    best = None
    for k in range(len(names), 1, -1):
        for group in combinations(names, k):
            n_fam = len({fam[g] for g in group})
            spread = max(dist[a, b] for a, b in combinations(group, 2))
            if n_fam >= 2 and spread <= agree_px and (best is None or (n_fam, -spread) > (best[0], -best[1])):
                best = (n_fam, spread, group)
    if best is None:
        return None, "disagree", []
    members = list(best[2])
    ref = np.asarray(boards[members[0]], np.float64)
    per_family: dict[str, list] = {}
    for m in members:
        per_family.setdefault(fam[m], []).append(align_to_truth(boards[m], ref, pattern))
    ref = np.mean([np.mean(v, axis=0) for v in per_family.values()], axis=0)
    return ref, "consensus", members


def run_photos(folder: Path, pattern: tuple[int, int], detectors: dict, *, degrade: bool = False, seed: int = 0,
               progress: bool = True) -> dict:
    """Run every detector on every photo (and, with ``degrade``, on its degraded copies).

    detectors : {name: f(uint8 image) -> Found} (see aicalib_tf.bench.runner.make_detectors).
    Returns {"rows": per photo × degradation × detector dicts, "agreement": per photo × pair,
    "calibration": per detector, "references": per photo, "skipped": {file: reason},
    "examples": [(file, uint8 image, {detector: (Found, outcome)})]}.
    """


    # size: one loop over photos x variants x detectors that fills three tables; the steps share its state.
    from tqdm import tqdm

    from aicalib_tf.bench.timing import time_detector
    from aicalib_tf.calib.workflow import CalibrationError, View, calibrate_camera

    files = list_images(folder)
    variants = list(PHOTO_DEGRADATIONS) if degrade else ["clean"]
    rows, agreement, references, skipped, examples = [], [], [], {}, []
    views = {d: [] for d in detectors}
    sizes = {}
    first = True
    bar = tqdm(total=len(files) * len(variants), desc="photos", unit="img", disable=not progress)
    for fi, f in enumerate(files):
        try:
            gray = load_image(f)
        except ImageError as exc:
            skipped[f.name] = str(exc)
            bar.update(len(variants))
            continue
        sizes[f.name] = (gray.shape[1], gray.shape[0])
        ref = None
        for vi, var in enumerate(variants):
            img = dg.quantize(gray) if var == "clean" else degrade_photo(gray, var, np.random.default_rng([seed, fi, vi]))
            if first:  # warm up on the first photo, untimed (twice: a size's own graph is traced on its second use)
                for fn in list(detectors.values()) * 2:
                    fn(img)
                first = False
            found_by = {d: time_detector(fn, img) for d, fn in detectors.items()}
            if var == "clean":
                boards = {d: fo.corners for d, (fo, _) in found_by.items() if fo.complete}
                ref, rule, members = consensus_reference(boards, pattern)
                references.append({"file": f.name, "rule": rule, "members": "+".join(members),
                                   "full_boards": "+".join(boards)})
                for a, b in combinations(list(detectors), 2):
                    rec = {"file": f.name, "pair": f"{a} vs {b}", "both_found": a in boards and b in boards}
                    if rec["both_found"]:
                        rec.update(detection_agreement(boards[a], boards[b], pattern))
                    agreement.append(rec)
                for d, (fo, _) in found_by.items():
                    if len(fo.corners):
                        views[d].append(View(f.name, fo.corners, fo.ids, sigmas=fo.sigmas))
            outcomes = {}
            for d, (fo, ms) in found_by.items():
                row = {"file": f.name, "width": gray.shape[1], "height": gray.shape[0], "degradation": var,
                       "detector": d, "found": len(fo.corners) > 0,
                       "complete": bool(fo.complete), "n_corners": len(fo.corners), "time_ms": ms,
                       "reference": ref is not None, "outcome": "", "dev_median_px": np.nan, "dev_max_px": np.nan,
                       "recall": np.nan}
                if ref is not None:
                    if fo.complete:
                        outcome, e = board_detection_outcome(fo.corners, ref, pattern, WRONG_PX)
                        row.update(outcome=outcome, dev_median_px=float(np.median(e)), dev_max_px=float(e.max()))
                    elif len(fo.corners):
                        st = partial_board_stats(fo.corners, fo.ids, ref, np.ones(len(ref), bool), pattern, WRONG_PX)
                        row.update(outcome="partial", recall=st["recall"],
                                   dev_median_px=float(np.median(st["errors"])) if st["correct"] else np.nan)
                    else:
                        row["outcome"] = "miss"
                    if row["outcome"] in ("hit", "partial") and fo.complete:
                        row["recall"] = 1.0
                outcomes[d] = (fo, row["outcome"] or ("full" if fo.complete else "partial" if len(fo.corners) else "none"))
                rows.append(row)
            if var != "clean" and ref is not None:
                bad = sum(o not in ("hit",) for _, o in outcomes.values())
                examples.append((bad, f"{f.name} {var}", img, ref, outcomes))
            bar.update(1)
    bar.close()
    calibration = []
    if sizes:
        size, _ = Counter(sizes.values()).most_common(1)[0]
        odd = {n for n, s in sizes.items() if s != size}
        for d, vs in views.items():
            vs = [v for v in vs if v.name not in odd]
            rec = {"detector": d, "images": len(sizes), "views": len(vs), "other_size": len(odd)}
            try:
                cal = calibrate_camera(vs, pattern, 1.0, size)
            except CalibrationError as exc:
                rec.update(status=f"failed: {exc}")
            else:
                rec.update(views_used=len(cal.views), rejected=len(cal.rejected), rms_px=float(cal.rms),
                           fx=cal.fx, fy=cal.fy, cx=cal.cx, cy=cal.cy,
                           **{k: float(v) for k, v in zip(("k1", "k2", "p1", "p2", "k3"), cal.dist)}, status="ok")
            calibration.append(rec)
    examples.sort(key=lambda e: -e[0])
    return {"rows": rows, "agreement": agreement, "calibration": calibration, "references": references,
            "skipped": skipped, "examples": [e[1:] for e in examples[:4] if e[0] > 0], "files": len(files)}
