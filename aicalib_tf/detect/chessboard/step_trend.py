"""Where a bent grid line goes next: its steps' complex ratio, and that ratio's trend (pure numpy).

Towards a fisheye's rim a board's grid lines turn steadily while their steps shrink, faster the
nearer the rim: a close-up board's squares can shrink from 40 px at the lens' centre to a few px at
85–100° off its axis. :func:`turned` predicts a line's next point from its last three points (the
last step turned and scaled as it was from the one before) or four (that ratio itself changed as it
last changed). :mod:`aicalib_tf.detect.chessboard.grid_growth` grows bent lines with it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["TREND_LIMIT", "TREND_TURN", "turned"]

TREND_LIMIT = 1.4  # a line's step ratio changes by at most this factor (or its inverse) per step
TREND_TURN = 0.3  # radians: and its turn per step changes by at most this much per step


def turned(p1: np.ndarray, p2: np.ndarray, p3: np.ndarray, p4: np.ndarray | None = None) -> np.ndarray:
    """The next points (M, 2) of lines ending p3, p2, p1 (each (M, 2) px), each step the last one
    turned and scaled as the last one was from the one before (a constant complex ratio of steps);
    with ``p4`` (M, 2), the point before p3, the ratio itself changed as it last changed (its trend).

    Towards a fisheye's rim a line's steps shrink by a similar fraction each step while its direction
    turns steadily; a quadratic (constant second difference) overshoots there, the more the faster
    they shrink. On the true corners of data_gen's ``fisheye_closeup`` boards the ratio misses the
    next corner by more than ``grid_growth.TOLERANCE`` of a step 125 times in 12600, the quadratic
    144 times. Where the squares shrink 3× or more across the board (``closeup_laws`` close-ups,
    80 boards, true corners jittered by σ 0.1 px), the ratio falls faster the nearer the rim: its
    trend misses 55 times in 4224 predictions on equidistant lenses where the constant ratio misses
    172 (DS and EUCM: 54 in 3456 against 149), and another corner lies within the tolerance of it
    58 times against 173 (66 against 153). Noise on short steps makes up changes of the ratio:
    the change is held to ``TREND_LIMIT`` and ``TREND_TURN`` (at σ 0.25 px the trend misses as often
    as the constant ratio, 170 against 184, and still lands near another corner a third as often).
    """
    a, b = p1 - p2, p2 - p3
    re, im = _ratio(a, b)
    if p4 is not None:  # the ratio's change from the step before: (a / b) / (b / c), held to TREND_LIMIT
        cre, cim = _ratio(b, p3 - p4)
        den = cre * cre + cim * cim
        qre, qim = (re * cre + im * cim) / den, (im * cre - re * cim) / den
        mag = np.sqrt(qre * qre + qim * qim)
        held = np.clip(mag, 1.0 / TREND_LIMIT, TREND_LIMIT) / np.maximum(mag, 1e-12)
        qre, qim = qre * held, qim * held
        ang = np.arctan2(qim, qre)
        turn = np.clip(ang, -TREND_TURN, TREND_TURN) - ang
        qre, qim = qre * np.cos(turn) - qim * np.sin(turn), qre * np.sin(turn) + qim * np.cos(turn)
        re, im = re * qre - im * qim, re * qim + im * qre
    # r · a in complex numbers: a's length and turn relative to b, applied once more to a
    return p1 + np.stack([re * a[:, 0] - im * a[:, 1], re * a[:, 1] + im * a[:, 0]], axis=1)


def _ratio(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The complex ratio a / b of steps (M, 2) px, as (real (M,), imaginary (M,))."""
    den = (b * b).sum(axis=1)
    return (a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]) / den, (a[:, 1] * b[:, 0] - a[:, 0] * b[:, 1]) / den
