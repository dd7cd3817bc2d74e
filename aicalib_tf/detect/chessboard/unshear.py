"""A second look at a steeply tilted board: its region warped so that its lines cross at right angles.

Tilted 55–80° from facing the camera, a board's two line directions meet at 8–20° in the image
and its squares become slivers; the corner network misses X-junctions that sharp (every junction
it finds crosses at 18° or more). A warp that makes the board's axes perpendicular with equal
steps turns those slivers back into squares of the network's range. So when the full-size search
gives no complete board (:func:`aicalib_tf.detect.pipeline.detect_corners`), the board's axes are
estimated from what the search did find, the region is warped (bicubic: bilinear leaves the
enlarged slivers blurrier) and searched again, and a complete board found there is mapped back
(:func:`second_look`). Two kinds of evidence:

* a partial board (corners with ids) whose axes meet at under ``MAX_ANGLE``, whose steps differ
  by more than ``MAX_STEP_RATIO``, or whose lattice predicts a square thinner than
  ``MIN_THICKNESS`` px next to it (:func:`thinnest_square`: the far rows of a board tilted along one
  axis, or seen close through a wide lens, its near squares 5–10 times its far ones): the homography
  of its ids to its corners (:func:`lattice_map`);
* a sliver of texture (:func:`texture_quads`): the network may find no corner at all on the board,
  but its many nearly parallel edges stand out. The image's gradient energy, smoothed, has a
  connected region whose edges are nearly all of one orientation (coherence at least
  ``MIN_COHERENCE``), ``MIN_ELONGATION`` times longer than wide and ``MIN_LENGTH`` px long: a
  board seen nearly edge-on (sought again without the brightest region when bold text outshines
  it, ``ENERGY_PASSES``). Its outline, a parallelogram, is mapped onto a square (an affine
  map, :func:`quad_map`). That leaves the board's perspective, so a part of the board found there
  is fitted again by its lattice's homography and searched once more (``ROUNDS``).

A board found is refined on its rectified view (:func:`refine_rectified`): on the image, a saddle
fit fails at most junctions that sharp. A search that leaves a few of the board's far corners out
(squares 1.5–3 px thick on the image, blurred across once enlarged) gets them placed on its view,
each where the found corners' homography predicts it and only where the view shows a junction there
(:mod:`aicalib_tf.detect.chessboard.unshear_fill`).

Steep tilts (tilt-steep, 55–80°, 100 images a seed): 99 and 98 of 100 on the seeds it was tuned
on (41, 97), 100, 100, 100 and 98 on others (211, 307, 401, 503), none wrong; the misses are a board
under text and boards whose far squares are 1.2–1.5 px thick. ``benchmarks/tilt_families.py`` (seed
301, 12 laws of 12 images): 142 of 144 through tilt_steep's lenses, 118 of 144 through strong barrel
lenses and fisheyes (136 and 112 with a 5 px ``MIN_THICKNESS`` and one energy share of 0.25, coherence
0.7), none wrong; its misses are squares 1.2–2.5 px thick that the network marks few corners of (a
barrel lens bends such a sliver into an arc no affine warp straightens). On a board-free 640×480 frame
the texture analysis costs about 8 ms CPU (both shares; 5 ms with one; 30 evaluate clutter frames),
and a search of a 200–300 px warp where a sliver is found (4 of those 30).

Coordinates are (x, y) px, OpenCV's convention: the centre of pixel (0, 0) is at (0.0, 0.0), and
``cv2.warpAffine`` / ``cv2.warpPerspective`` sample the image at M⁻¹ (x', y') for the pixel centre
(x', y') of the warped image, so points map back by M's inverse alone (no half-pixel term).
"""

from __future__ import annotations

import cv2
import numpy as np

from aicalib_tf.detect.chessboard.unshear_fill import filled_board

__all__ = ["MAX_ANGLE", "MAX_STEP_RATIO", "lattice_axes", "is_sheared", "thin_not_sheared", "lattice_map", "texture_quads", "quad_map",
           "warp", "from_warp", "candidate_maps", "second_look",
           "refine_rectified"]

MAX_ANGLE = 30.0  # degrees: a partial board whose axes meet at less than this is looked at again, unsheared
MAX_STEP_RATIO = 2.5  # ... and so is one whose steps along its two axes differ more than this
MIN_THICKNESS = 8.0  # px: ... and one whose lattice predicts a square thinner than this (the far squares of a tilted board)
STEP = 12.0  # px: a square's side in the warped image (an upsampled board is blurred across: larger is worse)
SIDE = 120.0  # px: the side of the square a texture sliver's outline is mapped onto (10×7 squares: 12×17 px)
PAD = 0.4  # of the board's warped extent: margin around it (the outer squares and paper)
ENERGY_SIGMA = 5.0  # px of the image: smoothing of the gradient energy and orientation (a few stripes of a sliver board)
ENERGY_SHARES = (0.25, 0.12)  # of the largest smoothed energy: a texture sliver's region, then a wider one (a faint far end)
MIN_COHERENCE = 0.6  # energy-weighted orientation coherence of a sliver (0: no orientation, 1: all parallel)
MIN_ELONGATION = 3.0  # length / width of a sliver (from its second moments)
MAX_SLIVERS = 2  # texture slivers looked at again, at each share of the energy
SAME_OUTLINE = 0.05  # of a sliver's length: an outline this near another's in every corner is the same sliver
CANDIDATE_REGIONS = 4  # high-energy regions, by summed energy, that may be one
ENERGY_PASSES = 2  # the regions taken again without the brightest one while none is a sliver
MIN_LENGTH = 150.0  # px: a shorter sliver holds no board the network could read once unsheared (10 squares of 15 px)
MIN_LATTICE = 9  # corners of a partial board that a lattice is fitted to
REFINE_STEP = 16.0  # px: a square's side in the view a found board's corners are refined on
ROUNDS = 2  # searches per warp: the outline's, then the lattice of what it found
MAX_PIXELS = 250_000  # the warped region's most pixels
INTERPOLATION = cv2.INTER_CUBIC  # of the warp (bilinear leaves an enlarged sliver's squares blurrier)
GRADIENT_SIDE = 800  # px: the texture's gradients are taken on the image reduced to this longer side at most
ANALYSIS_SIDE = 320  # px: ... and smoothed and searched for slivers on blocks of them, this longer side at most


def lattice_axes(ids: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares affine lattice of a partial board: points ≈ origin + col·u + row·v.

    ids : (K, 2) int (col, row), K ≥ 3 not on one line. points : (K, 2) px.
    Returns origin, u, v: (2,) float64 px each.
    """
    ij = np.asarray(ids, np.float64).reshape(-1, 2)
    a = np.column_stack([np.ones(len(ij)), ij])
    sol, *_ = np.linalg.lstsq(a, np.asarray(points, np.float64).reshape(-1, 2), rcond=None)
    return sol[0], sol[1], sol[2]


def is_sheared(u: np.ndarray, v: np.ndarray) -> bool:
    """Whether lattice steps u, v (2,) px meet at under ``MAX_ANGLE`` or differ in length by more than ``MAX_STEP_RATIO``."""
    nu, nv = float(np.linalg.norm(u)), float(np.linalg.norm(v))
    if min(nu, nv) <= 0:
        return False
    sine = abs(float(u[0] * v[1] - u[1] * v[0])) / (nu * nv)
    return sine < np.sin(np.radians(MAX_ANGLE)) or max(nu, nv) > MAX_STEP_RATIO * min(nu, nv)


def lattice_map(ids: np.ndarray, points: np.ndarray, pattern_size: tuple[int, int], placed: bool = True,
                step: float = STEP) -> tuple[np.ndarray, tuple[int, int]] | None:
    """The projective map that makes a grid's lattice square, steps of ``step`` px along x and y.

    ids : (K, 2) int (col, row), K ≥ 6, not on one line; points : (K, 2) px. The lattice is the
    least-squares homography ids -> points. placed : the ids are the pattern's, so the warped image
    holds ids −1 … cols and −1 … rows (the board's outer squares); otherwise they are relative to
    the grid, and it holds the grid and as many steps beyond it on each side as the pattern could
    reach (the grid may be any part of the board). ``PAD`` of that extent is added around. The
    board's handedness is kept (a lattice mirrored on the image is warped with its rows running up).
    Returns H (3, 3) float64, image -> warped px, and the warped image's (width, height), or None.
    """
    ij = np.asarray(ids, np.float64).reshape(-1, 2)
    lat, _ = cv2.findHomography(ij, np.asarray(points, np.float64).reshape(-1, 2), 0)
    if lat is None or not np.all(np.isfinite(lat)):
        return None
    if placed:
        lo, hi = np.array([-1.0, -1.0]), np.array(pattern_size, np.float64)
    else:
        reach = np.maximum(max(pattern_size) - (ij.max(axis=0) - ij.min(axis=0) + 1), 0) + 1
        lo, hi = ij.min(axis=0) - reach, ij.max(axis=0) + reach
    ext = (hi - lo) * step
    pad = PAD * ext.max()
    _, u, v = lattice_axes(ij, points)
    flip = float(u[0] * v[1] - u[1] * v[0]) < 0
    to_warp = np.array([[step, 0, pad - lo[0] * step],
                        [0, -step, pad + hi[1] * step] if flip else [0, step, pad - lo[1] * step], [0, 0, 1]])
    try:
        h = to_warp @ np.linalg.inv(lat)
    except np.linalg.LinAlgError:
        return None
    return h / h[2, 2], (int(np.ceil(ext[0] + 2 * pad)), int(np.ceil(ext[1] + 2 * pad)))


def _structure(gray: np.ndarray, sigma: float, step: int) -> tuple[np.ndarray, np.ndarray]:
    """Gradient energy and orientation coherence of gray (H, W) float32, smoothed over ``sigma`` px of
    gray: (H // step, W // step) float32 each. The gradients are gray's own (a sliver board's stripes
    are 2–4 px apart); their products are averaged over step × step blocks before the smoothing."""
    b = cv2.GaussianBlur(gray, (0, 0), 1.0)
    gx = cv2.Sobel(b, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(b, cv2.CV_32F, 0, 1, ksize=3)
    h, w = (gray.shape[0] // step, gray.shape[1] // step)
    jxx, jyy, jxy = (cv2.GaussianBlur(cv2.resize(p, (w, h), interpolation=cv2.INTER_AREA) if step > 1 else p,
                                      (0, 0), sigma / step) for p in (gx * gx, gy * gy, gx * gy))
    energy = jxx + jyy
    return energy, np.sqrt((jxx - jyy) ** 2 + 4 * jxy**2) / np.maximum(energy, 1e-12)


def _outline(xy: np.ndarray) -> np.ndarray | None:
    """A parallelogram-like outline of a sliver's pixels xy (N, 2): its hull's two farthest points and the
    points farthest from the line through them on either side, (4, 2) float64 in turn around it, or None."""
    hull = cv2.convexHull(xy.astype(np.float32)).reshape(-1, 2).astype(np.float64)
    if len(hull) < 4:
        return None
    d = np.linalg.norm(hull[:, None] - hull[None], axis=2)
    a, c = np.unravel_index(int(np.argmax(d)), d.shape)
    axis = (hull[c] - hull[a]) / d[a, c]
    side = (hull - hull[a]) @ np.array([-axis[1], axis[0]])
    if side.max() < 1.0 or side.min() > -1.0:
        return None
    return np.stack([hull[a], hull[int(np.argmax(side))], hull[c], hull[int(np.argmin(side))]])


def _sliver(xy: np.ndarray, energy: np.ndarray, coherence: np.ndarray, scale: float) -> np.ndarray | None:
    """A region's outline when it is a sliver of coherent texture (:func:`texture_quads`), else None.

    xy : (N, 2) int pixel positions of the region; energy, coherence : (N,) their values. scale : image px per px of xy.
    """
    if len(xy) < 3 or float(energy @ coherence) / float(energy.sum()) < MIN_COHERENCE:
        return None
    lam = np.linalg.eigvalsh(np.cov(xy.T.astype(np.float64)))
    if lam[0] <= 0 or lam[1] < MIN_ELONGATION**2 * lam[0] or 4 * np.sqrt(lam[1]) * scale < MIN_LENGTH:
        return None
    quad = _outline(xy)
    return None if quad is None else (quad + 0.5) * scale - 0.5


def texture_quads(gray: np.ndarray, most: int = MAX_SLIVERS) -> list[np.ndarray]:
    """Outlines of boards seen nearly edge-on: [(4, 2) float64 px in turn around it], at most ``most`` a share.

    gray : (H, W) float32. The regions where the smoothed gradient energy is at least a share
    (``ENERGY_SHARES``, in turn: a board's far end, its squares thinnest, may be too faint for the first
    and the region then its near part only, whose outline leaves the board sheared; the second may take
    in the paper around a clear board) of its largest value are taken by their summed energy, the largest
    ``CANDIDATE_REGIONS`` only; a board's has coherent edges (``MIN_COHERENCE``), is ``MIN_ELONGATION``
    times longer than wide and ``MIN_LENGTH`` px long (a small patterned object beside it may hold the
    largest value). When none is and the largest value's region is no sliver (bold text, say, so bright
    that a thin board beside it falls apart under that share), the regions are taken again with that one
    left out (``ENERGY_PASSES``). An outline within ``SAME_OUTLINE`` of its length of one found already is left
    out.
    """
    h, w = gray.shape
    f = max(1.0, max(w, h) / GRADIENT_SIDE)
    if min(w, h) < 16 * f:  # a strip too narrow for any board
        return []
    small = gray if f == 1.0 else cv2.resize(gray, (round(w / f), round(h / f)), interpolation=cv2.INTER_AREA)
    step = max(1, int(max(small.shape) // ANALYSIS_SIDE))
    if min(small.shape) < 8 * step:
        return []
    energy, coherence = _structure(np.asarray(small, np.float32), ENERGY_SIGMA / f, step)
    f *= step  # image px per px of the energy
    out: list[np.ndarray] = []
    for share in ENERGY_SHARES:
        out += [q for q in _slivers(energy, coherence, f, share, most)
                if all(np.abs(q - seen).max() > SAME_OUTLINE * np.ptp(q, axis=0).max() for seen in out)]
    return out


def _slivers(energy: np.ndarray, coherence: np.ndarray, f: float, share: float, most: int) -> list[np.ndarray]:
    """:func:`texture_quads`' outlines at one ``share`` of the largest ``energy`` (coherence alike; f image px a px)."""
    out: list[np.ndarray] = []
    for _ in range(ENERGY_PASSES):
        top = float(energy.max())
        if not top > 0:
            break
        n, labels, boxes, _ = cv2.connectedComponentsWithStats((energy >= share * top).astype(np.uint8), connectivity=8)
        sums = np.bincount(labels.ravel(), weights=energy.ravel(), minlength=n)
        sums[0] = 0.0  # the background
        for lab in np.argsort(sums)[::-1][:min(CANDIDATE_REGIONS, n - 1)]:
            x, y, bw, bh = boxes[lab, :4]
            yx = np.argwhere(labels[y:y + bh, x:x + bw] == lab) + [y, x]
            quad = _sliver(yx[:, ::-1], energy[yx[:, 0], yx[:, 1]], coherence[yx[:, 0], yx[:, 1]], f)
            if quad is not None:
                out.append(quad)
            if len(out) >= most:
                break
        if out:
            break
        brightest = (labels == labels.flat[int(np.argmax(energy))]).astype(np.uint8)
        reach = 2 * int(np.ceil(3 * ENERGY_SIGMA / f)) + 1  # and its smoothed halo
        energy = np.where(cv2.dilate(brightest, np.ones((reach, reach), np.uint8)) > 0, 0.0, energy)
    return out


def quad_map(quad: np.ndarray, side: float = SIDE) -> tuple[np.ndarray, tuple[int, int]]:
    """The affine map (least squares) of an outline (4, 2) px onto a square of ``side`` px with ``PAD`` around.

    The outline's turn is kept (a square in the same sense), so a board's handedness is too.
    Returns M (3, 3) float64 (an affine map), image -> warped px, and the warped image's (width, height).
    """
    q = np.asarray(quad, np.float64).reshape(4, 2)
    pad = PAD * side
    sq = np.array([[0, 0], [side, 0], [side, side], [0, side]], np.float64) + pad
    d1, d2, d3 = q[1] - q[0], q[2] - q[0], q[3] - q[0]
    turn = d1[0] * d2[1] - d1[1] * d2[0] + d2[0] * d3[1] - d2[1] * d3[0]
    if turn < 0:  # counter-clockwise on screen: keep it so in the warped image
        sq = sq[[0, 3, 2, 1]]
    sol, *_ = np.linalg.lstsq(np.column_stack([q, np.ones(4)]), sq, rcond=None)
    size = int(np.ceil(side + 2 * pad))
    return np.vstack([sol.T, [0.0, 0.0, 1.0]]), (size, size)


def warp(gray: np.ndarray, m: np.ndarray, size: tuple[int, int]) -> np.ndarray | None:
    """gray (H, W) float32 warped by M (3, 3) into ``size`` (width, height): float32, or None when larger
    than ``MAX_PIXELS`` or degenerate. Outside the image: the border pixels repeated."""
    if size[0] * size[1] > MAX_PIXELS or min(size) < 8 or not np.all(np.isfinite(m)):
        return None
    g = np.asarray(gray, np.float32)
    if np.allclose(m[2], [0.0, 0.0, 1.0]):
        return cv2.warpAffine(g, m[:2], size, flags=INTERPOLATION, borderMode=cv2.BORDER_REPLICATE)
    return cv2.warpPerspective(g, m, size, flags=INTERPOLATION, borderMode=cv2.BORDER_REPLICATE)


def from_warp(points: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Points (N, 2) px on a :func:`warp` image -> the same places on the image: (N, 2) float32."""
    p = np.asarray(points, np.float64).reshape(-1, 1, 2)
    if len(p) == 0:
        return np.zeros((0, 2), np.float32)
    return cv2.perspectiveTransform(p, np.linalg.inv(np.asarray(m, np.float64))).reshape(-1, 2).astype(np.float32)


def candidate_maps(gray: np.ndarray, pattern_size: tuple[int, int], ids: np.ndarray | None = None,
                   corners: np.ndarray | None = None) -> list[tuple[np.ndarray, tuple[int, int]]]:
    """The warps worth a second look, most trusted first: [(M (3, 3), (width, height))].

    gray : (H, W) float32. ids (K, 2) int and corners (K, 2) px: a partial board the search found
    (or None): its lattice when sheared or thin (:func:`is_sheared`, :func:`thinnest_square`; a board that is
    neither: none), else a texture sliver's outline (:func:`texture_quads`).
    """
    if _spans(ids):
        _, u, v = lattice_axes(ids, corners)
        thin = is_sheared(u, v) or thinnest_square(ids, corners) < MIN_THICKNESS
        got = lattice_map(ids, corners, pattern_size) if thin else None
        return [] if got is None else [got]
    return [quad_map(q) for q in texture_quads(gray)]


def thinnest_square(ids: np.ndarray, points: np.ndarray) -> float:
    """The thickness (px) of the thinnest square a grid's lattice predicts about it.

    ids (K, 2) int, points (K, 2) px: a grid. The homography of ids to points places the squares of
    the grid's extent and one square beyond it on every side; a square's thickness is its area over
    its longest side (its height across that side). Returns the least, or inf when no homography fits.
    """
    ij = np.asarray(ids, np.float64).reshape(-1, 2)
    lat, _ = cv2.findHomography(ij, np.asarray(points, np.float64).reshape(-1, 2), 0)
    if lat is None or not np.all(np.isfinite(lat)):
        return float("inf")
    lo, hi = ij.min(axis=0) - 1, ij.max(axis=0) + 1
    c, r = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1))
    g = cv2.perspectiveTransform(np.stack([c, r], -1).reshape(-1, 1, 2), lat).reshape(c.shape + (2,))
    a, b = g[1:, :-1] - g[:-1, :-1], g[:-1, 1:] - g[:-1, :-1]  # the two sides at each square's first corner
    d = g[1:, 1:] - g[:-1, :-1]
    area = 0.5 * (np.abs(a[..., 0] * d[..., 1] - a[..., 1] * d[..., 0]) + np.abs(d[..., 0] * b[..., 1] - d[..., 1] * b[..., 0]))
    side = np.maximum.reduce([np.linalg.norm(x, axis=-1) for x in (a, b, g[1:, 1:] - g[1:, :-1], g[1:, 1:] - g[:-1, 1:])])
    return float((area / np.maximum(side, 1e-9)).min())


def thin_not_sheared(ids: np.ndarray | None, corners: np.ndarray | None) -> bool:
    """Whether a partial board, ids (K, 2) int and corners (K, 2) px (or None), gets the lattice warp for a thin
    square alone (:func:`candidate_maps`): it spans the lattice and its steps are not sheared (:func:`is_sheared`),
    as a close-up's squeezed rim; its junctions are then square enough for the object test of a steep board's
    look to read them (:func:`aicalib_tf.detect.chessboard.occlusion.object_in_front`)."""
    if not _spans(ids):
        return False
    _, u, v = lattice_axes(ids, corners)
    return not is_sheared(u, v)


def _spans(ids) -> bool:
    """Whether ids (K, 2) (or None) hold at least ``MIN_LATTICE`` corners spanning 2 steps or more both ways."""
    return ids is not None and len(ids) >= MIN_LATTICE and min(np.ptp(np.asarray(ids), axis=0)) >= 2


def second_look(gray: np.ndarray, pattern_size: tuple[int, int], search, ids: np.ndarray | None = None,
                corners: np.ndarray | None = None, refine=None):
    """The first complete board found on the warps of :func:`candidate_maps`, or None.

    search : ``search(warped (h, w) float32) -> detection`` with ``complete``, ``found``, ``ids``
    (K, 2) and ``corners`` (K, 2) px. A warp whose search finds only part of the board is fitted
    again to that part's lattice (:func:`lattice_map`, with room for the whole pattern on every side) and searched
    once more (the search is sensitive to the crop: a tight one around the board did worse):
    the outline's affine map leaves the board's perspective, the lattice's homography does not.
    refine : ``refine(view, points (M, 2), max_shift) -> (points, ok)``, a saddle fit; with it, a
    placed partial board spanning the pattern but for a few empty positions is completed on its view
    (:func:`aicalib_tf.detect.chessboard.unshear_fill.filled_board`); None: only complete boards count.
    Returns (corners (N, 2) float32 px on gray, in the warped detection's order; that detection).
    """
    for m, size in candidate_maps(gray, pattern_size, ids, corners):
        for _ in range(ROUNDS):
            img = warp(gray, m, size)
            det = search(img) if img is not None else None
            if det is not None and det.complete:
                return from_warp(det.corners, m), det
            filled = _filled(det, img, pattern_size, refine)
            if filled is not None:
                return from_warp(filled.corners, m), filled
            if det is None or not _spans(det.ids):
                break
            got = lattice_map(det.ids, from_warp(det.corners, m), pattern_size, placed=False)
            if got is None:
                break
            m, size = got
    return None


def _filled(det, img: np.ndarray | None, pattern_size: tuple[int, int], refine):
    """A partial ``det`` on the view ``img`` completed (:func:`~aicalib_tf.detect.chessboard.unshear_fill.filled_board`), or None."""
    if refine is None or det is None or img is None or not det.found:
        return None
    return filled_board(det, pattern_size, img, refine)


def refine_rectified(gray: np.ndarray, corners: np.ndarray, pattern_size: tuple[int, int], refine,
                     step: float = REFINE_STEP) -> np.ndarray:
    """A full board's corners refined on its rectified view: (cols·rows, 2) float32 px on gray.

    corners : (cols·rows, 2) px in a row-major reading. The board's homography (:func:`lattice_map`)
    warps it to square steps of ``step`` px, where its junctions cross at right angles (on the
    image, at 8–20°, a saddle fit mostly fails); ``refine(warped (h, w) float32, points (N, 2))
    -> (points, ok (N,) bool)`` refines them there. A corner whose refinement fails keeps its place.
    """
    cols, rows = pattern_size
    pts = np.asarray(corners, np.float32).reshape(-1, 2)
    ids = np.stack(np.meshgrid(np.arange(cols), np.arange(rows)), -1).reshape(-1, 2)
    got = lattice_map(ids, pts, pattern_size, step=step)
    img = warp(gray, *got) if got is not None else None
    if img is None:
        return pts
    on_warp = cv2.perspectiveTransform(pts.reshape(-1, 1, 2).astype(np.float64), got[0]).reshape(-1, 2)
    refined, ok = refine(img, on_warp.astype(np.float32))
    return np.where(np.asarray(ok)[:, None], from_warp(refined, got[0]), pts).astype(np.float32)

