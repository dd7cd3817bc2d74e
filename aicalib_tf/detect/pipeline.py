"""Chessboard detection with the CNN: image -> ordered board (the CLI is ``python -m aicalib_tf.detect``).

Pipeline: CNN corner weights -> peaks (:mod:`aicalib_tf.cnn.inference`) -> saddle-point refinement
on the original image (:mod:`aicalib_tf.detect.corners.refine`, :mod:`aicalib_tf.detect.corners.junctions`) -> grid assembly
(:mod:`aicalib_tf.detect.chessboard.grid`) -> ordered board (:mod:`aicalib_tf.detect.chessboard.board_order`), or a partial board
(:mod:`aicalib_tf.detect.chessboard.partial`, placed by :mod:`aicalib_tf.detect.chessboard.placement` on the lattice model of
:mod:`aicalib_tf.detect.chessboard.lattice`).

Order of a full board (OpenCV's, row-major: index = r·cols + c). A board read from the front
keeps its handedness, so only its rotations are ambiguous: 180°, and 90° too for a square
pattern. They are resolved like ``cv2.findChessboardCorners`` (measured on data_gen boards):

* cols + rows odd (e.g. 9x6): the board's colours tell 180° apart. Corner 0 is the one whose
  outer diagonal square is black (the square beyond it, away from corners 1 and ``cols``). It is
  decided by a vote of all inner squares, so it never samples outside the board.
* otherwise (both even or both odd): the reading whose last row starts lowest in the image
  relative to corner 0 (largest y[(rows−1)·cols] − y[0]). OpenCV reverses its order when that
  difference is negative; the two agree whenever one reading has it positive and the other negative.
* square patterns: of the four rotations, the one with the largest (x[cols−1] − x[0]) +
  (y[(rows−1)·cols] − y[0]): rows run most nearly left to right and top to bottom.

Partial boards (``pattern_size`` given, no full board found; ``complete=False``). A board cut by
the frame or hidden in part by an object in front comes back with the corners that are seen, in
row-major order of their ids, each id the corner's (col, row) on the full board, correct up to
the board's symmetry as above. Ids are only returned when the image decides them; otherwise no
board (a miss rather than a wrong id). The grid is first grown by partly visible lines and across
gaps (corners found where the lattice predicts them, by saddle fit and ring test), then every
placement of it on the pattern (a 90° turn keeping handedness, and a shift) is checked against
three kinds of evidence:

* extent: the grid fits inside the pattern; spanning all ``cols`` (or ``rows``) corners of an axis
  fixes that axis;
* borders: beyond the board's outermost corner line lies one more row of squares, then white
  paper. A grid side whose next line, extrapolated, has alternating squares before it and white
  paper just beyond it all along (and is not mostly hidden) is the pattern's outermost line on
  that side;
* colours: the grid's black squares must be the board's black squares (board square (c, r), the
  one between corners (c−1, r−1) and (c, r), is black when c + r is even, as on a full board).
  This settles 180° when cols + rows is odd, as for full boards; the colours must be readable then.

The ids are returned when the placements left agree up to the board's symmetry; where that
leaves a choice (cols + rows even), the reading whose rows run most nearly downwards (square
patterns: rows right and columns down) is taken, the full-board geometric rule applied to the
mean steps. The pattern's missing corners are then looked for where the placed ones predict them
(a second time with a 2 px window and a small ring, for corners beside an object in front),
corners off their neighbours' lattice by more than ``MAX_RESIDUAL`` of a step are dropped (at most
a tenth of them, else no board), so are corners so near the frame that their refinement window
leaves the image by more than 0.3 of its radius (pulled towards the frame), and a board with
X-junctions one step outside the pattern is dropped. If every corner is found, the board is complete and ordered by the full-board rules.
A view of one corner of a non-square board alone (two sides cut by the frame) cannot be placed:
the visible sides could be the long or the short ones. When no 3×3 seed starts a grid at all,
the candidates are assembled again from 3×2 seeds (:func:`aicalib_tf.detect.chessboard.grid.assemble_grids` with
``strips``, growing by candidates only; the partial board then grows as above): strips of a board
2 corners wide, between objects or around one, hold no 3×3 block.

With ``pattern_size``, quick passes come first (:func:`aicalib_tf.detect.pyramid.quick_scales`): the
image at one or two scales coarser than the coarsest below (640×480 at 320×240; 1920×1080 at
240×135, then 480×270), for a full board only, its corners refined on the full image as below
(none may move more than :func:`aicalib_tf.detect.pyramid.quick_shift`), with the model's ``quick`` network
when it has one (:func:`aicalib_tf.cnn.model.load_model`) and one smoothing for every window. The search
goes on as below where they find none (small squares, a board cut or hidden), at 1.2–1.5× the time.

Large images (longer side ≥ 1600 px) are searched coarse to fine (:mod:`aicalib_tf.detect.pyramid`):
first at a reduced scale (block means, the longer side kept ≥ 800 px), the corners found there
refined again on the full image (a board any of whose corners that refinement cannot place is
not trusted); a finer scale is tried only when no complete board was found,
and the partial board with the most corners over all scales is returned otherwise. Without
``pattern_size`` every scale is searched and the largest grid wins (the coarsest of equal ones):
at a coarse scale a tilted board's far squares can fall below the CNN's reach and leave a complete
grid of its near rows only. A 1920×1080
image costs about a quarter as much; a board whose squares are too small for the coarse scale is
found at full size.

Thin boards (``pattern_size`` given): at the edge of a wide-angle lens a board's squares can be
2–4 px thick, and the CNN finds few of their corners. When the full-size search finds no full
board but assembles a grid with corners under 6 px apart, the region the board could cover is
enlarged 3× (at most 240,000 px enlarged) and searched again (:mod:`aicalib_tf.detect.chessboard.zoom`). A complete
board found there is returned, so is a partial one with more than half the pattern's corners;
otherwise partial boards are looked for at full size too, and the one with more corners is
returned. Boards close to a fisheye: with no full board assembled, the candidates are assembled again
with ``bend`` (:func:`aicalib_tf.detect.chessboard.grid.assemble_grids`); only a full board from it counts. There the
network's weak points (``WEAK``) confirm saddles the ring test fails at the dark rim (``proposer``'s ``bent``).
A grid of either assembly holding the pattern but up to 3 corners of its outer ring gets them placed
(:func:`aicalib_tf.detect.chessboard.rim.rim_board`), kept only when every corner shows an X-junction like its
neighbours' (an object in front of the board does not). A grid holding half the pattern or more but no full
board is searched again on its region with the shading divided out (:mod:`aicalib_tf.detect.chessboard.shading`:
the rim's darkened outer rings); only a complete board counts. Steeply tilted boards (55–80° from facing the
camera; their lines meet at 8–20°, sharper than the network's junctions): with no full board at full size, a
sheared partial board's lattice, else a sliver of coherent texture, is warped to square axes and searched again
(:mod:`aicalib_tf.detect.chessboard.unshear`; a board spanning the pattern there with up to 5 corners missing gets
them where its homography predicts a junction, :mod:`aicalib_tf.detect.chessboard.unshear_fill`); only a complete board counts, mapped back and refined on its rectified view. Any full board with a corner on an object's edge
(:func:`aicalib_tf.detect.chessboard.occlusion.object_in_front`: sectors out of the board's alternation
and a ring unlike its neighbours') is passed over, on its scale and again at full size. A full board's corners
off the smooth grid of their neighbours (:func:`aicalib_tf.detect.chessboard.smooth_grid.without_off_grid`: over
1.5 px and 0.1 of a step from their lines' cubic interpolation, a point on an object's edge) are left out, and so are
its corners whose squares have the colours of the other parity (:func:`aicalib_tf.detect.corners.contrast.without_reversed`:
a rim corner placed a square off): it comes back a partial board.

Without ``pattern_size``, the largest grid with every corner found is returned, complete, its
size taken as the pattern (columns counted along the grid direction nearer the image's x axis,
so a 9×6 board held landscape is (9, 6) and turned on its side (6, 9)); ids are relative to that
grid, in the full-board order. A grid with positions missing (a line cut by the frame that kept a few
corners, say) counts by its largest filled rectangle (:func:`aicalib_tf.detect.chessboard.grid.full_subgrid`), so a
few extra corners never hide it, after corners off their neighbours' lattice are dropped as for partial
boards. :func:`aicalib_tf.detect.dropin.find_chessboard_corners` reports full boards only, like OpenCV.
"""

from __future__ import annotations

from dataclasses import replace
from functools import partial as bind

import numpy as np

from aicalib_tf.cnn.spec import DETECTOR_NETWORK
from aicalib_tf.detect.chessboard.board_order import full_board, order_full_board
from aicalib_tf.detect.corners.sigma import with_sigmas
from aicalib_tf.detect.corners.contrast import without_reversed
from aicalib_tf.detect.detection import NO_CANDIDATES, NO_GRID, NO_MATCH, REASONS, UNDECIDED, Detection, from_charuco
from aicalib_tf.detect.chessboard.grid import MIN_CORNERS, Grid, assemble_grids, full_subgrid
from aicalib_tf.detect.corners.junctions import dedupe, nearest_spacing, proposer, typical_amplitude
from aicalib_tf.detect.chessboard.lattice import drop_outliers
from aicalib_tf.detect.chessboard.occlusion import object_in_front, object_in_front_at
from aicalib_tf.detect.chessboard.partial import partial_board, relative_board
from aicalib_tf.detect.chessboard.rim import rim_board
from aicalib_tf.detect.chessboard.smooth_grid import without_off_grid
from aicalib_tf.detect.chessboard.shading import flattened_look
from aicalib_tf.detect.pyramid import Frame, boards_coarse_to_fine, quick_scales, quick_shift, refine_full, scales, to_full
from aicalib_tf.detect.corners.refine import Smoothed, polish_in_region, refine_candidates
from aicalib_tf.detect.chessboard.unshear import refine_rectified, second_look as unshear_look, thin_not_sheared
from aicalib_tf.detect.chessboard.zoom import zoomed_look
from aicalib_tf.io import read_image

__all__ = ["Detection", "detect_corners", "detect_charuco", "order_full_board", "refined_points"]


_DEFAULT_MODEL = None
MAX_CANDIDATES = 3000  # a 20x15 board has 300 corners; more candidates are clutter
WEAK = 0.5  # of the threshold: network points this weak confirm a corner where the bent grid predicts one
UNSHEAR_SHIFT = 1.0  # px: an unsheared board's corner moved further by its refinement (rectified view) keeps its place
RING_SIGMA = 1.0  # px: the smoothing of the ring tests' image; a quick pass refines its windows on it too


def _default_model():
    global _DEFAULT_MODEL
    if _DEFAULT_MODEL is None:
        from aicalib_tf.cnn.model import load_model
        _DEFAULT_MODEL = load_model(DETECTOR_NETWORK)
    return _DEFAULT_MODEL


def _own_grids(grids: list[Grid]) -> list[Grid]:
    """Without a pattern: each grid's filled part, largest first.

    A grid with every position filled is kept as it is. In any other grid, corners off their
    neighbours' lattice (:func:`aicalib_tf.detect.chessboard.lattice.drop_outliers`, as for partial boards; a grid
    that would lose more than a tenth of them is dropped) leave holes, then the largest filled rectangle is kept
    (:func:`aicalib_tf.detect.chessboard.grid.full_subgrid`): a line cut by the frame that kept a few corners never
    hides the rest of the grid, and a corner pulled by an object in front does not come back with it.
    """
    out = []
    for grid in grids:
        a, b = grid.shape
        if len(grid) == a * b:  # filled already
            out.append(grid)
            continue
        kept = drop_outliers(grid.ij, grid.points, grid.index)
        if kept is not None:
            sub = full_subgrid(Grid(index=kept[2], ij=kept[0], points=kept[1]))
            if sub is not None:
                out.append(sub)
    return sorted(out, key=len, reverse=True)


def detect_corners(image, pattern_size: tuple[int, int] | None = None, *, model=None,
                   threshold: float = 0.5, relative: bool = False) -> Detection:
    """Find a chessboard's inner corners.

    image : path or array (see :func:`aicalib_tf.io.load_image`).
    pattern_size : (cols, rows) inner corners; None returns the largest complete grid found, with
        ids relative to it. A ChArUco board (a :class:`~aicalib_tf.geometry.charuco.CharucoBoard` or
        its ``charuco:...`` description) returns the largest such board found (:func:`detect_charuco`),
        each corner's id decided by its markers.
    model : a loaded corner model (default: the shipped ``models/default.keras``).
    threshold : CNN corner weight above which a peak is a candidate.
    relative : with ``pattern_size``, a grid whose place on the pattern the image leaves open (a
        board larger than the frame, no edge in view) comes back with ids relative to it and
        ``relative=True`` (:func:`aicalib_tf.detect.chessboard.partial.relative_board`), rather than not at all.
        Enough for calibration, where each view has its own pose; not a detection of the pattern.
    Returns a :class:`Detection`; ``found`` is False when no board is there. With ``pattern_size``,
    a board partly out of frame or hidden is returned with ``complete=False`` when the image
    decides its ids (module docstring), and not at all otherwise (unless ``relative``).
    """
    frame = Frame(read_image(image))  # converted to float grey only where needed: a region, a reduced scale
    w, h = frame.size
    if _charuco_board(pattern_size) is not None:  # a ChArUco board: the largest one found
        board, refused = _charuco_board(pattern_size), {}
        found = detect_charuco(frame.raw, [board], model=model, threshold=threshold, refused=refused)
        return with_sigmas(from_charuco(found[0] if found else None, board, (w, h), refused.get(board)), frame)
    if pattern_size is not None:
        from aicalib_tf.geometry.pattern import check_pattern

        check_pattern(pattern_size)
    model = model if model is not None else _default_model()
    best, reason = None, REASONS[0]
    quick = quick_scales(w, h) if pattern_size is not None else []
    for f in quick + scales(w, h):
        look = bind(_second_looks, frame.gray, pattern_size, model, threshold) if f == 1 and pattern_size is not None else None
        net = (getattr(model, "quick", None) or model) if f in quick else model  # the quick passes' own network
        det = _detect_at(frame.reduced(f), pattern_size, net, threshold, second_look=look, relative=relative, full_only=f in quick)
        det = _unsheared_clear(frame, pattern_size, model, threshold, det) if look and not (det.complete or relative) else det
        if det.found and f > 1:
            corners, ok = refine_full(frame, to_full(det.corners, f), max_shift=quick_shift(f) if f in quick else 2.0)
            if not ok.all():  # a corner left at its coarse place may be px off: try the finer scales
                reason = reason if f in quick else max(reason, NO_MATCH, key=REASONS.index)
                continue
            det = replace(det, corners=corners, image_size=(w, h))
            if det.complete and pattern_size is not None and object_in_front_at(frame.region, (w, h), corners, pattern_size):
                continue  # at full size, a corner on an object's edge: the finer scales
        if det.complete and pattern_size is not None:  # less its corners off the grid of their neighbours
            return without_reversed(without_off_grid(with_sigmas(_polished(det, frame), frame), NO_MATCH), frame)
        if f in quick:  # a quick pass counts only with a complete board
            continue
        if not det.found:
            reason = max(reason, det.reason, key=REASONS.index)
        # without a pattern every scale is searched: a coarse scale can miss a board's smallest
        # squares and come back with a complete sub-grid of it
        if best is None or (best.relative and not det.relative and det.found) or (
                det.relative <= best.relative and len(det.corners) > len(best.corners)):
            best = det  # a board with fixed ids beats one with relative ids
    if best is None:  # every scale's board was refused on the full image (a corner off its place or on an edge)
        best, reason = Detection(np.zeros((0, 2), np.float32), np.zeros((0, 2), np.int32), np.zeros(0, np.float32),
                                 pattern_size, False, (w, h)), max(reason, NO_MATCH, key=REASONS.index)
    return with_sigmas(_polished(replace(best, image_size=(w, h), reason="" if best.found else reason), frame), frame)


def _polished(det: Detection, frame: Frame) -> Detection:
    """A found board with its corners polished (:func:`aicalib_tf.detect.corners.refine.polish_in_region`)."""
    return replace(det, corners=polish_in_region(frame.region, frame.size, det.corners, det.ids)) if det.found else det


def _zoomed(gray: np.ndarray, pattern_size: tuple[int, int], model, threshold: float, seen: Grid,
            others: np.ndarray | None = None) -> Detection | None:
    """The search again on the region of a thin grid ``seen``, enlarged (:func:`aicalib_tf.detect.chessboard.zoom.zoomed_look`)."""
    return zoomed_look(gray, pattern_size, seen, others, bind(_detect_at, pattern_size=pattern_size, model=model, threshold=threshold))


def _second_looks(gray: np.ndarray, pattern_size: tuple[int, int], model, threshold: float, seen: Grid,
                  others: np.ndarray, largest: Grid) -> Detection | None:
    """:func:`_zoomed`'s detection when complete, else a complete board on the ``largest`` grid's region with the shading
    divided out (:func:`aicalib_tf.detect.chessboard.shading.flattened_look`), else :func:`_zoomed`'s: ``_detect_at``'s second look."""
    from aicalib_tf.cnn.inference import weak_corner_points

    look = _zoomed(gray, pattern_size, model, threshold, seen, others)
    full = bind(_detect_at, pattern_size=pattern_size, model=model, threshold=threshold, partial_above=sum(pattern_size) ** 2)
    marks = bind(weak_corner_points, model, threshold=threshold, weak=WEAK * threshold)
    return look if look is not None and look.complete else (flattened_look(gray, pattern_size, largest, others, full, marks) or look)


def _unsheared_clear(frame: Frame, pattern_size: tuple[int, int], model, threshold: float, seen: Detection) -> Detection:
    """:func:`_unsheared` on the full-size ``frame``; a board looked at for a thin square alone (a close-up's squeezed
    rim, :func:`~aicalib_tf.detect.chessboard.unshear.thin_not_sheared`) is kept only where no corner lies on an
    object's edge (:func:`~aicalib_tf.detect.chessboard.occlusion.object_in_front_at`: a corner filled under an object,
    say), else ``seen``. A sheared board's thin junctions are beyond that test."""
    det = _unsheared(frame.gray, pattern_size, model, threshold, seen)
    if det is not seen and thin_not_sheared(seen.ids if seen.found else None, seen.corners if seen.found else None) \
            and object_in_front_at(frame.region, frame.size, det.corners, pattern_size):
        return seen
    return det


def _unsheared(gray: np.ndarray, pattern_size: tuple[int, int], model, threshold: float, seen: Detection) -> Detection:
    """The search again on a steeply tilted board's region, warped to square axes (:mod:`aicalib_tf.detect.chessboard.unshear`),
    when the full-size search ``seen`` found no full board: a complete board, its corners mapped back to gray (H, W)
    float32 and refined on the board's rectified view of it where they can be, else ``seen``."""
    got = unshear_look(gray, pattern_size, lambda img: _detect_at(img, pattern_size, model, threshold, relative=True),
                       seen.ids if seen.found else None, seen.corners if seen.found else None, refine_full)
    if got is None:
        return seen
    corners = refine_rectified(gray, got[0], pattern_size, bind(refine_full, max_shift=UNSHEAR_SHIFT))
    if sum(pattern_size) % 2 == 0:  # the geometric rule is the image's, not the warp's (colours: the warp's)
        corners = order_full_board(corners, pattern_size, gray)
    return replace(got[1], corners=corners.astype(np.float32), image_size=gray.shape[::-1])


def refined_points(model, gray: np.ndarray, threshold: float = 0.5, *, smoothed: Smoothed | None = None,
                   min_points: int = 0, weak: float | None = None):
    """The detector's corner candidates: the CNN's points, refined on the image, duplicates merged.

    gray : (H, W) float32 or uint8. The network's points (:func:`aicalib_tf.cnn.inference.corner_points`,
    at most ``MAX_CANDIDATES``, strongest first) are moved to the saddle point of the image around
    them (:func:`aicalib_tf.detect.corners.refine.refine_candidates`, a window fitting the local spacing); points
    whose fit fails are dropped, and of points that meet within 1.5 px the strongest stays.
    smoothed : the image's :class:`~aicalib_tf.detect.corners.refine.Smoothed` when the caller has it.
    min_points : fewer network points than this give no candidates (nothing is refined).
    weak : also return ``weak_points() -> (K, 2)`` px, the network's points from ``weak``·threshold up to it.
    Returns points (N, 2) float32 (x, y) px and weights (N,) float32, strongest first (and weak_points).
    """
    from aicalib_tf.cnn.inference import weak_corner_points

    pts, scores, lower = weak_corner_points(model, gray, threshold, (weak or 0.0) * threshold)
    pts, scores = pts[:MAX_CANDIDATES], scores[:MAX_CANDIDATES]  # strongest first; bounds the N² steps
    keep = np.zeros(0, int)
    if len(pts) >= max(min_points, 1):
        smoothed = Smoothed(np.asarray(gray, np.float32)) if smoothed is None else smoothed
        pts, ok = refine_candidates(smoothed, pts, nearest_spacing(pts))
        pts, scores = pts[ok], scores[ok]
        keep = dedupe(pts, scores)
    out = pts[keep].astype(np.float32).reshape(-1, 2), scores[keep].astype(np.float32)
    return out if weak is None else (*out, lower)


def _clear_full_board(grid: Grid, scores: np.ndarray, pattern_size: tuple[int, int], smooth: np.ndarray):
    """:func:`full_board`'s board, or None where one of its corners is an object's edge
    (:func:`aicalib_tf.detect.chessboard.occlusion.object_in_front`): the assembly then goes on."""
    board = full_board(grid, scores, pattern_size, smooth)
    return None if board is None or object_in_front(board[0], pattern_size, smooth) else board


def _detect_at(gray: np.ndarray, pattern_size: tuple[int, int] | None, model, threshold: float,
               second_look=None, partial_above: int = 0, relative: bool = False, full_only: bool = False) -> Detection:
    """:func:`detect_corners` on one scale: gray (H, W) float32, pattern already checked.

    second_look : None, or ``look(grid, candidates, largest) -> Detection | None``, asked with the first
    grid, the candidate points and the largest grid, bent ones too, when no full board is found (:func:`_second_looks`). Its
    board is returned when complete or with more than half the pattern's corners (the partial search
    here is the costly part of a thin board's time); else the larger of it and this scale's partial
    board. partial_above : partial boards are only looked for when the largest
    grid has more corners than this. relative : as :func:`detect_corners`. full_only : a full board or nothing.
    """
    h, w = gray.shape
    empty = Detection(np.zeros((0, 2), np.float32), np.zeros((0, 2), np.int32), np.zeros(0, np.float32),
                      pattern_size, False, (w, h), NO_CANDIDATES)
    if h < 8 or w < 8:
        return empty
    smoothed = Smoothed(gray, RING_SIGMA if full_only else None)  # a quick pass: one smoothing for all
    refined, scores, weak = refined_points(model, gray, threshold, smoothed=smoothed, min_points=MIN_CORNERS, weak=WEAK)
    if len(refined) == 0:
        return empty
    smooth = smoothed.sigma(RING_SIGMA)
    ref_amp = typical_amplitude(smooth, refined, MIN_CORNERS) if len(refined) >= MIN_CORNERS else 0.0
    propose = proposer(smoothed, smooth, ref_amp, weak=weak) if len(refined) >= MIN_CORNERS else None
    if pattern_size is None:
        grids = _own_grids(assemble_grids(refined, scores, gray=smooth, propose=propose))
        for grid in grids:
            board = full_board(grid, scores, None, smooth)
            if board is not None:
                return Detection(*board, True, (w, h))
        return replace(empty, reason=NO_MATCH if grids else NO_GRID)
    board = None

    def is_board(grid: Grid) -> bool:  # the first grid assembled that is the full board ends the assembly
        nonlocal board
        board = _clear_full_board(grid, scores, pattern_size, smooth)
        return board is not None

    # grow one step past the pattern so that a bigger board shows itself and is rejected
    limit = max(pattern_size) + 1
    grids = assemble_grids(refined, scores, gray=smooth, propose=propose, limit=limit, stop=is_board)
    if board is None and not full_only:  # bent strongly (close to a fisheye): a full board or nothing
        bent = assemble_grids(refined, scores, gray=smooth, propose=propose and propose.bent, limit=limit, stop=is_board,
                              bend=True)
        board = board or rim_board(grids + bent, scores, pattern_size, smoothed, smooth, ref_amp)
    if board is not None or full_only:  # full_only: the quick pass, a full board or nothing
        return Detection(*board, True, (w, h)) if board else replace(empty, reason=NO_MATCH if grids else NO_GRID)
    if not grids:  # no 3×3 block anywhere: strips 2 corners wide (between objects, say)
        grids = assemble_grids(refined, scores, gray=smooth, limit=limit, strips=True)
    look = second_look(grids[0], refined, max(grids + bent, key=len)) if second_look is not None and grids else None
    if look is not None and (look.complete or 2 * len(look.corners) > pattern_size[0] * pattern_size[1]):
        return look
    if not grids or len(grids[0]) <= partial_above:
        return replace(empty, reason=NO_MATCH if grids else NO_GRID)
    board, undecided = partial_board(grids, scores, pattern_size, smooth, (w, h), propose)
    rel = relative_board(grids[0], scores, pattern_size, (w, h), propose) if board is None and undecided and relative else None
    if board is not None or rel is not None:
        det = Detection(*(rel or board[:3]), tuple(pattern_size), board is not None and board[3], (w, h), relative=rel is not None)
    else:
        det = replace(empty, reason=UNDECIDED if undecided else NO_MATCH)
    return look if look is not None and len(look.corners) > len(det.corners) else det


def _charuco_board(board):
    """The :class:`~aicalib_tf.geometry.charuco.CharucoBoard` that ``board`` is or describes, else None."""
    from aicalib_tf.geometry.charuco import CharucoBoard, is_charuco, parse_board

    if isinstance(board, CharucoBoard):
        return board
    return parse_board(board) if is_charuco(board) else None


def detect_charuco(image, boards, *, model=None, threshold: float = 0.5, refused: dict | None = None) -> list:
    """Every ChArUco board of ``boards`` in the image (:mod:`aicalib_tf.detect.charuco.detector`).

    image : path or array (the image gate). boards : CharucoBoards or their descriptions
    (``charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100``). The corners are the chessboard
    stages' (CNN, saddle refinement, grid assembly), their ids come from the markers. Returns a list of
    :class:`~aicalib_tf.detect.charuco.detector.CharucoDetection`, largest first (empty when none). refused : a dict
    that receives {board: why} for a board whose markers contradict it (:mod:`aicalib_tf.detect.charuco.layout`).
    """
    from aicalib_tf.detect.charuco.detector import detect_charuco_boards

    frame = Frame(read_image(image))  # a large photo: coarse to fine (pyramid.charuco_scales), refined on the full image
    boards = [_charuco_board(b) for b in ([boards] if isinstance(boards, str) or not hasattr(boards, "__iter__") else boards)]
    if not boards or any(b is None for b in boards):
        raise ValueError("boards must be ChArUco boards or descriptions such as charuco:11x8,square=30mm,marker=22mm,dict=DICT_5X5_100")
    model = model if model is not None else _default_model()

    def search(gray):
        def chessboard_search(pattern):  # the chessboard search's grid, ids relative to it allowed
            det = detect_corners(gray, pattern, model=model, threshold=threshold, relative=True)
            return [(det.ids.astype(np.int64), det.corners.astype(np.float64))] if det.found else []
        return detect_charuco_boards(gray, boards, model, threshold, more_lattices=chessboard_search, refused=refused)
    return boards_coarse_to_fine(frame, search)

