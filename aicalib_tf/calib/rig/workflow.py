"""From each camera's photos to a saved rig calibration: pair the images, detect, calibrate, assess, write.

Pairing (:func:`pair_images`): images of different cameras taken at one instant are matched by a
shared name stem, either the whole file stem (``cam0/0001.png`` with ``cam1/0001.png``) or the
number it ends with (``left01.jpg`` with ``right01.jpg``: frame ``01``); whichever pairs more images
wins. When no name is shared and every camera has as many images, they are paired in sorted
order. Images left without a partner are reported; they still serve their own camera's lens.

Each camera's image circle (a circular fisheye's) is estimated from the mean of its images, as for
one camera (:mod:`aicalib_tf.calib.workflow`), and kept in its calibration.

The command line is ``python -m aicalib_tf.calibrate --rig cam0="left/*.png" cam1="right/*.png"``.
Videos of a rig come through :mod:`aicalib_tf.guided.rig_video`, which selects the frames and then
calls the same :func:`calibrate_views` and :func:`write_rig_files`.
"""

from __future__ import annotations

import dataclasses
import re
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from aicalib_tf.calib.run_options import RunOptions

__all__ = ["RigConfig", "Pairing", "parse_rig", "pair_images", "run_rig", "rig_models", "calibrate_views",
           "write_rig_files"]

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_-]*")


def parse_rig(items) -> list[tuple[str, str]]:
    """["cam0=left/*.png", "cam1=right/*.png"] -> [(name, pattern)]; ValueError naming a bad item."""
    out = []
    for item in items:
        name, sep, pattern = str(item).partition("=")
        if not sep or not _NAME.fullmatch(name) or not pattern:
            raise ValueError(f"--rig takes NAME=GLOB items such as cam0=\"left/*.png\", got {item!r}")
        out.append((name, pattern))
    names = [n for n, _ in out]
    if len(set(names)) != len(names):
        raise ValueError(f"--rig names a camera twice: {', '.join(sorted(n for n, c in Counter(names).items() if c > 1))}")
    if len(out) < 2:
        raise ValueError(f"--rig needs at least two cameras, got {len(out)}")
    return out


@dataclass(frozen=True)
class Pairing:
    """frames: [(frame name, {camera: file})] in order; rule: how they were paired; unpaired: {camera: [file]}."""

    frames: list
    rule: str
    unpaired: dict


def _stem(f: str) -> str:
    from aicalib_tf.io import display_name

    return display_name(Path(f).stem)


def _number(f: str) -> str | None:
    m = re.search(r"(\d+)\D*$", Path(f).stem)
    return str(int(m.group(1))) if m else None


def _keyed(files: dict[str, list[str]], key) -> dict[str, dict[str, str]] | None:
    """{key: {camera: file}} or None when a camera has two files of one key or a file has none."""
    out: dict[str, dict[str, str]] = {}
    for cam, fs in files.items():
        for f in fs:
            k = key(f)
            if k is None or cam in out.setdefault(k, {}):
                return None
            out[k][cam] = f
    return out


def pair_images(files: dict[str, list[str]]) -> Pairing:
    """Pair each camera's sorted files into frames (module docstring). ValueError when they cannot be paired."""
    best = None
    for rule, key in (("the same file name stem", _stem), ("the number ending each file name", _number)):
        keyed = _keyed(files, key)
        if keyed is None:
            continue
        n = sum(len(v) >= 2 for v in keyed.values())
        if n and (best is None or n > best[0]):
            best = (n, rule, keyed, key)
    if best is None:
        counts = {c: len(fs) for c, fs in files.items()}
        if len(set(counts.values())) != 1:
            raise ValueError("cannot pair the images: their names share no stem or number, and the cameras have "
                             f"different image counts ({', '.join(f'{c}: {n}' for c, n in counts.items())})")
        first = next(iter(files))
        frames = [(_stem(files[first][i]), {c: fs[i] for c, fs in files.items()}) for i in range(counts[first])]
        return Pairing(frames, "sorted order (the names share no stem or number)", {})
    _, rule, keyed, key = best
    order = sorted(keyed, key=lambda k: min(sorted(files[c]).index(f) for c, f in keyed[k].items()))
    shown = {k: _stem(next(iter(keyed[k].values()))) if key is _stem else
             re.search(r"(\d+)\D*$", _stem(next(iter(keyed[k].values())))).group(1) for k in order}
    frames = [(shown[k], keyed[k]) for k in order]
    unpaired = {c: [keyed[k][c] for k in order if c in keyed[k] and len(keyed[k]) < 2] for c in files}
    return Pairing(frames, rule, {c: v for c, v in unpaired.items() if v})


@dataclass(frozen=True, kw_only=True)
class RigConfig(RunOptions):
    """Everything one rig run needs (the CLI's options): the shared :class:`RunOptions` and the cameras."""

    cameras: tuple[tuple[str, str], ...]  # (name, glob)
    out: str = "rig"


def _detect_camera(cam, frames, cfg: RigConfig) -> tuple[dict, dict, dict, list]:
    """({frame: View}, {frame: (w, h)}, {frame: why skipped}, the detections with their thumbnails) of one camera."""
    from aicalib_tf.calib.workflow import _detect_all

    files = [fs[cam] for _, fs in frames if cam in fs]
    labels = {fs[cam]: name for name, fs in frames if cam in fs}
    found, skipped = _detect_all(files, labels, cfg)
    views = {f.label: f.view for f in found if f.view is not None}
    for f in found:
        if f.view is None:
            skipped[f.label] = "no board found" + (f": {f.why}" if f.why else "")
    return views, {f.label: f.size for f in found}, skipped, found


def _save_failed_rig(rig, folder: Path) -> None:
    """A failed rig's files: rig.json (status "failed", the problems) and each camera's own calibration
    (alone, never the joint fit's) in a folder of its name; no stereo files to be used by mistake."""
    from aicalib_tf.calib.files import FILES
    from aicalib_tf.calib.rig.files import rig_texts
    from aicalib_tf.io import atomic_write_text

    texts = rig_texts(dataclasses.replace(rig, cameras=rig.single or rig.cameras))
    for rel, text in texts.items():
        parts = Path(rel).parts
        if rel == "rig.json" or (len(parts) == 2 and parts[0] in rig.names and parts[1] in FILES):
            (folder / rel).parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(folder / rel, text)


def _refuse_shared_files(files: dict[str, list[str]]) -> None:
    """ValueError when two cameras are given the same image files (a rig of one camera with itself)."""
    import os

    owner: dict[str, str] = {}
    for cam, fs in files.items():
        for f in fs:
            key = os.path.realpath(f)
            if owner.setdefault(key, cam) != cam:
                raise ValueError(f"--rig: {owner[key]} and {cam} are given the same image file ({Path(f).name}); "
                                 "each camera needs its own images")


def _check_sizes(cam, views, sizes, frames, skipped) -> tuple[int, int]:
    """The camera's image size (its most common one); a frame of another size is dropped with a message
    naming the pair and both sizes."""
    if not sizes:
        from aicalib_tf.calib.workflow import unreadable_error

        raise unreadable_error([fs[cam] for _, fs in frames if cam in fs], skipped, f"{cam} images")
    size = Counter(sizes.values()).most_common(1)[0][0]
    files = dict((n, fs) for n, fs in frames)
    for name, s in sizes.items():
        if s != size:
            views.pop(name, None)
            others = ", ".join(f"{c} {Path(f).name}" for c, f in files[name].items() if c != cam)
            skipped[name] = (f"pair {name}: {cam}'s {Path(files[name][cam]).name} is {s[0]}x{s[1]} but {cam}'s other "
                             f"images are {size[0]}x{size[1]} (with {others})")
    return size


def run_rig(cfg: RigConfig) -> tuple[object, str]:
    """Pair, detect, calibrate the rig, assess it, write every file; returns (rig, printed report).

    Raises ValueError / CalibrationError / FileNotFoundError for bad input, before writing anything.
    """
    from aicalib_tf.calib.workflow import _image_circle, _target, make_detector
    from aicalib_tf.io import expand_images
    from aicalib_tf.outfolder import OutputFolder

    files = {}
    for name, pattern in cfg.cameras:
        files[name] = expand_images([pattern])
        if not files[name]:
            raise ValueError(f"{name}: no images match {pattern}")
    models = rig_models(cfg.model, list(files))
    _refuse_shared_files(files)
    pairing = pair_images(files)
    detect = make_detector(cfg.detector, _target(cfg), cfg.network)  # a bad network or board fails here, before any work
    with OutputFolder(cfg.out, "rig") as out:  # a bad --out fails here; files are swapped in at the end
        views, sizes, skipped, circles, notes = {}, {}, {}, {}, {}
        for cam in files:
            v, s, sk, found = _detect_camera(cam, pairing.frames, cfg)
            sizes[cam] = _check_sizes(cam, v, s, pairing.frames, sk)
            circles[cam], note = _image_circle(found, sizes[cam])
            if note:
                notes[cam] = note
            views[cam] = [v[n] for n, _ in pairing.frames if n in v]
            skipped.update({f"{cam}/{n}": why for n, why in sk.items()})
        meta = {"detector": cfg.detector, "model": detect.info.get("model"), "model_sha256": detect.info.get("sha256"),
                "lens_model": cfg.model, "pairing": pairing.rule, "images": {c: len(f) for c, f in files.items()},
                **({"board": cfg.board} if cfg.board else {}), **({"image_circle_notes": notes} if notes else {})}
        rig, report, figure = calibrate_views(views, sizes, pairing, skipped, cfg, models, meta, circles)
        write_rig_files(out.path, rig, report, figure)
    return rig, report


def rig_models(model: str, names: list[str]) -> list[str]:
    """``--model`` (one lens model or auto, or a comma list) -> one per camera or one for all; ValueError
    when the list's length is neither 1 nor the number of cameras."""
    models = model.split(",")
    if len(models) not in (1, len(names)):
        raise ValueError(f"--model lists {len(models)} lens models for {len(names)} cameras ({', '.join(names)})")
    return models


def write_rig_files(folder: Path, rig, report: str, figure: bytes) -> None:
    """Write a calibrated rig's files into ``folder`` (an :class:`~aicalib_tf.outfolder.OutputFolder`'s
    staging path): every file of :func:`~aicalib_tf.calib.rig.files.save_rig`, or only rig.json and each
    camera's own files for a failed rig; report.png and report.txt."""
    from aicalib_tf.calib.rig.files import save_rig
    from aicalib_tf.io import atomic_write_bytes, atomic_write_text

    if rig.quality.get("status") == "failed":
        _save_failed_rig(rig, folder)
    else:
        save_rig(rig, folder)
    atomic_write_bytes(folder / "report.png", figure)
    atomic_write_text(folder / "report.txt", report + "\n")


def calibrate_views(views: dict, sizes: dict, pairing, skipped: dict, cfg, models: list[str], meta: dict,
                    circles: dict | None = None):
    """Calibrate the rig from each camera's views named by frame, assess it and run the sanity checks;
    returns (rig, report text, report.png bytes).

    views : {camera: [View]} (a frame's views share its name across cameras); sizes : {camera: (w, h)};
    circles : {camera: its image circle (a circular fisheye's, estimated from its images) or None};
    pairing : a :class:`Pairing` ({camera: file path or (H, W) image} per frame, for the preview);
    skipped : {"camera/frame": why}; cfg : pattern, square, square_unit (:class:`RigConfig` or alike).
    """
    from aicalib_tf.calib.rig.fit import calibrate_rig
    from aicalib_tf.calib.rig.quality import assess_rig
    from aicalib_tf.calib.rig.report import format_rig_report, rig_figure
    from aicalib_tf.calib.rig.sanity import rig_problems

    names = list(views)
    rig = calibrate_rig([views[c] for c in names], cfg.pattern, cfg.square, [sizes[c] for c in names], names=names,
                        models=models if len(models) > 1 else models[0], square_unit=cfg.square_unit, meta=meta,
                        image_circles=[(circles or {}).get(c) for c in names])
    rig = assess_rig(rig, [views[c] for c in names])
    problems = rig_problems(rig)
    quality = dict(rig.quality, status="failed" if problems else "ok", problems=problems)
    if problems:  # one verdict per run: a rig that fails its sanity checks is never also called good
        quality["verdict"] = "failed: not a usable rig calibration (" + "; ".join(problems) + ")"
    rig = dataclasses.replace(rig, quality=quality)
    report = format_rig_report(rig, pairing, skipped)
    if problems:
        report += "\n\nFAILED: this is not a usable rig calibration\n" + "\n".join(f"  - {p}" for p in problems) + \
            "\nrig.json is written with status \"failed\" and each camera's own calibration; no stereo files."
    return rig, report, rig_figure(rig, pairing)
