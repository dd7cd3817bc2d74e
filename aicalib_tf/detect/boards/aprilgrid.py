"""Find a Kalibr AprilGrid (:mod:`aicalib_tf.geometry.aprilgrid`) in an image: tags decoded by
OpenCV's aruco, each tag corner placed by the project's saddle fit.

OpenCV's ``cv2.aruco.ArucoDetector`` (the grid's AprilTag dictionary, two-bit borders) decodes the
tags. Tags of ids outside the grid, or seen twice, are dropped. Which of a tag's corners OpenCV
reports first depends on how the codes were drawn: with two tags or more, the quarter turn whose
corners a homography from the board fits best decides (one tag alone keeps
:data:`~aicalib_tf.geometry.aprilgrid.PRINT_ROTATION`). Each corner is an X-junction: the tag's
black border and the small square at its corner meet there, in a clean square of side
min(gap, two bits) on the board. OpenCV's quad corners lie up to that far off, pushed out along the
tag's diagonals where its contour runs into the corner squares, so a coarse saddle fit in a wide
window starts where a homography over the tag and its neighbours puts the corner (else at the
quad's corner), and :func:`aicalib_tf.detect.corners.refine.refine_windowed` finishes in a window inside the
clean square. Under a steep shear a quad's corner can lie beyond that fit's reach: a corner whose
fit failed is fitted again from where the placed corners of its tag and the tags next to it put it
(a least-squares homography, :func:`local_homography`). A tag OpenCV did not decode (steeply sheared,
its contour merged with the corner squares) next to placed corners is seen square-on through that
homography, its surroundings painted white (:func:`rectified_tag`), and decoded there by OpenCV
again; where it reads the tag's own id, the quad it finds, brought back to the image, is placed as a
decoded tag's, round after round. A corner whose fits fail, or whose window leaves the image, is
dropped. Corner ids are lattice positions (the geometry module's docstring), so a partial view keeps
its ids.
``refine="opencv"`` returns OpenCV's own sub-pixel corners instead, for comparison.

Coordinates are (x, y) px with the centre of pixel (0, 0) at (0.0, 0.0).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from aicalib_tf.detect.corners.refine import SQUEEZED_WINDOW, Smoothed, refine_saddle, refine_windowed, window_radius
from aicalib_tf.geometry.aprilgrid import BORDER_BITS, PRINT_ROTATION, AprilGrid, dictionary

__all__ = ["AprilGridDetection", "detect_aprilgrid", "detect_corners_aprilgrid", "decode_tags", "clean_window_px",
           "predicted_corners", "local_homography", "neighbour_predictions", "rectified_tag", "make_detector",
           "REFINES"]

REFINES = ("saddle", "opencv", "none")
_OPENCV_REFINE = {"saddle": "CORNER_REFINE_NONE", "none": "CORNER_REFINE_NONE", "opencv": "CORNER_REFINE_SUBPIX",
                  "apriltag": "CORNER_REFINE_APRILTAG"}


@dataclass(frozen=True)
class AprilGridDetection:
    """corners (N, 2) float64 px; ids (N, 2) int64 lattice (col, row); tags (K,) int64 tag ids
    seen; rotation: the quarter turn used; why: "" or why nothing was found."""

    corners: np.ndarray
    ids: np.ndarray
    tags: np.ndarray
    rotation: int
    why: str = ""


def _detector(family: str, refine: str):
    p = cv2.aruco.DetectorParameters()
    p.markerBorderBits = BORDER_BITS
    p.cornerRefinementMethod = getattr(cv2.aruco, _OPENCV_REFINE[refine])
    return cv2.aruco.ArucoDetector(dictionary(family), p)


def decode_tags(gray: np.ndarray, board: AprilGrid, refine: str = "none") -> tuple[np.ndarray, np.ndarray]:
    """Tags of ``board`` in the uint8 image: ids (K,) int64 and corners (K, 4, 2) float64 px, in
    OpenCV's order; ids outside the grid and ids seen twice are left out. refine: a key of
    ``_OPENCV_REFINE`` (OpenCV's own corner refinement)."""
    corners, ids, _ = _detector(board.family, refine).detectMarkers(gray)
    if ids is None or not len(ids):
        return np.zeros(0, np.int64), np.zeros((0, 4, 2))
    ids = ids.ravel().astype(np.int64)
    quads = np.concatenate([np.asarray(c, np.float64).reshape(1, 4, 2) for c in corners])
    uniq, counts = np.unique(ids, return_counts=True)
    lo, hi = board.first_id, board.first_id + board.tags[0] * board.tags[1]
    keep = (ids >= lo) & (ids < hi) & np.isin(ids, uniq[counts == 1])
    return ids[keep], quads[keep]


def _rotation(board: AprilGrid, ids: np.ndarray, quads: np.ndarray) -> int:
    """The quarter turn of the corner order that a homography from the board fits best."""
    if len(ids) < 2:
        return PRINT_ROTATION
    img = quads.reshape(-1, 2)
    best, best_err = PRINT_ROTATION, np.inf
    for r in range(4):
        obj = board.tag_corner_ids(ids, r).reshape(-1, 2).astype(np.float64)
        H, _ = cv2.findHomography(obj, img, 0)
        if H is None:
            continue
        proj = cv2.perspectiveTransform(obj.reshape(-1, 1, 2), H).reshape(-1, 2)
        err = float(np.mean(np.sum((proj - img) ** 2, axis=1)))
        if err < best_err:
            best, best_err = r, err
    return best


def clean_window_px(board: AprilGrid, quads: np.ndarray) -> np.ndarray:
    """(K, 4) px: the side, in the image, of the clean square at each tag corner: min(gap, two bits)
    on the board, times the tag's smaller height at that corner (a foreshortened or sheared tag's
    clean square is narrower across than along)."""
    e1 = np.roll(quads, -1, axis=1) - quads
    e2 = np.roll(quads, 1, axis=1) - quads
    cross = np.abs(e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0])
    height = cross / np.maximum(np.maximum(np.linalg.norm(e1, axis=2), np.linalg.norm(e2, axis=2)), 1e-9)
    return height * min(float(board.spacing), BORDER_BITS / (board.bits + 2 * BORDER_BITS))


PULL_IN_RADIUS = 12  # px, the widest window of the first, coarse saddle fit
PULL_IN_WINDOWS = (0.6, 0.8, 0.45)  # its windows' half-sizes over the clean square, tried in turn
PULL_IN_REACH = 0.6  # clean squares: how far from the predicted (or the quad's) corner its result may lie


def predicted_corners(board: AprilGrid, ids: np.ndarray, quads: np.ndarray, rotation: int) -> np.ndarray:
    """(K, 4, 2) px: each tag's corners where a homography fitted to its quad and those of the tags
    next to it (least squares) puts them, or the quad where no neighbour was decoded. A quad pushed
    out along its diagonals (the contour running into the corner squares) is pushed out about its
    own centre; a homography over several tags keeps their centres and spacing, not that."""
    lattice = board.tag_corner_ids(ids, rotation).astype(np.float64)
    cells = board.tag_cell(ids)
    out = quads.astype(np.float64).copy()
    for k in range(len(ids)):
        near = np.flatnonzero(np.max(np.abs(cells - cells[k]), axis=1) <= 1)
        if len(near) < 2:
            continue
        H, _ = cv2.findHomography(lattice[near].reshape(-1, 2), quads[near].reshape(-1, 2), 0)
        if H is not None:
            out[k] = cv2.perspectiveTransform(lattice[k].reshape(-1, 1, 2), H).reshape(4, 2)
    return out


def _pull_in(smoothed: Smoothed, quads: np.ndarray, predicted: np.ndarray, spacing: np.ndarray):
    """A coarse saddle fit in a wide window (up to ``PULL_IN_RADIUS``) about the clean square.

    OpenCV's quad corners can lie up to a clean square off, outwards along the diagonal, where the
    tag's contour runs into its corner squares: the fit starts at the corner the tag and its
    neighbours predict (:func:`predicted_corners`), then where that fails at the quad's corner,
    each with the windows ``PULL_IN_WINDOWS`` (fractions of the clean square) in turn; it must end
    within ``PULL_IN_REACH`` clean squares of the prediction or of the quad's corner.
    quads, predicted (K, 4, 2), spacing (K, 4) px. Returns (4K, 2) float64 and ok (4K,) bool.
    """
    pred = predicted.reshape(-1, 2)
    sp = spacing.reshape(-1)
    quad = quads.reshape(-1, 2).astype(np.float64)
    out, ok = pred.copy(), np.zeros(len(pred), bool)
    for start in (pred, quad):
        for frac in PULL_IN_WINDOWS:
            todo = np.flatnonzero(~ok)
            radius = np.clip(np.round(frac * sp[todo]), 2, PULL_IN_RADIUS).astype(int)
            for r in sorted(set(radius.tolist())):
                sel = todo[radius == r]
                got, good = refine_saddle(smoothed[int(r)], start[sel], sigma=0.0, radius=int(r), iterations=15,
                                          max_shift=2.0 * r)
                near = np.minimum(np.linalg.norm(got - pred[sel], axis=1), np.linalg.norm(got - quad[sel], axis=1))
                good &= near <= PULL_IN_REACH * sp[sel] + 1.0
                out[sel[good]], ok[sel[good]] = got[good], True
    return out, ok


NEIGHBOURS_MIN = 6  # refined corners (of the tag and the tags next to it) a second-pass prediction needs
NEIGHBOUR_REACH = 0.3  # clean squares (+ 0.5 px): how far the second pass's fit may end from that prediction


def local_homography(tag_cell: np.ndarray, lattice: np.ndarray, pts: np.ndarray, ok: np.ndarray, cell,
                     least: int = NEIGHBOURS_MIN):
    """(3, 3) lattice-to-image homography (least squares) through the placed corners (``ok``) of the
    tags at most one cell from ``cell`` (col, row), or None where fewer than ``least``, or only one row
    or column of them, are placed. tag_cell, lattice (N, 2) int per corner; pts (N, 2) px."""
    near = np.flatnonzero(ok & (np.max(np.abs(tag_cell - np.asarray(cell)), axis=1) <= 1))
    obj = lattice[near].astype(np.float64)
    if len(near) < least or len(np.unique(obj[:, 0])) < 2 or len(np.unique(obj[:, 1])) < 2:
        return None
    H, _ = cv2.findHomography(obj, pts[near], 0)
    return H


def _apply(H: np.ndarray, lattice: np.ndarray) -> np.ndarray:
    """(N, 2) px where the homography H puts lattice points (N, 2)."""
    return cv2.perspectiveTransform(np.asarray(lattice, np.float64).reshape(-1, 1, 2), H).reshape(-1, 2)


def neighbour_predictions(cells: np.ndarray, lattice: np.ndarray, pts: np.ndarray, ok: np.ndarray,
                          which: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where :func:`local_homography` about each corner's tag puts the corners ``which`` (M,) int:
    (M, 2) px and has (M,) bool (False where it has no homography).
    cells (K, 2) tag cells; lattice (4K, 2) corner ids; pts (4K, 2) px; ok (4K,) bool."""
    tag_cell = np.repeat(np.asarray(cells), 4, axis=0)
    out, has = np.zeros((len(which), 2)), np.zeros(len(which), bool)
    for n, i in enumerate(which):
        H = local_homography(tag_cell, lattice, pts, ok, tag_cell[i])
        if H is not None:
            out[n], has[n] = _apply(H, lattice[i : i + 1])[0], True
    return out, has


def _fit_near(smoothed: Smoothed, start: np.ndarray, spacing: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`refine_windowed` from ``start`` (N, 2) px, ending within ``NEIGHBOUR_REACH`` clean squares
    (``spacing`` (N,) px) + 0.5 px of it: the window sized from the clean square, then, where that fails,
    ``SQUEEZED_WINDOW`` times narrower. Returns (N, 2) float64 and ok (N,) bool."""
    out, ok = np.asarray(start, np.float64).copy(), np.zeros(len(start), bool)
    reach = NEIGHBOUR_REACH * spacing + 0.5
    for scale in (1.0, SQUEEZED_WINDOW):
        todo = np.flatnonzero(~ok)
        if not len(todo):
            break
        got, good = refine_windowed(smoothed, out[todo], scale * spacing[todo], max_shift=reach[todo])
        out[todo[good]], ok[todo[good]] = got[good], True
    return out, ok


def _from_neighbours(smoothed: Smoothed, cells, lattice, pts: np.ndarray, ok: np.ndarray, spacing: np.ndarray):
    """A second pass for the corners whose first fit failed (:func:`_pull_in` and
    :func:`refine_windowed` started from OpenCV's quad, which on a steeply sheared corner lies
    further out than the pull-in's reach): each starts where its placed neighbours put it
    (:func:`neighbour_predictions`, a small fraction of a clean square off) (:func:`_fit_near`).
    Returns pts (4K, 2) float64, ok (4K,)."""
    redo = np.flatnonzero(~ok)
    start, has = neighbour_predictions(cells, lattice, pts, ok, redo)
    redo, start = redo[has], start[has]
    pts, ok = pts.copy(), ok.copy()
    got, good = _fit_near(smoothed, start, spacing[redo])
    pts[redo[good]], ok[redo[good]] = got[good], True
    return pts, ok


GROW_FROM = 4  # placed corners (one whole tag) from which a tag beside them is looked for
RECTIFIED_CELL = 8  # px a bit cell in the square-on view of a tag handed back to OpenCV's decoder


def rectified_tag(gray: np.ndarray, H: np.ndarray, board: AprilGrid, tag_id: int,
                  cell_px: int = RECTIFIED_CELL) -> tuple[np.ndarray, np.ndarray]:
    """Tag ``tag_id`` seen square-on through the lattice-to-image homography ``H``: ((S, S) uint8,
    ``cell_px`` px a bit cell, on white two cells wide, and the (3, 3) homography from its px to the
    image's). What lies around the tag (the corner squares touching it, whose contours OpenCV merges
    with the tag's under a steep shear) is painted white."""
    n = board.bits + 2 * BORDER_BITS
    corners = board.tag_corner_ids(tag_id).astype(np.float64)
    lo, side = corners.min(axis=0), corners.max(axis=0) - corners.min(axis=0)
    m, size = 2 * cell_px, (n + 4) * cell_px
    scale = side / (n * cell_px)  # lattice units a patch px; the tag spans patch px edges m - 0.5 .. m + n·cell - 0.5
    to_image = H @ np.array([[scale[0], 0, lo[0] - (m - 0.5) * scale[0]], [0, scale[1], lo[1] - (m - 0.5) * scale[1]],
                             [0, 0, 1]])
    out = cv2.warpPerspective(gray, to_image, (size, size), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                              borderValue=255)
    inner = out[m: m + n * cell_px, m: m + n * cell_px].copy()
    out[:] = 255
    out[m: m + n * cell_px, m: m + n * cell_px] = inner
    return out, to_image


def _read_square_on(u8: np.ndarray, decoder, board: AprilGrid, H: np.ndarray, tag_id: int, ids: np.ndarray):
    """The image quad (4, 2) px of tag ``tag_id`` (its corners' lattice ids ``ids`` (4, 2), in that order),
    where OpenCV's decoder reads that id in its square-on view (:func:`rectified_tag`); else None. Its
    quad's corners, brought back to the image, are matched to the nearest of the corners ``H`` predicts:
    they hold where the prediction, extrapolated from the neighbours, drifts (a lens's distortion)."""
    patch, to_image = rectified_tag(u8, H, board, tag_id)
    found, got, _ = decoder.detectMarkers(patch)
    if got is None or len(got) != 1 or int(np.ravel(got)[0]) != tag_id:
        return None
    quad = _apply(to_image, np.asarray(found[0], np.float64).reshape(4, 2))
    nearest = np.argmin(np.linalg.norm(_apply(H, ids)[:, None] - quad[None], axis=2), axis=1)
    return quad[nearest] if len(set(nearest.tolist())) == 4 else None


def _grow(u8: np.ndarray, smoothed: Smoothed, board: AprilGrid, rotation: int, tags, lattice, pts, ok, spacing):
    """Tags OpenCV did not decode in the image (steeply sheared ones, whose contours merge with the
    corner squares) beside placed corners: each is seen square-on through the homography of the placed
    corners of the tags next to it (:func:`local_homography`, one whole tag at least), and where OpenCV's
    decoder reads its own id there (:func:`_read_square_on`), its corners are placed as a decoded tag's
    (:func:`_pull_in` from that quad, :func:`refine_windowed`). Round after round while one adds a tag.
    Returns tags, lattice, pts, ok, spacing, the new tags' corners appended."""
    decoder, have = _detector(board.family, "none"), set(np.asarray(tags).tolist())
    tried = {}  # tag -> placed corners about it when last looked for: looked for again once there are more
    while True:
        tag_cell, new = board.tag_cell(board.tag_of(lattice)), []
        for t in (int(k) for k in board.tag_ids() if int(k) not in have):
            near = int(np.sum(ok & (np.max(np.abs(tag_cell - board.tag_cell(t)), axis=1) <= 1)))
            H = local_homography(tag_cell, lattice, pts, ok, board.tag_cell(t), least=GROW_FROM)
            if H is None or tried.get(t, -1) >= near:
                continue
            tried[t] = near
            ids = board.tag_corner_ids(t, rotation)
            quad = _read_square_on(u8, decoder, board, H, t, ids)
            if quad is None:
                continue
            clean = clean_window_px(board, quad[None])
            start, good = _pull_in(smoothed, quad[None], quad[None], clean)
            got, fine = refine_windowed(smoothed, start, clean[0], max_shift=0.25 * clean[0] + 1.0)
            new.append((t, ids, got.astype(np.float64), good & fine, clean[0]))
            have.add(t)
        if not new:
            return tags, lattice, pts, ok, spacing
        tags = np.r_[tags, [t for t, *_ in new]].astype(np.int64)
        lattice, pts, ok, spacing = (np.concatenate([a, *(n[k] for n in new)]) for k, a in
                                     ((1, lattice), (2, pts), (3, ok), (4, spacing)))


def detect_aprilgrid(gray: np.ndarray, board: AprilGrid, refine: str = "saddle") -> AprilGridDetection:
    """The corners of ``board`` in ``gray`` (H, W) uint8 or float in [0, 1].

    refine : "saddle" (the project's fit, from OpenCV's unrefined quads), "opencv" (OpenCV's
    CORNER_REFINE_SUBPIX), "apriltag" (OpenCV's CORNER_REFINE_APRILTAG) or "none".
    Returns an :class:`AprilGridDetection`, corners sorted by (row, col) id.
    """
    g = np.asarray(gray)
    u8 = g if g.dtype == np.uint8 else np.clip(np.rint(np.asarray(g, np.float64) * 255.0), 0, 255).astype(np.uint8)
    ids, quads = decode_tags(u8, board, refine)
    if not len(ids):
        return AprilGridDetection(np.zeros((0, 2)), np.zeros((0, 2), np.int64), ids, PRINT_ROTATION,
                                  f"no {board.family} tag with ids {board.first_id}.."
                                  f"{board.first_id + board.tags[0] * board.tags[1] - 1}: check the family and first=")
    rot = _rotation(board, ids, quads)
    lattice = board.tag_corner_ids(ids, rot).reshape(-1, 2)
    pts = quads.reshape(-1, 2)
    ok = np.ones(len(pts), bool)
    if refine == "saddle":
        clean = clean_window_px(board, quads)
        spacing = clean.reshape(-1)
        smoothed = Smoothed(u8.astype(np.float32) / 255.0)
        start, ok = _pull_in(smoothed, quads, predicted_corners(board, ids, quads, rot), clean)
        pts, fine = refine_windowed(smoothed, start, spacing, max_shift=0.25 * spacing + 1.0)
        pts, ok = _from_neighbours(smoothed, board.tag_cell(ids), lattice, pts.astype(np.float64), ok & fine, spacing)
        ids, lattice, pts, ok, spacing = _grow(u8, smoothed, board, rot, ids, lattice, pts, ok, spacing)
        pts, ok = _from_neighbours(smoothed, board.tag_cell(ids), lattice, pts, ok, spacing)  # the new tags too
        r = window_radius(spacing) + 1
        h, w = u8.shape[:2]
        ok &= (pts[:, 0] >= r) & (pts[:, 1] >= r) & (pts[:, 0] <= w - 1 - r) & (pts[:, 1] <= h - 1 - r)
    pts, lattice = pts[ok], lattice[ok]
    order = np.lexsort((lattice[:, 0], lattice[:, 1]))
    why = "" if len(order) else "no tag corner could be placed (each fit failed)"
    return AprilGridDetection(pts[order], lattice[order], ids, rot, why)


def detect_corners_aprilgrid(gray: np.ndarray, board: AprilGrid):
    """:func:`detect_aprilgrid` as a :class:`aicalib_tf.detect.detection.Detection` (scores 1, the
    board's lattice as its pattern; complete when every tag corner is placed)."""
    from aicalib_tf.detect.detection import Detection

    g = np.asarray(gray)
    det = detect_aprilgrid(g, board)
    n = len(det.ids)
    return Detection(det.corners.astype(np.float32), det.ids.astype(np.int32), np.ones(n, np.float32),
                     board.pattern_size, n == 4 * board.tags[0] * board.tags[1], (g.shape[1], g.shape[0]), det.why)


def make_detector(board: AprilGrid):
    """The calibration's detector (:func:`aicalib_tf.calib.workflow.make_detector`) for an AprilGrid:
    grey image -> (corners (N, 2), ids (N, 2)) or None, ``why`` set after a miss."""

    def detect(gray):
        det = detect_aprilgrid(gray, board)
        detect.why = det.why
        return (det.corners, det.ids) if len(det.ids) else None

    detect.info = {"board": board.describe(), "kind": "AprilGrid"}
    detect.why, detect.relative, detect.sigmas = "", False, None
    return detect
