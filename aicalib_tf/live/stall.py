"""Why the live loop stalls, and what would help: the page's answer when views stop coming.

A stall is :data:`STALL_S` seconds (and at least :data:`STALL_MIN_FRAMES` frames) without a kept
view while the session is not done: a looped video that shows the same path again, a board held
still, a board out of view. :class:`StallWatch` follows the updates of the guided loop
(:class:`~aicalib_tf.guided.session.Update`) and, during a stall, explains it from the reasons the
frames were skipped for since the last kept view (the most frequent one), for example::

    {"seconds": 31.0, "reason": "near-duplicate",
     "why": "no new poses for 31 s: the path repeats the poses already kept",
     "help": "try: hold the board at the top-right corner of the image, turned left about its vertical axis",
     "verdict": "uncertainty 0.124 px against the 0.1 px target, 12 views: Save keeps this calibration",
     "can_save": true}

``help`` is the guided loop's own next view (the one that lowers the predicted uncertainty most) or
what is still missing; ``verdict`` is where the calibration stands now, and ``can_save`` whether
Save can write it (at least 3 views). Times are the caller's clock, seconds.
"""

from __future__ import annotations

import math
from collections import Counter

from aicalib_tf.guided.save import MIN_SAVED_VIEWS

__all__ = ["StallWatch", "STALL_S", "STALL_MIN_FRAMES"]

STALL_S = 30.0  # seconds without a kept view before the page explains the stall
STALL_MIN_FRAMES = 10  # and at least this many frames handled in that time (a paused stream is not a stall)

# why the frames were skipped (the reason's first words) -> (why, in words; help when there is no next view)
_EXPLAIN = {
    "near-duplicate": ("no new poses for {s} s: the path repeats the poses already kept",
                       "move the board somewhere new"),
    "adds little": ("no new information for {s} s: the poses shown add little to the calibration",
                    "show the board in other places and tilts"),
    "no board": ("no board seen for {s} s", "bring the whole board into view, flat and well lit"),
    "too few corners": ("only part of the board seen for {s} s", "show the whole board, inside the image"),
    "blurred": ("the board is blurred for {s} s", "move the board more slowly, or add light"),
    "no pose for the board": ("no pose found for the board for {s} s", "hold the whole board flat in view"),
}


def _family(reason: str) -> str:
    """A skip reason's family: "near-duplicate of frame 12" -> "near-duplicate"."""
    for key in _EXPLAIN:
        if reason.startswith(key):
            return key
    return reason.split(" (")[0]


class StallWatch:
    """Follows the loop's updates; :meth:`note` returns the stall explanation (module docstring) or None.

    target_px : the session's target (px). seconds, min_frames : the stall rule.
    """

    def __init__(self, target_px: float, seconds: float = STALL_S, min_frames: int = STALL_MIN_FRAMES):
        self.target_px, self.seconds, self.min_frames = float(target_px), float(seconds), int(min_frames)
        self.since: float | None = None  # when the last view was kept (or the first frame came)
        self.reasons: Counter = Counter()  # why the frames since were not kept

    def note(self, update, views: int, now: float) -> dict | None:
        """Take one update (``views``: the views kept so far; ``now``: s); the stall explanation or None."""
        if self.since is None or update.kept or update.done:
            self.since, self.reasons = now, Counter()
            return None
        self.reasons[_family(update.reason)] += 1
        idle = now - self.since
        if idle < self.seconds or sum(self.reasons.values()) < self.min_frames:
            return None
        return self.explain(update, views, idle)

    def explain(self, update, views: int, idle: float) -> dict:
        """The explanation of a stall of ``idle`` seconds at ``update``."""
        reason = self.reasons.most_common(1)[0][0]
        why, fallback = _EXPLAIN.get(reason, ("no view kept for {s} s (" + reason + ")", None))
        why = why.format(s=f"{idle:.0f}")
        est, missing = update.estimate, list(update.missing)
        if est is not None and est.sigma_px <= self.target_px and missing:
            why += f"; the uncertainty meets the target, but {missing[0]}"
        nxt = update.guidance.text.removeprefix("next: ") if update.guidance is not None else None
        if reason in ("near-duplicate", "adds little") or nxt is None:
            help_ = f"try: {nxt}" if nxt else (missing[0] if missing else fallback)
        else:
            help_ = fallback
        if est is None:
            verdict = f"no fit yet ({views} views kept)"
        elif not math.isfinite(est.sigma_px):
            verdict = f"uncertainty not known yet (the boards cover too little of the image), {views} views"
        else:
            verdict = f"uncertainty {est.sigma_px:.3f} px against the {self.target_px:g} px target, {views} views"
        can_save = views >= MIN_SAVED_VIEWS
        if can_save:
            verdict += ": Save keeps this calibration"
        return {"seconds": round(idle, 1), "reason": reason, "why": why, "help": help_, "verdict": verdict,
                "can_save": can_save}
