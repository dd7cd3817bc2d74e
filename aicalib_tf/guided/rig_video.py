"""From each camera's video (or stream) of a rig to a saved rig calibration, through the guided loop.

    python -m aicalib_tf.calibrate --rig cam0=left.mp4 cam1=right.mp4 --pattern 9x6 --square 25mm --out rig/

1. **Reading.** The cameras' frames come through :func:`aicalib_tf.sources.open_source`, merged in
   time order (the earliest next frame first; by frame number with ``pair_by="index"``).
2. **Selection.** Each camera's frames go through its own
   :class:`~aicalib_tf.guided.session.GuidedCalibration` (the motion gate, the keep rule, the stop
   rule), so most frames are never detected. A camera stops examining at its target, at
   ``max_views`` or after ``max_examined`` detections, and reading stops when every camera has.
3. **Partners.** For every frame a camera keeps, the other cameras' frames within two tolerances
   of it are held (a few frames kept back from the reading, and those still to come); after the
   reading, :func:`aicalib_tf.sources.pair_frames` pairs every camera with camera 0 (by timestamp
   within ``sync_tolerance_s``, or by index), the kept frame's partners are detected, and a frame
   kept by either camera becomes a shared frame that ties the cameras. Cameras out of sync beyond
   the tolerance are refused (ValueError with the measured offset, naming both sources), checked
   every :data:`SYNC_CHECK_EVERY` frames and at the end.
4. **The rig.** :func:`aicalib_tf.calib.rig.workflow.calibrate_views` (calibrate_rig, assess_rig,
   the sanity checks) and :func:`~aicalib_tf.calib.rig.workflow.write_rig_files`: the files of the
   photo rig path. Views are named ``frame<camera 0's frame index>``; a kept frame with no partner
   serves its own camera's lens only. rig.json's ``meta`` holds each camera's kept frames, the
   frames used, the pairing and the measured offset.
"""

from __future__ import annotations

import re
import sys
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from aicalib_tf.calib.fit import CalibrationError, View
from aicalib_tf.calib.run_options import RunOptions
from aicalib_tf.guided.save import PARTIAL_HEAD
from aicalib_tf.guided.session import GuidedCalibration, GuidedConfig, check_max_views
from aicalib_tf.guided.workflow import board_name, board_target

__all__ = ["RigVideoConfig", "run_rig_video", "is_rig_video", "parse_tolerance", "pair_overlap", "SYNC_CHECK_EVERY"]

SYNC_CHECK_EVERY = 30  # frames of camera 0 between two checks of the cameras' sync
_RECENT = 64  # frames each camera keeps back for the partners of the others' kept frames, at most


@dataclass(frozen=True, kw_only=True)
class RigVideoConfig(RunOptions):
    """A rig from videos or streams: ``cameras`` ((name, source), ...), the shared
    :class:`~aicalib_tf.calib.run_options.RunOptions` (the board, detector, lens model, outputs), the loop's
    settings and the pairing (``pair_by`` "time" or "index", ``sync_tolerance_s``)."""

    cameras: tuple[tuple[str, str], ...]
    out: str = "rig"
    target_px: float = 0.1
    max_views: int = 40
    max_examined: int = 300  # detections per camera at most (the motion gate picks which frames)
    sync_tolerance_s: float = 0.010
    pair_by: str = "time"
    save_partial: bool = False  # a reading stopped early (Ctrl-C, a stream that fails) still calibrates

    def __post_init__(self):
        check_max_views(self.max_views)


def is_rig_video(cameras) -> bool:
    """Whether every (name, source) of a ``--rig`` names a video file or a stream URL (False when none
    does); ValueError naming them when only some do."""
    from aicalib_tf.sources import is_stream, is_video

    video = [n for n, s in cameras if is_stream(s) or is_video(s)]
    if video and len(video) < len(cameras):
        others = [n for n, _ in cameras if n not in video]
        raise ValueError(f"--rig: {', '.join(video)} given a video or stream but {', '.join(others)} images; "
                         "give every camera a video (or stream), or every camera images")
    return bool(video)


def parse_tolerance(text: str) -> float:
    """``"10ms"``, ``"0.01s"`` or ``"10"`` (ms) -> seconds (>= 0); ValueError otherwise."""
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:e[-+]?[0-9]+)?)\s*(ms|s)?\s*", str(text).lower())
    if not m:
        raise ValueError(f"--sync-tolerance must be a time such as 10ms or 0.01s, got {text!r}")
    return float(m.group(1)) * (1.0 if m.group(2) == "s" else 1e-3)


@dataclass
class _Camera:
    """One camera while reading: its source and session, every frame's index and time, the frames
    kept back (``recent``), the frames held for the rig ({index: (H, W) uint8}) and the times of the
    other cameras' kept frames it still holds partners for (``wants``)."""

    name: str
    source: object
    session: GuidedCalibration
    indices: list = field(default_factory=list)
    times: list = field(default_factory=list)
    recent: deque = field(default_factory=lambda: deque(maxlen=_RECENT))
    held: dict = field(default_factory=dict)
    wants: list = field(default_factory=list)
    found: dict = field(default_factory=dict)  # {index: (corners, ids, relative) or None} of the frames examined

    def stopped(self, max_examined: int) -> bool:
        """The camera examines no more frames (its stop rule, or the cap)."""
        return self.session._s.done or self.session.examined >= max_examined


def _key(frame, by: str) -> float:
    return float(frame.index) if by == "index" else float(frame.time_s)


def _take(cams: list[_Camera], k: int, frame, cfg: RigVideoConfig, window: float) -> None:
    """One frame of camera ``k``: record it, hold it when another camera kept a frame near it, run the
    camera's loop on it, and when kept, hold the other cameras' frames near it (now and to come)."""
    cam, t = cams[k], _key(frame, cfg.pair_by)
    cam.indices.append(frame.index)
    cam.times.append(frame.time_s)
    cam.recent.append(frame)
    while _key(cam.recent[0], cfg.pair_by) < t - window - 1e-9:
        cam.recent.popleft()
    cam.wants = [w for w in cam.wants if w >= t - window - 1e-9]
    if any(abs(t - w) <= window + 1e-9 for w in cam.wants):
        cam.held[frame.index] = frame.gray
    if cam.stopped(cfg.max_examined):
        return
    update = cam.session.add(frame)
    if update.examined:
        cam.found[frame.index] = None if update.corners is None else (
            update.corners, update.ids, bool(getattr(cam.session.detect, "relative", False)),
            getattr(cam.session.detect, "sigmas", None))
    if not update.kept:
        return
    cam.held[frame.index] = frame.gray
    for other in cams:
        if other is not cam:
            other.wants.append(t)
            other.held.update({f.index: f.gray for f in other.recent if abs(_key(f, cfg.pair_by) - t) <= window + 1e-9})


def pair_overlap(times_a, times_b, *, by: str = "time", tolerance_s: float = 0.010, names=("cam0", "cam1")):
    """:func:`aicalib_tf.sources.pair_frames` over the span both cameras recorded (by time: a camera that
    started earlier or ran longer is not out of sync for it); the frames outside it are unpaired.
    times_a, times_b : (Na,), (Nb,) s. Returns a :class:`aicalib_tf.sources.Pairing` indexing the full arrays."""
    from aicalib_tf.sources import Pairing, pair_frames

    a, b = np.asarray(times_a, np.float64), np.asarray(times_b, np.float64)
    if by != "time" or not len(a) or not len(b):
        return pair_frames(a, b, by=by, tolerance_s=tolerance_s, names=names)
    lo, hi = max(a.min(), b.min()) - tolerance_s, min(a.max(), b.max()) + tolerance_s
    ia, ib = np.flatnonzero((a >= lo) & (a <= hi)), np.flatnonzero((b >= lo) & (b <= hi))
    if not len(ia) or not len(ib):
        raise ValueError(f"{names[0]} and {names[1]} never recorded at the same time ({a.min():.2f}-{a.max():.2f} s "
                         f"against {b.min():.2f}-{b.max():.2f} s)")
    p = pair_frames(a[ia], b[ib], by=by, tolerance_s=tolerance_s, names=names)
    pairs = [(int(ia[i]), int(ib[j])) for i, j in p.pairs]
    used_a, used_b = {i for i, _ in pairs}, {j for _, j in pairs}
    return Pairing(pairs, [i for i in range(len(a)) if i not in used_a], [j for j in range(len(b)) if j not in used_b],
                   p.offset_s)


def _check_sync(cams: list[_Camera], cfg: RigVideoConfig) -> list:
    """Each camera paired with camera 0 (:func:`pair_overlap`); ValueError naming the sources when they
    are out of sync."""
    out = []
    for cam in cams[1:]:
        try:
            out.append(pair_overlap(cams[0].times, cam.times, by=cfg.pair_by, tolerance_s=cfg.sync_tolerance_s,
                                    names=(f"{cams[0].name} ({cams[0].source.name})", f"{cam.name} ({cam.source.name})")))
        except ValueError as exc:
            raise ValueError(f"--rig: {exc}") from None
    return out


def _read(cams: list[_Camera], cfg: RigVideoConfig) -> str:
    """Read every camera in time order through its loop; returns why the reading stopped."""
    window = 0.0 if cfg.pair_by == "index" else 2.0 * cfg.sync_tolerance_s
    iters = [iter(c.source) for c in cams]
    heads = [next(it, None) for it in iters]
    while any(h is not None for h in heads):
        k = min((i for i, h in enumerate(heads) if h is not None), key=lambda i: _key(heads[i], cfg.pair_by))
        frame, heads[k] = heads[k], next(iters[k], None)
        _take(cams, k, frame, cfg, window)
        if k == 0 and len(cams[0].times) % SYNC_CHECK_EVERY == 0 and cfg.pair_by == "time":
            _check_sync(cams, cfg)
        if not cfg.quiet and k == 0 and len(cams[0].times) % 10 == 0:
            print("\r" + " | ".join(f"{c.name}: frames {len(c.times)}, examined {c.session.examined}, kept "
                                    f"{len(c.session.views)}" for c in cams).ljust(96), end="", file=sys.stderr)
        if all(c.stopped(cfg.max_examined) for c in cams) and not any(c.wants for c, h in zip(cams, heads) if h is not None):
            return "every camera reached its target, --max-views or the cap on frames examined"
    return "end of the streams" if any(c.source.live for c in cams) else "end of the videos"


def _groups(cams: list[_Camera], pairings: list) -> tuple[list, dict]:
    """The frames to use: ([(name, {camera k: position in k's frames})], {camera: kept positions
    without a partner}); a frame kept by any camera joins with its partners in every camera."""
    pos = [{idx: p for p, idx in enumerate(c.indices)} for c in cams]
    to0 = [None] + [{j: i for i, j in p.pairs} for p in pairings]
    from0 = [None] + [dict(p.pairs) for p in pairings]
    frames, solo = {}, {}
    for k, cam in enumerate(cams):
        for idx in cam.session.kept_frames:
            p = pos[k][idx]
            i = p if k == 0 else to0[k].get(p)
            if i is None:
                frames[f"{cam.name}-frame{idx:06d}"] = {k: p}
                solo.setdefault(cam.name, []).append(f"frame {idx}")
                continue
            group = {0: i, **{m: from0[m][i] for m in range(1, len(cams)) if i in from0[m]}}
            frames[f"frame{cams[0].indices[i]:06d}"] = group
    order = sorted(frames, key=lambda n: min(cams[k].times[p] for k, p in frames[n].items()))
    return [(n, frames[n]) for n in order], solo


def _partner_view(cam: _Camera, name: str, idx: int, detect) -> tuple[View | None, str, bool]:
    """A partner frame's view (its loop's detection, or detected now), or None and why not; and whether
    the detector ran."""
    ran = idx not in cam.found
    if ran:
        gray = cam.held.get(idx)
        if gray is None:
            return None, "the frame was not held (the cameras' clocks disagree?)", False
        hit = detect(gray)
        if hit is None:
            why = getattr(detect, "why", "")
            return None, "no board found" + (f": {why}" if why else ""), True
        cam.found[idx] = (np.asarray(hit[0], np.float64), np.asarray(hit[1]), bool(getattr(detect, "relative", False)),
                          getattr(detect, "sigmas", None))
    if cam.found[idx] is None:
        return None, "no board found", False
    corners, ids, relative, sigmas = cam.found[idx]
    if len(ids) < cam.session.cfg.min_corners:
        return None, f"too few corners ({len(ids)})", ran
    return View(name, corners, ids, relative=relative, sigmas=sigmas), "", ran


def _views(cams: list[_Camera], groups: list, detect, cfg: RigVideoConfig):
    """({camera: [View]}, {"camera/frame": why skipped}, [(name, {camera: (H, W) frame})], detections run)."""
    own = [{int(v.name.removeprefix("frame")): v for v in c.session.views} for c in cams]
    views, skipped, images, detected = {c.name: [] for c in cams}, {}, [], 0
    for name, group in groups:
        shown = {}
        for k, p in group.items():
            cam, idx = cams[k], cams[k].indices[p]
            view = own[k].get(idx)
            if view is None:
                view, why, ran = _partner_view(cam, name, idx, detect)
                detected += ran
                if view is None:
                    skipped[f"{cam.name}/{name}"] = f"partner frame {idx}: {why}"
                    continue
            views[cam.name].append(View(name, view.corners, view.ids, view.relative, view.sigmas))
            if idx in cam.held:
                shown[cam.name] = cam.held[idx]
        images.append((name, shown))
    return views, skipped, images, detected


def _open(cfg: RigVideoConfig, detect, models: list[str]) -> list[_Camera]:
    """Each camera's source and loop (the camera's lens model, or the one for all)."""
    import os

    from aicalib_tf.sources import is_stream, open_source

    owner: dict[str, str] = {}
    for name, spec in cfg.cameras:
        if not is_stream(spec) and owner.setdefault(os.path.realpath(spec), name) != name:
            raise ValueError(f"--rig: {owner[os.path.realpath(spec)]} and {name} are given the same video ({spec}); "
                             "each camera needs its own")
    cams = []
    try:
        for k, (name, spec) in enumerate(cfg.cameras):
            session = GuidedCalibration(GuidedConfig(cfg.pattern, cfg.square, cfg.square_unit, models[k % len(models)],
                                                     cfg.target_px, cfg.max_views), detect)
            cams.append(_Camera(name, open_source(spec), session))
    except BaseException:
        for c in cams:
            c.source.close()
        raise
    return cams


def _summary(cams: list[_Camera], pairings: list, stopped: str, detected: int) -> list[str]:
    lines = [f"{c.name} ({c.source.name}): {len(c.times)} frames read, {c.session.examined} examined, "
             f"{len(c.session.views)} views kept" for c in cams]
    lines.append(f"  stopped: {stopped}; {detected} partner frames detected")
    for cam, p in zip(cams[1:], pairings):
        lines.append(f"  {cams[0].name}-{cam.name}: {len(p.pairs)} frame pairs, offset {1e3 * p.offset_s:+.1f} ms; "
                     f"unpaired: {len(p.unpaired_a)} of {cams[0].name}, {len(p.unpaired_b)} of {cam.name}")
    return lines


def run_rig_video(cfg: RigVideoConfig) -> tuple[object, str]:
    """Read, select, pair, detect the partners, calibrate the rig, write its files; returns (rig, report).

    Raises OSError / ValueError naming a source that is missing or unreadable, ValueError for cameras
    out of sync (the measured offset) or a bad ``out`` (before any frame is read), CalibrationError when
    a camera gives too few views; nothing is written then. A reading stopped early (Ctrl-C, a stream
    that fails) writes nothing unless ``save_partial``: then the rig from the frames read so far,
    ``"partial": true`` in rig.json's ``meta`` and PARTIAL at the top of the report.
    """
    from aicalib_tf.calib.rig.workflow import Pairing, calibrate_views, rig_models, write_rig_files
    from aicalib_tf.calib.workflow import make_detector
    from aicalib_tf.outfolder import OutputFolder

    models = rig_models(cfg.model, [n for n, _ in cfg.cameras])
    detect = make_detector(cfg.detector, board_target(cfg), cfg.network)
    with OutputFolder(cfg.out, "rig") as out:
        cams = _open(cfg, detect, models)
        partial = False
        try:
            stopped = _read(cams, cfg)
        except (KeyboardInterrupt, OSError) as exc:
            if not cfg.save_partial:
                raise
            partial, stopped = True, f"stopped early: {exc or 'interrupted'}"
        finally:
            for c in cams:
                c.source.close()
            if not cfg.quiet:
                print(file=sys.stderr)
        pairings = _check_sync(cams, cfg)
        for c in cams:
            if not c.session.views:
                raise CalibrationError(f"{c.name} ({c.source.name}): no {board_name(cfg)} kept "
                                       f"in the {c.session.examined} frames examined (of {len(c.times)})")
        groups, solo = _groups(cams, pairings)
        views, skipped, images, detected = _views(cams, groups, detect, cfg)
        rule = ("frame index" if cfg.pair_by == "index" else
                f"timestamps within {1e3 * cfg.sync_tolerance_s:g} ms")
        meta = {"detector": cfg.detector, "model": detect.info.get("model"), "model_sha256": detect.info.get("sha256"),
                "lens_model": cfg.model, "pairing": rule, "sources": {c.name: c.source.name for c in cams},
                "frames": {c.name: len(c.times) for c in cams}, "examined": {c.name: c.session.examined for c in cams},
                "kept_frames": {c.name: c.session.kept_frames for c in cams}, "frames_used": [n for n, _ in groups],
                "offset_s": {c.name: p.offset_s if np.isfinite(p.offset_s) else None for c, p in zip(cams[1:], pairings)},
                "stopped": stopped, "partial": partial, **({"board": cfg.board} if cfg.board else {})}
        sizes = {c.name: c.session.image_size for c in cams}
        found = {c.name: c.session.image_circle_and_note() for c in cams}  # each camera's examined frames
        circles = {name: circle for name, (circle, _) in found.items()}
        notes = {name: note for name, (_, note) in found.items() if note}
        if notes:
            meta["image_circle_notes"] = notes
        rig, report, figure = calibrate_views(views, sizes, Pairing(images, rule, solo), skipped, cfg, models, meta,
                                              circles)
        report = "\n".join([*_summary(cams, pairings, stopped, detected), report])
        if partial:
            report = PARTIAL_HEAD + report
        write_rig_files(out.path, rig, report, figure)
    return rig, report
