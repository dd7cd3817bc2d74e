"""Guided calibration: a loop that takes frames one at a time, keeps the informative ones, and says
what to show next. The same loop serves a video file, a camera and a web page.

    session = GuidedCalibration(GuidedConfig(pattern=(9, 6), square=25.0), detector)
    for frame in source:                 # aicalib_tf.sources.Frame, or (index, time_s, gray)
        update = session.add(frame)      # Update: detection, kept / skipped and why, guidance, estimate
        if update.done:
            break
    calibration = session.result()       # the full model choice over the kept views

Per frame: the motion gate (:class:`~aicalib_tf.guided.selection.MotionGate`) skips fast-moving
and unchanged frames without a detection; a detected board is skipped when it is blurred (edge
width above ``blur_ratio`` × the running median and above ``blur_min_px``), a near-duplicate of a
kept view, or adds too little: before the first fit every new view is kept; after it, a view
is kept when it covers new image cells (``new_cells`` of an 8 × 6 grid), or when adding its
information to the current fit's (:func:`aicalib_tf.calib.quality.view_information`) lowers the
predicted mean projection uncertainty over the image by ``min_gain`` or more. Every
``refit_every`` kept views the running model is refitted (forced and cheap: the user's model, or
whichever of plumb_bob and equidistant fits the first views better), warm-started from the last
fit. The session is done when the 90th percentile of the 1σ uncertainty over the covered cells is
at or below ``target_px`` with at least ``min_views`` views and every region of the image
covered (a circular fisheye: every region its image circle reaches), or at ``max_views``. The examined frames' mean (small copies) gives the final
calibration its image circle (a circular fisheye's; :mod:`aicalib_tf.geometry.image_circle`).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

import cv2
import numpy as np

from aicalib_tf.calib.fit import Calibration, CalibrationError, View, calibrate_camera, fit_views
from aicalib_tf.calib.coverage import coverage_counts, in_circle
from aicalib_tf.calib.quality import lens_of, sigma_from_basis, uncertainty_basis, view_information
from aicalib_tf.geometry.image_circle import ImageCircle, find_image_circle, thumbnail
from aicalib_tf.geometry.pattern import board_points
from aicalib_tf.guided.design import design_weight, elimination_order
from aicalib_tf.guided.guidance import Suggestion, missing, next_views
from aicalib_tf.guided.selection import MotionGate, Pose, blur_px, board_pose, near_duplicate, tilt_of

__all__ = ["GuidedConfig", "GuidedCalibration", "Update", "Estimate"]

_CELLS = (8, 6)  # the coverage grid of the keep rule
_POOL = 240  # candidate views remembered beyond the kept ones (the most recent)


MIN_MAX_VIEWS = 3  # a calibration needs at least three views of the board


def check_max_views(n) -> int:
    """``n`` if it is a usable cap on the kept views (an int of at least :data:`MIN_MAX_VIEWS`); else ValueError."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < MIN_MAX_VIEWS:
        raise ValueError(f"--max-views must be an integer of at least {MIN_MAX_VIEWS}, got {n!r}")
    return int(n)


@dataclass(frozen=True)
class GuidedConfig:
    """The loop's settings (module docstring). pattern : (cols, rows); square : board units."""

    pattern: tuple[int, int]
    square: float = 1.0
    square_unit: str = ""
    model: str = "auto"  # the final lens model: auto or a forced one (then also the running model)
    target_px: float = 0.1
    max_views: int = 40
    min_views: int = 8
    first_fit: int = 5
    refit_every: int = 2
    min_corners: int = 12
    new_cells: int = 3
    min_gain: float = 0.04
    blur_ratio: float = 1.5
    blur_min_px: float = 2.5
    gate: bool = True  # the motion gate (False: examine every frame)
    gate_moving: float = 2.0
    gate_changed: float = 1.5
    gate_max_gap: int = 30

    def __post_init__(self):
        check_max_views(self.max_views)


@dataclass(frozen=True)
class Estimate:
    """The running fit: model, K (3, 3), dist, rms px, views, sigma_px (90th percentile of 1σ over
    the covered cells), covered (share of the 8 × 6 cells with a corner)."""

    model: str
    K: np.ndarray
    dist: np.ndarray
    rms: float
    views: int
    sigma_px: float
    covered: float


@dataclass(frozen=True)
class Update:
    """What one frame did. examined : the detector ran. corners (N, 2) px / ids (N, 2), or None.
    kept : the view joined the calibration; reason : why it was kept or skipped. guidance : the
    best next view (None before the first fit); missing : what no kept view shows yet. estimate :
    the running fit (None before it). done : the stop rule holds."""

    index: int
    time_s: float
    examined: bool
    corners: np.ndarray | None
    ids: np.ndarray | None
    kept: bool
    reason: str
    guidance: Suggestion | None
    missing: tuple
    estimate: Estimate | None
    done: bool


@dataclass
class _State:
    views: list = field(default_factory=list)
    poses: list = field(default_factory=list)
    pool: list = field(default_factory=list)  # (View, Pose) seen, not kept, no near-duplicate: candidates
    frames: list = field(default_factory=list)
    blur: list = field(default_factory=list)
    cal: Calibration | None = None
    running: str | None = None
    information: np.ndarray | None = None
    basis: tuple | None = None
    since_fit: int = 0
    estimate: Estimate | None = None
    guidance: Suggestion | None = None
    missing: tuple | None = None
    done: bool = False


class GuidedCalibration:
    """The loop (module docstring). detector : gray (H, W) uint8 -> (corners (N, 2), ids (N, 2)) or
    None, with a ``relative`` attribute after each call (:func:`aicalib_tf.calib.workflow.make_detector`)."""

    def __init__(self, cfg: GuidedConfig, detector):
        self.cfg, self.detect = cfg, detector
        self.gate = MotionGate(cfg.gate_moving, cfg.gate_changed, cfg.gate_max_gap)
        self.image_size: tuple[int, int] | None = None
        self.examined, self.frames_seen = 0, 0
        self.skipped: Counter = Counter()
        self._s = _State()
        self._thumbs, self._n_thumbs = None, 0  # the examined frames' thumbnails: sum (float64), count
        self._circle = None  # the image circle as of the last refit

    @property
    def kept_frames(self) -> list[int]:
        """Frame indices of the kept views, in order."""
        return list(self._s.frames)

    @property
    def views(self) -> list[View]:
        """The kept views."""
        return list(self._s.views)

    @property
    def calibration(self) -> Calibration | None:
        """The running fit (None before the first)."""
        return self._s.cal

    def add(self, frame) -> Update:
        """Take one frame (:class:`aicalib_tf.sources.Frame` or (index, time_s, gray (H, W) uint8))."""
        index, time_s, gray = (frame.index, frame.time_s, frame.gray) if hasattr(frame, "gray") else frame
        self.frames_seen += 1
        size = (gray.shape[1], gray.shape[0])
        if self.image_size is None:
            self.image_size = size
        elif size != self.image_size:
            raise ValueError(f"frame {index} is {size[0]}x{size[1]}, the first was {self.image_size[0]}x{self.image_size[1]}")
        why = self.gate.check(gray) if self.cfg.gate and not self._s.done else ""
        if why or self._s.done:
            return self._update(index, time_s, False, None, None, False, why or "done")
        self.examined += 1
        small = thumbnail(gray) / (255.0 if gray.dtype == np.uint8 else 1.0)  # grey in [0, 1]
        self._thumbs = small.astype(np.float64) if self._thumbs is None else self._thumbs + small
        self._n_thumbs += 1
        hit = self.detect(gray)
        if hit is None:
            return self._update(index, time_s, True, None, None, False, "no board")
        corners, ids = np.asarray(hit[0], np.float64), np.asarray(hit[1])
        kept, reason = self._consider(index, gray, corners, ids, bool(getattr(self.detect, "relative", False)))
        return self._update(index, time_s, True, corners, ids, kept, reason)

    def _update(self, index, time_s, examined, corners, ids, kept, reason) -> Update:
        if not kept:
            self.skipped[reason.split(" (")[0].split(" of frame")[0]] += 1
        s = self._s
        if kept or s.missing is None:
            s.missing = tuple(missing(s.views, [tilt_of(p) for p in s.poses], self.image_size, self._circle))
        return Update(index, time_s, examined, corners, ids, kept, reason, s.guidance, s.missing, s.estimate, s.done)

    def _consider(self, index, gray, corners, ids, relative) -> tuple[bool, str]:
        cfg, s = self.cfg, self._s
        if len(ids) < cfg.min_corners or len(np.unique(ids[:, 0])) < 2 or len(np.unique(ids[:, 1])) < 2:
            return False, f"too few corners ({len(ids)})"
        b = blur_px(gray, corners, ids)
        if math.isfinite(b):
            med = float(np.median(s.blur[-30:])) if s.blur else b
            s.blur.append(b)
            if b > cfg.blur_min_px and b > cfg.blur_ratio * med:
                return False, f"blurred (edges {b:.1f} px wide, typical {med:.1f} px)"
        lens = lens_of(s.cal) if s.cal is not None else None
        pose = board_pose(corners, ids, cfg.square, self.image_size, lens)
        if pose is None:
            return False, "no pose for the board"
        sigmas = getattr(self.detect, "sigmas", None)  # the detection's per-corner σ (None: equal weights)
        view = View(f"frame{index:06d}", corners, ids, relative=relative,
                    sigmas=sigmas if sigmas is not None and len(sigmas) == len(corners) else None)
        dup = near_duplicate(pose, s.poses, self.image_size)
        if dup is not None:
            return False, f"near-duplicate of frame {s.frames[dup]}"
        why = self._worth(view, pose)
        if why.startswith("adds little"):
            if near_duplicate(pose, [p for _, p in s.pool], self.image_size) is None:  # a repeat adds nothing
                s.pool = [*s.pool[-(_POOL - 1):], (view, pose)]
            return False, why
        s.views.append(view)
        s.poses.append(pose)
        s.frames.append(index)
        s.since_fit += 1
        if s.cal is not None and s.information is not None:
            s.information = s.information + self._view_info(view, pose) / self._sigma2()
        if len(s.views) >= cfg.first_fit and (s.cal is None or s.since_fit >= cfg.refit_every
                                              or len(s.views) >= cfg.max_views):
            self._refit()
        return True, why

    def _worth(self, view: View, pose: Pose) -> str:
        """Why the view is kept ("adds little ..." when it is not)."""
        s, cfg = self._s, self.cfg
        if s.cal is None or s.information is None or s.basis is None:
            return "new view"
        before = coverage_counts(s.views, self.image_size, _CELLS) > 0
        after = before | (coverage_counts([view], self.image_size, _CELLS) > 0)
        fresh = int(after.sum() - before.sum())
        if fresh >= cfg.new_cells:
            return f"covers {fresh} new cells"
        G, ok = s.basis
        now = float(np.nanmean(sigma_from_basis(G, ok, np.linalg.pinv(s.information, hermitian=True))))
        new = np.linalg.pinv(s.information + self._view_info(view, pose) / self._sigma2(), hermitian=True)
        then = float(np.nanmean(sigma_from_basis(G, ok, new)))
        gain = (now - then) / now if now > 0 else 0.0
        if gain >= cfg.min_gain:
            return f"lowers the predicted uncertainty by {100 * gain:.0f}%"
        return f"adds little (predicted uncertainty -{100 * max(gain, 0):.1f}%)"

    def _sigma2(self) -> float:
        cal = self._s.cal
        return max(float(cal.rms) ** 2, 1e-4) if cal is not None else 1.0

    def _view_info(self, view: View, pose: Pose) -> np.ndarray:
        lens = lens_of(self._s.cal)
        P = board_points(view.ids, self.cfg.square) @ cv2.Rodrigues(pose.rvec)[0].T + pose.tvec
        return view_information(lens, P)

    def _refit(self) -> None:
        cfg, s = self.cfg, self._s
        models = [cfg.model] if cfg.model != "auto" else ([s.running] if s.running else ["plumb_bob", "equidistant"])
        fits = []
        for m in models:
            try:
                fits.append(fit_views(s.views, cfg.pattern, cfg.square, self.image_size, m,
                                      start=s.cal if s.cal is not None and s.cal.model == m else None,
                                      fix_k3=m != "equidistant", square_unit=cfg.square_unit,
                                      flex="off"))  # the running fit: the board's flex is the final fit's
            except (CalibrationError, np.linalg.LinAlgError):
                continue
        if not fits:
            return
        cal = min(fits, key=lambda c: c.rms)
        s.cal, s.running, s.since_fit = cal, cal.model, 0
        s.poses = [board_pose(v.corners, v.ids, cfg.square, self.image_size, lens_of(cal)) or p
                   for v, p in zip(s.views, s.poses)]
        self._circle = self.image_circle()  # the frames so far: nothing outside it is suggested or asked for
        covered = coverage_counts(s.views, self.image_size, (32, 24)).ravel() > 0
        _, G, ok = uncertainty_basis(cal, fit_mask=covered)
        s.basis = (G, ok & in_circle(self.image_size, (32, 24), self._circle))
        s.information = np.linalg.pinv(cal.covariance, hermitian=True)
        sigma = sigma_from_basis(G, ok, cal.covariance)
        sig = float(np.percentile(sigma[covered & np.isfinite(sigma)], 90)) if (covered & np.isfinite(sigma)).any() else math.inf
        frac = float(np.mean(coverage_counts(s.views, self.image_size, _CELLS) > 0))
        s.estimate = Estimate(cal.model, cal.K, cal.dist, cal.rms, len(s.views), sig, frac)
        distance = float(np.median([np.linalg.norm(p.tvec) for p in s.poses]))
        ranked = next_views(lens_of(cal), s.information, s.basis, distance, cfg.pattern, cfg.square, self._sigma2(),
                            self._circle)
        s.guidance = ranked[0] if ranked else None
        gone = missing(s.views, [tilt_of(p) for p in s.poses], self.image_size, self._circle)
        regions_left = any("covered" in g for g in gone)
        s.done = len(s.views) >= cfg.max_views or (
            sig <= cfg.target_px and len(s.views) >= cfg.min_views and not regions_left)

    def image_circle(self) -> ImageCircle | None:
        """The image circle of the examined frames (their thumbnails' mean), None when they fill the frame."""
        return self.image_circle_and_note()[0]

    def image_circle_and_note(self) -> tuple[ImageCircle | None, str]:
        """(:meth:`image_circle`, why none was found where the frames' corners are dark, else "")."""
        if not self._n_thumbs:
            return None, ""
        return find_image_circle(self._thumbs / self._n_thumbs, self.image_size)

    def _design(self) -> tuple[list[View], list[np.ndarray], np.ndarray, np.ndarray, list[int]]:
        """(candidates: the kept views and the pool, their information / σ² under the running fit,
        G, ok of the uncertainty basis over the cells they cover, the elimination order)."""
        s, cfg = self._s, self.cfg
        lens = lens_of(s.cal)
        cand, infos = [], []
        for v in [*s.views, *(v for v, _ in s.pool)]:
            pose = board_pose(v.corners, v.ids, cfg.square, self.image_size, lens)
            if pose is not None:
                cand.append(v)
                infos.append(self._view_info(v, pose) / self._sigma2())
        covered = coverage_counts(cand, self.image_size, (32, 24)).ravel() > 0
        _, G, ok = uncertainty_basis(s.cal, fit_mask=covered)
        ok = ok & covered
        return cand, infos, G, ok, elimination_order(infos, design_weight(G, ok), keep=min(cfg.min_views, len(cand)))

    def ranked_views(self) -> list[View]:
        """The candidates (kept and seen) from the most to the least useful: the first k are the
        design of k views (:mod:`aicalib_tf.guided.design`); the kept views before the first fit."""
        if self._s.cal is None:
            return list(self._s.views)
        cand, *_, order = self._design()
        return [cand[i] for i in reversed(order)]

    def final_views(self) -> list[View]:
        """The views to calibrate with: the design (:mod:`aicalib_tf.guided.design`) over the kept
        views and the candidates seen but not kept, as many as were kept, or more until it predicts
        the 90th percentile of the 1σ uncertainty over the covered cells at or below ``target_px``
        under the running fit, at most ``max_views``. Never fewer than were kept: the prediction is
        first-order and too hopeful for a few views. The kept views as they are before the first
        fit or when nothing else was seen."""
        s, cfg = self._s, self.cfg
        if s.cal is None or not s.pool:
            return list(s.views)
        cand, infos, G, ok, order = self._design()
        top = min(max(cfg.max_views, len(s.views)), len(cand))
        for k in range(min(max(cfg.min_views, len(s.views)), top), top + 1):
            pick = order[-k:]
            sigma = sigma_from_basis(G, ok, np.linalg.pinv(np.sum([infos[i] for i in pick], axis=0), hermitian=True))
            finite = sigma[np.isfinite(sigma)]
            if finite.size and float(np.percentile(finite, 90)) <= cfg.target_px:
                break
        return [cand[i] for i in sorted(pick)]

    def result(self, *, meta: dict | None = None, views: list[View] | None = None) -> Calibration:
        """The calibration of ``views`` (default :meth:`final_views`) with the configured model
        (``auto``: the full model choice). Raises CalibrationError with fewer than 3 views."""
        cfg = self.cfg
        views = self.final_views() if views is None else views
        if self.image_size is None or len(views) < 3:
            raise CalibrationError(f"{len(views)} views kept; need at least 3")
        circle, note = self.image_circle_and_note()
        meta = dict(meta or {}, **({"image_circle_note": note} if note else {}))
        return calibrate_camera(views, cfg.pattern, cfg.square, self.image_size, model=cfg.model,
                                square_unit=cfg.square_unit, meta=meta, image_circle=circle)
