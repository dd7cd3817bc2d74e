"""A board whose outer ring is squeezed and darkened at a fisheye's rim: its last corners placed.

Close to a circular fisheye, a board's outer squares are squeezed to a few px towards the image
circle, blurred more and darkened almost to black. Their corners still hold a saddle, but the ring
test that confirms a grid's predictions (:func:`aicalib_tf.detect.corners.junctions.proposer`)
fails there: the ring's amplitude falls with the light, and the light's gradient across the ring
makes it look like a T-junction. The grid then holds every corner of the pattern but a few on its
outer ring, and is no full board.

:func:`complete_rim` places those few corners where the grid's lines lead: each is extrapolated
from the two or three corners inwards of it along every grid line through it (by the ratio of the
lines' last steps, as squares shrink towards the rim), refined by the saddle fit in a window that
fits the corner's smallest step (windows down to 2 px where that fit fails: the squeezed direction;
started again from points about the prediction where no window holds at it), and kept only when
the fit stays within a third of that step, the ring about it keeps ``RIM_GATE`` of a typical
corner's amplitude, and it is no other corner's point. A board's corner is predicted by its cell's
parallelogram (its two neighbours on the ring and the diagonal one inside). A grid missing more
than ``MAX_MISSING`` corners, or any inside its outer ring, is left as it is. Where the rim's
corner is too faint for the noise, or its outer squares are sheared into slivers, the fit can stop
2–5 px short of the junction, on an edge or on a sliver's ridge: such a point's saddle is far
flatter than its neighbours' (:func:`flat_placed`), and the grid is then left as it is. Started
far from a board corner whose squares shrink faster than the lines lead, it can stop on the noise
inside one dark outer square: the ring about it of half the usual radius, which a junction's own
four squares fill, then keeps a fraction of its neighbours' amplitude (:func:`faint_placed`). Where
the fit slid along an edge of its light square, that ring's four arcs between the grid's lines do
not alternate light and dark (:func:`quadrant_split`). These tests also hold for the grid's own
corners that no network point marks (the ring test proposed them): a rim corner the grid holds
1 px off on an edge leads the completion astray.

A full board claims every corner in view. Where an object in front cuts the board, the grid may
hold points on the object's edge and miss a corner beside it, which this completion would then
place: the board is taken only when each of its corners, placed or not, shows an X-junction like
its neighbours' on the grid (:func:`unlike_neighbours`: ring amplitude and lopsidedness against
theirs, which the rim's darkening, blur and squeeze change slowly and an object's edge abruptly).
"""

from __future__ import annotations

import cv2
import numpy as np

from aicalib_tf.detect.chessboard.board_order import full_board
from aicalib_tf.detect.chessboard.grid import Grid
from aicalib_tf.detect.corners.junctions import nearest_spacing, ring_symmetry
from aicalib_tf.detect.corners.refine import Smoothed, refine_windowed, window_radius
from aicalib_tf.detect.corners.saddle import saddle_fit_matrix

__all__ = ["complete_rim", "rim_board", "unlike_neighbours", "flat_placed", "saddle_sharpness", "grid_directions",
           "neighbour_median", "faint_placed", "quadrant_split", "MAX_MISSING", "SHIFT", "PLACED_FLAT", "HALF_RING"]

MAX_MISSING = 3  # most corners of the outer ring placed here
SHIFT = 0.34  # of the smallest local step: the farthest the saddle fit may move a prediction
RIM_GATE = 0.1  # of a typical corner's ring amplitude: the least a placed corner keeps (the light falls to black)
RATIO = (0.3, 1.25)  # bounds of a line's step ratio used to extrapolate its next step
AMP_RANGE = (0.45, 1.4)  # a corner's ring amplitude over its neighbours' median: the least and the most
ODD_RATIO = 6.0  # a corner's ring asymmetry (of its amplitude) over its neighbours' median: the most ...
ODD_FLOOR = 0.05  # ... that median taken as at least this (sharp, evenly lit corners leave almost none)
HALF_RING = 0.5  # of unlike_neighbours' ring radius: the ring faint_placed reads, inside a corner's own squares
PLACED_FLAT = 0.5  # ln: a placed corner whose saddle_sharpness is this far under its neighbours' median is no junction
SHARP_RADIUS = 3  # px: the largest window radius of saddle_sharpness (a 7×7 window)
_NEIGHBOURS = [(di, dj) for di in (-1, 0, 1) for dj in (-1, 0, 1) if (di, dj) != (0, 0)]


def _along(cells: dict, i: int, j: int, di: int, dj: int):
    """(prediction (2,), its step px) for (i, j) from the corners inwards of it along (di, dj), or None."""
    a, b, c = (cells.get((i + k * di, j + k * dj)) for k in (1, 2, 3))
    if a is None or b is None:
        return None
    step = a - b
    ratio = 1.0
    if c is not None:
        prev = float(np.hypot(*(b - c)))
        ratio = float(np.clip(np.hypot(*step) / max(prev, 1e-9), *RATIO))
    step = step * ratio
    return a + step, float(np.hypot(*step))


def _edge_steps(cells: dict, i: int, j: int) -> list[float]:
    """Distances (px) between the outer-ring neighbours of (i, j) present on both sides of it, halved."""
    out = []
    for di, dj in ((1, 0), (0, 1)):
        p, q = cells.get((i - di, j - dj)), cells.get((i + di, j + dj))
        if p is not None and q is not None:
            out.append(0.5 * float(np.hypot(*(p - q))))
    return out


def _predict(cells: dict, i: int, j: int, shape: tuple[int, int]):
    """(prediction (2,), smallest local step px) for a missing outer-ring position, or None."""
    a, b = shape
    preds, steps = [], []
    for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        got = _along(cells, i, j, di, dj)  # positions outside the grid are never in cells
        if got is not None:
            preds.append(got[0])
            steps.append(got[1])
    if not preds:
        return None
    pred = np.mean(preds, axis=0)
    closure = [cells[(i + di, j)] + cells[(i, j + dj)] - cells[(i + di, j + dj)]
               for di in (1, -1) for dj in (1, -1)
               if all(k in cells for k in ((i + di, j), (i, j + dj), (i + di, j + dj)))]
    if closure:  # the cell's parallelogram: where the lines' steps shrink fastest, nearer than they lead
        pred = np.mean(closure, axis=0)
    return pred, min(steps + _edge_steps(cells, i, j))


def _place(cells: dict, pred: np.ndarray, step: float, smoothed: Smoothed, ring_image: np.ndarray,
           ref_amp: float):
    """(2,) px: the corner the saddle fit finds at ``pred`` with the smallest local ``step`` px, or None.

    Windows from the step's down to 2 px until the fit holds within ``SHIFT``·step; where none does
    from ``pred``, the fit starts again from 16 points about it (``_starts``); kept when its ring
    (0.3 step) keeps ``RIM_GATE``·``ref_amp`` and no point of ``cells`` is within half a step."""
    h, w = ring_image.shape
    if not (step >= 2.0 and 1 <= pred[0] <= w - 2 and 1 <= pred[1] <= h - 2):
        return None
    q = _saddle(smoothed, pred[None], pred, step)
    q = _saddle(smoothed, _starts(pred, step), pred, step) if q is None else q
    if q is None:
        return None
    amp, _ = ring_symmetry(ring_image, q[None].astype(np.float64), np.array([max(1.5, 0.3 * step)]))
    others = np.array(list(cells.values()))
    if amp[0] < RIM_GATE * ref_amp or np.min(np.hypot(*(others - q).T)) < 0.5 * step:
        return None
    return q.astype(np.float64)


def _saddle(smoothed: Smoothed, starts: np.ndarray, pred: np.ndarray, step: float):
    """(2,) px: the saddle fit from ``starts`` (M, 2) px that ends nearest ``pred`` within ``SHIFT``·step,
    in the largest window (from the step's down to 2 px: the squeezed direction may be narrower
    than the smallest step says) where any does; or None."""
    for radius in range(int(window_radius(np.array([step]))[0]), 1, -1):
        q, ok = refine_windowed(smoothed, starts, np.full(len(starts), radius / 0.45), restarts=False)
        d = np.hypot(*(q - pred).T)
        ok &= d <= SHIFT * step
        if ok.any():
            return q[np.flatnonzero(ok)[np.argmin(d[ok])]]
    return None


def _starts(pred: np.ndarray, step: float) -> np.ndarray:
    """(16, 2) px: points 1 and 2 window radii from ``pred`` in 8 directions. A rim corner where the
    lines' steps shrink faster than their last ratio says lies up to about a fifth of a step from
    the prediction, beyond the reach of a fit window that fits its squares."""
    r = float(window_radius(np.array([step]))[0])
    ang = np.arange(8) * np.pi / 4
    ring = np.stack([np.cos(ang), np.sin(ang)], 1)
    return np.concatenate([pred + r * ring, pred + 2 * r * ring])


def grid_directions(points: np.ndarray) -> np.ndarray:
    """(4, a, b, 2) px: each corner's step to its neighbour along +i, +j, -i, -j of a full grid ``points``
    (a, b, 2), a ≥ 2 and b ≥ 2; at the grid's edge the missing step is the opposite one mirrored."""
    a, b = points.shape[:2]
    big = np.full((a + 2, b + 2, 2), np.nan)
    big[1:-1, 1:-1] = points
    out = np.stack([big[1 + di:a + 1 + di, 1 + dj:b + 1 + dj] - points
                    for di, dj in ((1, 0), (0, 1), (-1, 0), (0, -1))])
    for k in range(4):
        out[k] = np.where(np.isnan(out[k]), -out[(k + 2) % 4], out[k])
    return out


def neighbour_median(values: np.ndarray) -> np.ndarray:
    """(a, b): the median of each grid position's (up to 8) neighbours' ``values`` (a, b)."""
    a, b = values.shape
    pad = np.full((a + 2, b + 2), np.nan)
    pad[1:-1, 1:-1] = values
    return np.nanmedian([pad[1 + di:a + 1 + di, 1 + dj:b + 1 + dj] for di, dj in _NEIGHBOURS], axis=0)


def unlike_neighbours(points: np.ndarray, ring_image: np.ndarray) -> np.ndarray:
    """(a, b) bool: the corners of a full grid that show no X-junction like their neighbours'.

    points : (a, b, 2) px, every position of the grid. ring_image : (H, W) float32, smoothed
    (σ = 1 px). On a ring of 0.3 of each corner's smallest step to a neighbour along a grid line
    (at least 1.5 px), :func:`aicalib_tf.detect.corners.junctions.ring_symmetry` gives its amplitude
    and its asymmetry, read as a share of the amplitude. Vignetting, blur and the squeeze towards a
    fisheye's rim change both slowly across the board, so each corner is compared with the median of
    its (up to 8) neighbours on the grid: its amplitude must lie within ``AMP_RANGE`` of theirs and
    its asymmetry share within ``ODD_RATIO`` times theirs (at least ``ODD_FLOOR``). A point where an
    object in front cuts the board is a junction of three regions (object, dark and light square) or
    the object's own edge: its ring is lopsided where its neighbours' are not, or much fainter or
    stronger than theirs, on rings of any radius. A board corner (a corner of the grid) has three
    squares beyond it that no step measures, squeezed at a fisheye's rim to a fraction of the inner ones
    (a 202° lens's board corner 89° off axis: a ring of 0.3 of its inner step crosses them, asymmetry
    0.96, 0.13 on half that ring): its own asymmetry is the lesser of the two rings' (its neighbours'
    median stays that of the full rings). Other outer-ring corners keep the full ring: on half of it an
    EUCM board's rim corner 2.3 px off its junction passed.
    """
    a, b = points.shape[:2]
    d = grid_directions(points)
    radius = np.maximum(1.5, 0.3 * np.hypot(d[..., 0], d[..., 1]).min(axis=0)).ravel()
    amp, asym = ring_symmetry(ring_image, points.reshape(-1, 2), radius)
    amp, odd = amp.reshape(a, b), (asym / np.maximum(amp, 1e-12)).reshape(a, b)
    near_amp, near_odd = neighbour_median(amp), neighbour_median(odd)
    edge = np.zeros((a, b), bool)
    edge[[0, 0, -1, -1], [0, -1, 0, -1]] = True  # a board corner: three of its four squares lie beyond the grid
    half_amp, half_asym = ring_symmetry(ring_image, points[edge], np.maximum(1.5, 0.5 * radius.reshape(a, b)[edge]))
    odd[edge] = np.minimum(odd[edge], half_asym / np.maximum(half_amp, 1e-12))  # outer squares narrower than inner
    return (amp < AMP_RANGE[0] * near_amp) | (amp > AMP_RANGE[1] * near_amp) | (odd > ODD_RATIO * np.maximum(near_odd, ODD_FLOOR))


def saddle_sharpness(gray: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N,) ln(√|det H| / contrast) of each corner's saddle: H the Hessian (grey / px²) of the saddle fit's quadratic
    (:func:`aicalib_tf.detect.corners.saddle.saddle_fit_matrix`) on the unsmoothed ``gray`` (H, W) float32 about
    ``points`` (N, 2) px (bilinear samples, the window radius of the corner spacing, at most ``SHARP_RADIUS``),
    the contrast the Gaussian-weighted standard deviation of the window's point-symmetric part. An X-junction's
    quadratic curves both ways; a point off the junction along one of its edges sees an edge, one curvature near
    0, and the position along that edge is set by the noise (a blurred, darkened board corner: 2.5 px off)."""
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    radius = np.minimum(window_radius(nearest_spacing(pts.astype(np.float32))), SHARP_RADIUS) if len(pts) > 1 \
        else np.full(len(pts), SHARP_RADIUS)
    out = np.zeros(len(pts))
    g = np.asarray(gray, np.float32)
    for r in sorted(set(radius.tolist())):
        sel = np.flatnonzero(radius == r)
        offsets, fit = saddle_fit_matrix(int(r))
        at = (pts[sel, None, :] + offsets[None].astype(np.float64)).astype(np.float32)  # (K, M, 2)
        vals = cv2.remap(g, at[..., 0], at[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).astype(np.float64)
        a, b, c = (vals @ fit[:3].T).T  # f = a x² + b xy + c y² + ...
        s = r / 2.0 + 0.5
        w = np.exp(-(offsets.astype(np.float64) ** 2).sum(axis=1) / (2 * s * s))
        w /= w.sum()
        even = 0.5 * (vals + vals[:, ::-1])  # offsets run row-major, so offset −o is the mirrored index
        even -= (even * w).sum(axis=1, keepdims=True)
        contrast = np.sqrt((w * even * even).sum(axis=1))
        out[sel] = 0.5 * np.log(np.maximum(np.abs(4 * a * c - b * b), 1e-24)) - np.log(np.maximum(contrast, 1e-12))
    return out


def _as_grid(grid: Grid, cells: dict) -> Grid:
    """A grid of ``cells`` {(i, j): (2,) px}; ``grid``'s own points keep their index, the others get -1."""
    index = {(int(i), int(j)): int(k) for (i, j), k in zip(grid.ij, grid.index)}
    keys = list(cells)
    return Grid(index=np.array([index.get(key, -1) for key in keys]), ij=np.array(keys),
                points=np.array([cells[key] for key in keys]))


def complete_rim(grid: Grid, shape: tuple[int, int], smoothed: Smoothed, ring_image: np.ndarray,
                 ref_amp: float) -> Grid | None:
    """``grid`` with the missing corners of its outer ring placed, or None when it cannot be.

    shape : (a, b), the grid's full extent in (i, j) positions (the pattern's, either way round).
    smoothed : the image's :class:`~aicalib_tf.detect.corners.refine.Smoothed`. ring_image : (H, W)
    float32, smoothed (σ = 1 px). ref_amp : a typical corner's ring amplitude
    (:func:`aicalib_tf.detect.corners.junctions.typical_amplitude`).
    Returns a grid with every position of ``shape`` filled (placed corners get index -1), or None
    when the grid's extent is not ``shape``, more than ``MAX_MISSING`` corners are missing, one is
    inside the outer ring, a corner's fit fails, a corner of the full grid is
    :func:`unlike_neighbours` (an object in front), or a placed one, or one of the grid's without a
    candidate (index -1), is :func:`flat_placed` or :func:`faint_placed`, or splits no quadrants
    (:func:`quadrant_split` 0 or less).
    """
    a, b = shape
    if grid.shape != (a, b) or len(grid) >= a * b or a * b - len(grid) > MAX_MISSING or min(a, b) < 4:
        return None
    cells = {(int(i), int(j)): np.asarray(p, np.float64) for (i, j), p in zip(grid.ij, grid.points)}
    missing = [(i, j) for i in range(a) for j in range(b) if (i, j) not in cells]
    if any(0 < i < a - 1 and 0 < j < b - 1 for i, j in missing):
        return None
    placed = {}
    for i, j in missing:
        got = _predict(cells, i, j, shape)  # from the grid's own corners: never one placed here
        q = None if got is None else _place({**cells, **placed}, *got, smoothed, ring_image, ref_amp)
        if q is None:
            return None
        placed[(i, j)] = q
    full = {**cells, **placed}
    points = np.array([[full[(i, j)] for j in range(b)] for i in range(a)])
    if unlike_neighbours(points, ring_image).any():
        return None  # an object in front: a full board would claim corners it hides
    unsure = missing + [(int(i), int(j)) for (i, j), k in zip(grid.ij, grid.index) if k < 0]  # no network point
    if flat_placed(points, smoothed.gray, unsure).any():
        return None  # a fit left on an edge or a ridge short of the junction
    if faint_placed(points, ring_image, unsure).any():
        return None  # a fit left on the noise inside one square, short of the junction
    if (quadrant_split(points, ring_image, unsure) <= 0.0).any():
        return None  # no X-junction: an outer square darkened to black leaves an L-corner, and the fit slides along its edge
    return _as_grid(grid, full)


def faint_placed(points: np.ndarray, ring_image: np.ndarray, placed: list) -> np.ndarray:
    """(len(placed),) bool: the placed positions [(i, j)] of a full grid ``points`` (a, b, 2) px whose ring of
    ``HALF_RING`` of :func:`unlike_neighbours`' radius on ``ring_image`` (H, W) keeps less than ``AMP_RANGE[0]`` of
    the median amplitude of their neighbours' on the grid, on rings of the same share of their own steps.
    That ring stays inside the corner's own four squares (a rim corner's outer squares are squeezed to a
    fraction of its inner step): a saddle fit left on the noise inside one dark square, short of the junction,
    keeps the junction's edges on the wider ring but almost nothing on this one (a rim corner 16 px off: 0.67 of
    its neighbours on the wide ring, 0.2 on this; the rim completion's true corners of closeup_families: 0.5 or more)."""
    if not placed:
        return np.zeros(0, bool)
    a, b = points.shape[:2]
    d = grid_directions(points)
    radius = np.maximum(1.5, HALF_RING * 0.3 * np.hypot(d[..., 0], d[..., 1]).min(axis=0)).ravel()
    amp = ring_symmetry(ring_image, points.reshape(-1, 2), radius)[0].reshape(a, b)
    near = neighbour_median(amp)
    ii, jj = np.array(placed).T
    return amp[ii, jj] < AMP_RANGE[0] * near[ii, jj]


def quadrant_split(points: np.ndarray, ring_image: np.ndarray, placed: list) -> np.ndarray:
    """(len(placed),): how clearly each placed position [(i, j)] of a full grid ``points`` (a, b, 2) px is an
    X-junction on ``ring_image`` (H, W): on the ring of :func:`faint_placed`, the mean grey of each of the four
    arcs between the grid's lines through it (:func:`grid_directions`), the lighter opposite pair's darker arc
    less the darker pair's lighter one, over the two pairs' difference of means. About 1 at a clean junction,
    0 or less where one of the four squares is not the colour the order says: where the light falls to black
    at a fisheye's rim, a board corner's outer square goes dark, the junction is an L-corner with no saddle,
    and the fit slides along its edge (a rim corner 3.9 px off: -0.21; every other corner of that board 0.44
    or more)."""
    if not placed:
        return np.zeros(0)
    d = grid_directions(points)
    k = 48
    ang = np.arange(k) * (2 * np.pi / k)
    ring = np.stack([np.cos(ang), np.sin(ang)], 1)
    out = np.zeros(len(placed))
    for n, (i, j) in enumerate(placed):
        r = max(1.5, HALF_RING * 0.3 * float(np.hypot(*d[:, i, j].T).min()))
        xy = (points[i, j] + r * ring).astype(np.float32)
        grey = cv2.remap(ring_image, xy[:, :1], xy[:, 1:], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).ravel()
        lines = np.sort(np.arctan2(d[:, i, j, 1], d[:, i, j, 0]) % (2 * np.pi))
        arc = np.searchsorted(lines, ang, side="right") % 4  # arc t lies between lines t - 1 and t (mod 4)
        means = np.array([grey[arc == t].mean() if (arc == t).any() else np.nan for t in range(4)])
        pairs = means[[0, 2]], means[[1, 3]]
        light, dark = pairs if pairs[0].sum() > pairs[1].sum() else pairs[::-1]
        spread = light.mean() - dark.mean()
        out[n] = (light.min() - dark.max()) / spread if spread > 0 else -1.0
    return np.nan_to_num(out, nan=-1.0)


def flat_placed(points: np.ndarray, gray: np.ndarray, placed: list) -> np.ndarray:
    """(len(placed),) bool: the placed positions [(i, j)] of a full grid ``points`` (a, b, 2) px whose
    :func:`saddle_sharpness` on ``gray`` (H, W) is more than ``PLACED_FLAT`` under the median of their
    neighbours' on the grid. A saddle fit left on a square's edge, or on the ridge of a sliver of light
    square between two dark ones where the outer squares are sheared at the rim, sees one curvature near 0,
    and the place along it is set by the noise (2–5 px off; on the rim completion's true corners of
    closeup-eq, -unified and the closeup_families benchmark, within 0.1 of their neighbours)."""
    if not placed:
        return np.zeros(0, bool)
    a, b = points.shape[:2]
    sharp = saddle_sharpness(gray, points.reshape(-1, 2)).reshape(a, b)
    near = neighbour_median(sharp)
    ii, jj = np.array(placed).T
    return sharp[ii, jj] < near[ii, jj] - PLACED_FLAT


def rim_board(grids: list[Grid], scores: np.ndarray, pattern_size: tuple[int, int], smoothed: Smoothed,
              ring_image: np.ndarray, ref_amp: float):
    """The first of ``grids`` that is the full board once its outer ring's missing corners are placed
    (:func:`complete_rim`), as :func:`aicalib_tf.detect.chessboard.board_order.full_board` returns it, or None.

    scores : (N,) weights of the candidate points the grids' indices refer to (a placed corner gets 0).
    """
    cols, rows = pattern_size
    for grid in grids:
        for shape in dict.fromkeys(((cols, rows), (rows, cols))):
            full = complete_rim(grid, shape, smoothed, ring_image, ref_amp)
            board = None if full is None else full_board(full, scores, pattern_size, ring_image)
            if board is not None:
                return board
    return None
