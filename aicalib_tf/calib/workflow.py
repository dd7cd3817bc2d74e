"""From photos to a saved calibration: detect every image, build views, calibrate, report, write files.

The photos' image circle (a circular fisheye's) is estimated from the mean of small copies of the
photos of the calibration's size (:func:`~aicalib_tf.geometry.image_circle.estimate_image_circle`)
and kept in the calibration.

The command line is :mod:`aicalib_tf.calibrate`; its docstring describes the outputs and exit codes.
"""

from __future__ import annotations

import re
import sys
from collections import Counter
import dataclasses
import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from aicalib_tf.cnn.spec import DETECTOR_NETWORK
from aicalib_tf.detect.registry import DETECTORS
from aicalib_tf.calib.fit import Calibration, CalibrationError, View, calibrate_camera, choose_model, fit_views
from aicalib_tf.calib.flex import FLEX_DEFAULT
from aicalib_tf.calib.quality import assess
from aicalib_tf.calib.run_options import RunOptions
from aicalib_tf.geometry.image_circle import find_image_circle, thumbnail
from aicalib_tf.geometry.lens import MODELS as LENS_MODELS

__all__ = ["View", "Calibration", "CalibrationError", "calibrate_camera", "CalibrateConfig", "parse_square", "make_detector", "run", "undistort"]

PREVIEW_NAME = "undistorted.png"  # one image of the set, undistorted
RESIZE_POLICIES = ("error", "skip", "crop", "scale")
_UNITS = {"mm": "mm", "cm": "cm", "m": "m", "in": "in", "inch": "in", "": ""}


def undistort(image, calibration: Calibration, *, alpha: float = 0.0):
    """Remove lens distortion (see :func:`aicalib_tf.calib.files.undistort`)."""
    from aicalib_tf.calib.files import undistort as _undistort

    return _undistort(image, calibration, alpha=alpha)


MAX_SQUARE = 1e5  # a square's size in its unit: 100 m in metres, beyond any printed or painted board


def parse_square(text: str) -> tuple[float, str]:
    """``"25mm"`` -> (25.0, "mm"). Units: mm, cm, m, in; a bare number is unitless."""
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*([a-zA-Z]*)\s*", str(text))
    if not m:
        raise ValueError(f"--square must be a positive size such as 25mm, 2.5cm or 0.025m, got {text!r}")
    value, unit = float(m.group(1)), m.group(2).lower()
    if unit not in _UNITS:
        raise ValueError(f"--square unit {m.group(2)!r} is not one of mm, cm, m, in (got {text!r})")
    if not 0 < value <= MAX_SQUARE:
        raise ValueError(f"--square must be positive and at most {MAX_SQUARE:g} {unit or 'units'}, got {text!r}")
    return value, _UNITS[unit]


def make_detector(name: str, pattern_size: tuple[int, int], model: str = DETECTOR_NETWORK):
    """A function (H, W) grey image (float in [0, 1] or uint8) -> (corners (N, 2), ids (N, 2)) or None.

    name : "cnn" (full or partial boards, with ``model``: default, report or a .keras path),
    "report" (the same pipeline with the report's network), "opencv" (classic + cornerSubPix) or
    "opencv-sb" (full boards only). The function's ``info`` attribute holds the model path and
    sha256 for the CNN detectors; after a call that found nothing, its ``why`` attribute says why
    where the detector tells (the CNN detectors), else "". After each call its ``relative``
    attribute says whether the ids are relative to the visible grid (the CNN detectors return a
    board larger than the frame that way), and its ``sigmas`` attribute holds the corners' σ (N,) px
    (:mod:`aicalib_tf.detect.corners.sigma`) or None (the OpenCV detectors, nothing found).
    The detectors are those of :mod:`aicalib_tf.detect.registry`.
    """
    from aicalib_tf.detect.registry import make_detectors
    from aicalib_tf.io import quantize

    if name not in DETECTORS:
        raise ValueError(f"unknown detector {name!r}; choose from {', '.join(DETECTORS)}")
    if hasattr(pattern_size, "tag_ids"):  # an AprilGrid (aicalib_tf.geometry.aprilgrid): OpenCV decodes its tags
        from aicalib_tf.detect.boards.aprilgrid import make_detector as aprilgrid_detector

        return aprilgrid_detector(pattern_size)
    if hasattr(pattern_size, "circle_ids"):  # an OpenCV circle grid (aicalib_tf.geometry.circles)
        from aicalib_tf.detect.boards.circles import make_detector as circles_detector

        return circles_detector(pattern_size)
    if hasattr(pattern_size, "marker_ids"):  # a ChArUco board (aicalib_tf.geometry.charuco)
        return _charuco_detector(name, pattern_size, model)
    detectors, info = make_detectors([name], tuple(pattern_size), model, relative=True)
    found_by = detectors[name]

    def detect(gray):
        g = np.asarray(gray)
        found = found_by(g if g.dtype == np.uint8 else quantize(g))
        detect.why, detect.relative = found.why, found.relative
        detect.sigmas = found.sigmas if len(found.corners) else None
        return (found.corners, found.ids) if len(found.corners) else None

    detect.info, detect.why, detect.relative, detect.sigmas = info.get(name, {}), "", False, None
    return detect


def _charuco_detector(name: str, board, model: str):
    """make_detector for a ChArUco board: the largest board found whose ids no other board in the
    image shares (:func:`aicalib_tf.detect.pipeline.detect_charuco`); the CNN detectors only."""
    from aicalib_tf.cnn.model import file_sha256, load_model
    from aicalib_tf.detect.pipeline import detect_charuco

    if name not in ("cnn", "report"):
        raise ValueError(f"--detector {name} reads chessboards only; ChArUco boards take cnn or report")
    net = load_model(model if name == "cnn" else "report")

    def detect(gray):
        refused = {}
        found = [d for d in detect_charuco(gray, [board], model=net, refused=refused) if not d.duplicate]
        detect.why = "" if found else refused.get(board, "no ChArUco board whose markers decide its corners "
                                                         "(or two with the same ids)")
        return (found[0].corners, found[0].ids) if found else None

    detect.info = {"model": str(net.aicalib_path), "sha256": file_sha256(net.aicalib_path), "board": board.describe()}
    detect.why, detect.relative, detect.sigmas = "", False, None
    return detect


@dataclass(frozen=True, kw_only=True)
class CalibrateConfig(RunOptions):
    """Everything one calibration run of photos needs (the CLI's options): the shared
    :class:`~aicalib_tf.calib.run_options.RunOptions` and the photos' own."""

    images: tuple[str, ...]
    fix_k3: bool = False
    rational: bool = False
    resize_policy: str = "error"
    flex: str = FLEX_DEFAULT  # the board's shape (calib.flex.FLEX_MODES): "auto" keeps it where the views afford it


@dataclass
class _Found:
    label: str
    file: str
    size: tuple[int, int]
    view: View | None
    why: str = ""  # no view: why, where the detector says
    thumb: np.ndarray | None = None  # a small uint8 copy of the photo (geometry.image_circle.thumbnail)


def _labels(files: list[str]) -> dict[str, str]:
    """Short names for reports: the file name, or the path where two files share a name (printable:
    undecodable bytes of a name shown as \\xNN)."""
    from aicalib_tf.io import display_name

    counts = Counter(Path(f).name for f in files)
    return {f: display_name(Path(f).name if counts[Path(f).name] == 1 else f) for f in files}


def _file_detector(name: str, pattern: tuple[int, int], network: str):
    """``file -> (size (w, h), (corners, ids) or None, why, relative, thumbnail (h', w') uint8)`` or
    the ImageError's text, with the detector made once (the setup of :func:`aicalib_tf.detect.batch.map_images`)."""
    from aicalib_tf.io import ImageError, load_image

    detect = make_detector(name, pattern, network)

    def work(f):
        try:
            gray = load_image(f)
        except ImageError as exc:
            return str(exc)
        hit = detect(gray)
        small = np.round(np.clip(thumbnail(gray), 0.0, 1.0) * 255).astype(np.uint8)  # 0.3 MB a photo at most
        return gray.shape[::-1], hit, detect.why, detect.relative, small, detect.sigmas
    return work


def _detect_all(files: list[str], labels: dict[str, str], cfg: "CalibrateConfig") -> tuple[list[_Found], dict[str, str]]:
    """Detect every file (in ``cfg.workers`` processes; :mod:`aicalib_tf.detect.batch`), in order."""
    from tqdm import tqdm

    from aicalib_tf.detect.batch import map_images
    from aicalib_tf.io import display_name

    found, skipped = [], {}
    results = map_images(files, _file_detector, (cfg.detector, _target(cfg), cfg.network), workers=cfg.workers)
    for f, res in zip(files, tqdm(results, total=len(files), desc="detect", unit="img", disable=cfg.quiet)):
        if isinstance(res, str):
            skipped[labels[f]] = res.removeprefix(f"{display_name(f)}: ")
            continue
        size, hit, why, relative, thumb, sigmas = res
        view = View(labels[f], *hit, relative=relative, sigmas=sigmas) if hit is not None else None
        found.append(_Found(labels[f], f, size, view,
                            "" if hit is not None else why, thumb))
    return found, skipped


def _target(cfg):
    """What the detector looks for: the ChArUco board of ``cfg.board``, else the pattern."""
    if cfg.board:
        from aicalib_tf.geometry.aprilgrid import is_aprilgrid, load_board
        from aicalib_tf.geometry.charuco import parse_board
        from aicalib_tf.geometry.circles import is_circles
        from aicalib_tf.geometry.circles import parse_board as parse_circles

        if is_circles(cfg.board):
            return parse_circles(cfg.board)
        return load_board(cfg.board) if is_aprilgrid(cfg.board) else parse_board(cfg.board)
    return cfg.pattern


def _apply_size_policy(found: list[_Found], policy: str, skipped: dict) -> tuple[list[_Found], tuple[int, int]]:
    """Bring every image to the most common size, as the policy says; returns (found, size)."""
    sizes = Counter(f.size for f in found)
    size = sizes.most_common(1)[0][0]
    odd = [f for f in found if f.size != size]
    if not odd:
        return found, size
    if policy == "error":
        names = ", ".join(f"{f.label} ({f.size[0]}x{f.size[1]})" for f in odd)
        raise CalibrationError(f"images of different sizes: most are {size[0]}x{size[1]} but {names}; "
                               "choose --resize-policy skip, crop or scale")
    out = []
    for f in found:
        if f.size == size:
            out.append(f)
            continue
        tag = f"{f.size[0]}x{f.size[1]}"
        if policy == "skip":
            skipped[f.label] = f"image is {tag}, not {size[0]}x{size[1]} (--resize-policy skip)"
            continue
        if policy == "crop" and (f.size[0] < size[0] or f.size[1] < size[1]):
            skipped[f.label] = f"image is {tag}, smaller than {size[0]}x{size[1]}: cannot crop"
            continue
        view = f.view
        if view is not None and policy == "crop":
            inside = (view.corners[:, 0] <= size[0] - 0.5) & (view.corners[:, 1] <= size[1] - 0.5)
            view = View(view.name, view.corners[inside], view.ids[inside], view.relative,
                        None if view.sigmas is None else view.sigmas[inside])
        elif view is not None:  # scale
            s = np.array([size[0] / f.size[0], size[1] / f.size[1]])
            sig = None if view.sigmas is None else view.sigmas * float(np.sqrt(s[0] * s[1]))
            view = View(view.name, (view.corners + 0.5) * s - 0.5, view.ids, view.relative, sig)
        print(f"note: {f.label} is {tag}; {'cropped' if policy == 'crop' else 'scaled'} to {size[0]}x{size[1]}",
              file=sys.stderr)
        out.append(_Found(f.label, f.file, size, view, f.why))  # no thumbnail: not the photos' frame
    return out, size


def _image_circle(found: list[_Found], size: tuple[int, int]):
    """(the image circle of the photos of ``size`` (their thumbnails' mean) or None, why none was found
    where the frame's corners are dark, else "")."""
    thumbs = [f.thumb for f in found if f.thumb is not None and f.size == size]
    if not thumbs or any(t.shape != thumbs[0].shape for t in thumbs):
        return None, ""
    return find_image_circle(np.mean(thumbs, axis=0, dtype=np.float64) / 255.0, size)


def _preview(cal: Calibration, files: dict[str, str]) -> tuple[str, bytes] | None:
    """(file name, PNG bytes) of the first used view's image of the calibration's size, undistorted (grey).

    Images that --resize-policy brought to that size are passed over, so the preview never
    repeats the crop or scale that their corners went through.
    """
    import cv2

    from aicalib_tf.calib.files import undistort as _undistort
    from aicalib_tf.io import ImageError, load_image, quantize

    w, h = cal.image_size
    for name in cal.views:
        try:
            img = quantize(load_image(files[name]))
        except ImageError:
            continue
        if img.shape[:2] != (h, w):
            continue
        ok, png = cv2.imencode(".png", _undistort(img, cal))
        if ok:
            return PREVIEW_NAME, png.tobytes()
    return None


def _suggest_pattern(files: list[str], model_path: str) -> str:
    """A hint naming the grid sizes the CNN sees in the first images, for a wrong --pattern."""
    from aicalib_tf.cnn.model import load_model
    from aicalib_tf.detect.pipeline import detect_corners
    from aicalib_tf.io import ImageError

    model = load_model(model_path)
    seen = Counter()
    for f in files[:3]:
        try:
            det = detect_corners(f, None, model=model)
        except ImageError:
            continue
        if det.found and det.pattern_size:
            c, r = det.pattern_size
            seen[f"{max(c, r)}x{min(c, r)}"] += 1
    if not seen:
        return ""
    return f" (the CNN sees {', '.join(f'{k} grids in {v} image(s)' for k, v in seen.items())}; is --pattern right?)"


def run(cfg: CalibrateConfig) -> tuple[Calibration, str]:
    """Detect, calibrate, write every output file; returns (calibration, printed report).

    Raises ValueError / CalibrationError / FileNotFoundError for bad input, before writing anything.
    """
    from aicalib_tf.io import expand_images
    from aicalib_tf.outfolder import OutputFolder

    files = expand_images(cfg.images)
    if not files:
        raise ValueError(f"no images match {' '.join(cfg.images)}")
    if cfg.resize_policy not in RESIZE_POLICIES:
        raise ValueError(f"--resize-policy must be one of {', '.join(RESIZE_POLICIES)}, got {cfg.resize_policy!r}")
    if cfg.model != "auto" and cfg.model not in LENS_MODELS:
        raise ValueError(f"--model must be auto or one of {', '.join(LENS_MODELS)}, got {cfg.model!r}")
    detect = make_detector(cfg.detector, _target(cfg), cfg.network)  # a bad network or board fails here, before any work
    with OutputFolder(cfg.out, "calibration") as out:  # a bad --out fails here; files are swapped in at the end
        cal, report, figure, preview = _calibrate_files(files, detect, cfg)
        write_calibration_files(out.path, cal, report, figure, preview)
    return cal, report


def write_calibration_files(folder: Path, cal: Calibration, report: str, figure: bytes, preview=None) -> None:
    """A calibration's set of files in ``folder`` (an :class:`~aicalib_tf.outfolder.OutputFolder`'s
    staging path): :func:`~aicalib_tf.calib.files.save_calibration`'s files, report.png (``figure``,
    PNG bytes), report.txt and, when given, the preview ((file name, PNG bytes))."""
    from aicalib_tf.calib.files import save_calibration
    from aicalib_tf.io import atomic_write_bytes, atomic_write_text

    save_calibration(cal, folder)
    atomic_write_bytes(folder / "report.png", figure)
    atomic_write_text(folder / "report.txt", report + "\n")
    if preview is not None:
        atomic_write_bytes(folder / preview[0], preview[1])


def unreadable_error(files: list[str], skipped: dict[str, str], what: str = "images") -> CalibrationError:
    """The error for a set none of whose files could be read: the count and the first reasons."""
    shown = "; ".join(f"{name}: {why}" for name, why in list(skipped.items())[:3])
    more = f" (and {len(skipped) - 3} more)" if len(skipped) > 3 else ""
    return CalibrationError(f"none of the {len(files)} {what} could be read: {shown}{more}")


def _calibrate_files(files: list[str], detect, cfg: CalibrateConfig):
    """Detect, calibrate, assess; returns (calibration, report text, report.png bytes, preview or None)."""
    from aicalib_tf.calib.report import format_report, report_figure

    labels = _labels(files)
    found, skipped = _detect_all(files, labels, cfg)
    if not found:
        raise unreadable_error(files, skipped)
    found, size = _apply_size_policy(found, cfg.resize_policy, skipped)
    for f in found:
        if f.view is None:
            skipped[f.label] = f"no {cfg.pattern[0]}x{cfg.pattern[1]} board found" + (f": {f.why}" if f.why else "")
    views = [f.view for f in found if f.view is not None]
    if not views:
        whys = Counter(f.why for f in found if f.why)
        if whys and "board" in detect.info:  # a ChArUco board: its markers say why (e.g. another size)
            why, n = whys.most_common(1)[0]
            raise CalibrationError(f"no {detect.info.get('kind', 'ChArUco')} board read in any of the {len(files)} images; "
                                   f"in {n}: {why}")
        hint = _suggest_pattern(files, detect.info["model"]) if "model" in detect.info else ""
        raise CalibrationError(f"no {cfg.pattern[0]}x{cfg.pattern[1]} board found in any of the {len(files)} images{hint}")
    meta = {"detector": cfg.detector, "model": detect.info.get("model"), "model_sha256": detect.info.get("sha256"),
            "rational": cfg.rational, "lens_model": cfg.model, "fix_k3": cfg.fix_k3, "resize_policy": cfg.resize_policy,
            "flex": cfg.flex, "images": len(files), **({"board": cfg.board} if cfg.board else {})}
    circle, note = _image_circle(found, size)
    if note:
        meta["image_circle_note"] = note
    fit = functools.partial(calibrate_camera, pattern_size=cfg.pattern, square_size=cfg.square, image_size=size,
                            model=cfg.model, rational=cfg.rational, fix_k3=cfg.fix_k3, square_unit=cfg.square_unit,
                            meta=meta, image_circle=circle, flex=cfg.flex)
    board = _target(cfg)
    if hasattr(board, "circle_ids"):  # centres corrected for the projected-centre bias, then refitted
        from aicalib_tf.calib.circle_bias import calibrate_circles

        cal, views = calibrate_circles(views, board, fit)
    else:
        cal = fit(views)
    by_name = {v.name: v for v in views}
    used = [by_name[n] for n in cal.views]

    def choose(vs, models):  # a half's own model choice (auto only: a forced model is not questioned)
        return choose_model(vs, cfg.pattern, size, models, fix_k3=cfg.fix_k3, image_circle=circle)

    cal = dataclasses.replace(cal, quality=assess(cal, used, fit=fit_views, choose=choose if cfg.model == "auto" else None))
    report = format_report(cal, used, skipped=skipped, total=len(files))
    return cal, report, report_figure(cal, used), _preview(cal, {labels[f]: f for f in files})
