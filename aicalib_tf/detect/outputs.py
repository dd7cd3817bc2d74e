"""What ``python -m aicalib_tf.detect`` writes per image, and the work of one image in a batch.

``<stem>.png`` (the corners drawn over the image) and ``<stem>.json`` (corners (x, y) px, their
(col, row) ids, scores, whether the board is complete, why not, the model and its sha256).
"""

from __future__ import annotations

from pathlib import Path

import cv2

from aicalib_tf.detect.draw import draw_detection
from aicalib_tf.detect.pipeline import detect_corners
from aicalib_tf.io import load_image

__all__ = ["output_stems", "write_detection", "file_detector"]


def output_stems(files: list) -> list[str]:
    """Output names, in order: each file's stem, ``<stem>-<k>`` where an earlier file had it (a/x.jpg, b/x.png)."""
    used, out = set(), []
    for f in files:
        stem = Path(f).stem
        if stem in used:
            stem = f"{stem}-{len(used)}"
        used.add(stem)
        out.append(stem)
    return out


def write_detection(out: Path, f, stem: str, gray, det, pattern, *, model: str, sha) -> None:
    """Write ``<stem>.png`` (the overlay) and ``<stem>.json`` (the corners, ids, scores, why not) of one
    image into ``out``, atomically. gray : (H, W) float32 [0, 1]; det : its Detection."""
    from aicalib_tf.io import atomic_write_bytes, atomic_write_text
    from aicalib_tf.jsonio import dumps

    ok, png = cv2.imencode(".png", draw_detection(gray, det))
    atomic_write_bytes(out / f"{stem}.png", png.tobytes())
    record = {
        "file": str(f), "image_size": list(det.image_size), "pattern_size": list(getattr(pattern, "pattern_size", pattern)),
        "found": det.found, "complete": det.complete, "reason": det.reason, "corners": det.corners.tolist(),
        "ids": det.ids.tolist(), "scores": det.scores.tolist(), "model": model, "model_sha256": sha,
    }
    if hasattr(pattern, "describe"):  # a ChArUco board
        record["board"] = pattern.describe()
    atomic_write_text(out / f"{stem}.json", dumps(record) + "\n")


def file_detector(pattern, model_name: str, out, sha):
    """The work of one image, ``(file, stem) -> (kind, reason or error)``, with the model loaded once
    (the setup of :func:`aicalib_tf.detect.batch.map_images`). kind: complete, partial, none or failed."""
    from aicalib_tf.cnn.model import load_model
    from aicalib_tf.io import ImageError

    model = load_model(model_name)

    def work(item):
        f, stem = item
        try:
            gray = load_image(f)
        except ImageError as exc:
            return "failed", str(exc)
        if hasattr(pattern, "tag_ids"):  # an AprilGrid: OpenCV decodes its tags, no network
            from aicalib_tf.detect.boards.aprilgrid import detect_corners_aprilgrid

            det = detect_corners_aprilgrid(gray, pattern)
        else:
            det = detect_corners(gray, pattern, model=model)
        write_detection(out, f, stem, gray, det, pattern, model=model_name, sha=sha)
        return ("complete" if det.complete else "partial" if det.found else "none"), det.reason
    return work
