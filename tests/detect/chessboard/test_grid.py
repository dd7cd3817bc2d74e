import cv2
import numpy as np
import pytest

from aicalib_tf.detect.chessboard import grid_growth, grid_seeds
from aicalib_tf.detect.chessboard.grid import assemble_grids
from aicalib_tf.detect.chessboard.grid_seeds import edge_contrast
from data_gen import make_sample
from data_gen.presets import get_preset


def _same_lattice(ij: np.ndarray, truth_cr: np.ndarray) -> bool:
    """True if grid positions ij equal the true (col, row) up to a flip/transposition and shift."""
    for m in (np.array([[1, 0], [0, 1]]), np.array([[0, 1], [1, 0]])):
        for s in ([1, 1], [1, -1], [-1, 1], [-1, -1]):
            t = (truth_cr @ m) * np.array(s)
            t = t - t.min(0)
            if np.array_equal(t, ij):
                return True
    return False


@pytest.mark.parametrize("preset, seed", [("clean", 0), ("distorted", 1), ("distorted", 2), ("clean", 3), ("distorted", 4), ("distorted", 5)])
def test_true_corners_assemble_into_one_full_lattice(preset, seed):
    s = make_sample(preset, seed, 0, pattern=(9, 6))
    rng = np.random.default_rng(seed)
    pts = s.corners + rng.normal(0, 0.2, s.corners.shape)
    gray = cv2.GaussianBlur(s.image.astype(np.float32), (0, 0), 1.0)
    grids = assemble_grids(pts, gray=gray)
    assert len(grids) == 1
    g = grids[0]
    assert len(g) == 54 and sorted(g.shape) == [6, 9]
    cr = np.stack([g.index % 9, g.index // 9], 1)
    assert _same_lattice(g.ij, cr)


def test_clutter_points_and_missing_corners():
    s = make_sample("clean", 5, 0, pattern=(9, 6))
    rng = np.random.default_rng(5)
    keep = np.ones(54, bool)
    keep[[10, 11, 30, 44]] = False  # holes inside the board
    clutter = rng.uniform([0, 0], [640, 480], (80, 2))
    pts = np.concatenate([s.corners[keep], clutter])
    grids = assemble_grids(pts, gray=s.image.astype(np.float32))
    g = grids[0]
    board = g.index[g.index < keep.sum()]
    assert len(board) == 50 and len(g) == 50  # every true corner, no clutter point
    idx = np.flatnonzero(keep)[g.index]
    assert _same_lattice(g.ij, np.stack([idx % 9, idx // 9], 1))


def test_stop_ends_the_assembly_at_the_grid_it_accepts():
    # two separate lattices: the stronger seeds first, so the first grid assembled is the left one
    gx, gy = np.meshgrid(np.arange(5) * 20.0, np.arange(4) * 20.0)
    left = np.stack([gx.ravel() + 50, gy.ravel() + 50], 1)
    right = left + [300, 100]
    pts = np.concatenate([left, right])
    scores = np.r_[np.full(20, 0.9), np.full(20, 0.8)]
    both = assemble_grids(pts, scores)
    assert [len(g) for g in both] == [20, 20]
    asked = []
    first = assemble_grids(pts, scores, stop=lambda g: asked.append(len(g)) or True)
    assert asked == [20] and len(first) == 1 and np.all(first[0].index < 20)
    assert len(assemble_grids(pts, scores, stop=lambda g: False)) == 2


def test_too_few_or_scattered_points_give_no_grid():
    assert assemble_grids(np.zeros((5, 2))) == []
    rng = np.random.default_rng(0)
    assert all(len(g) < 20 for g in assemble_grids(rng.uniform(0, 640, (300, 2))))


def test_full_subgrid_cuts_the_largest_filled_rectangle():
    from aicalib_tf.detect.chessboard.grid import Grid, full_subgrid

    ii, jj = np.meshgrid(np.arange(8), np.arange(6), indexing="ij")
    ij = np.stack([ii.ravel(), jj.ravel()], 1)
    keep = ~((ij[:, 0] == 7) & (ij[:, 1] < 4))  # a last column cut by the frame: 2 of its 6 corners
    g = Grid(index=np.flatnonzero(keep), ij=ij[keep], points=ij[keep] * 30.0 + 5.0)
    sub = full_subgrid(g)
    assert sub.shape == (7, 6) and len(sub) == 42 and np.array_equal(sub.ij.min(0), [0, 0])
    assert np.array_equal(sub.points, sub.ij * 30.0 + 5.0)  # points stay with their positions
    full = Grid(index=np.arange(48), ij=ij, points=ij * 1.0)
    assert full_subgrid(full) is full
    hole = ~((ij[:, 0] == 3) & (ij[:, 1] == 2))  # a hole inside: the 8x3 below it (24) beats 4x6 (24, found later)
    sub = full_subgrid(Grid(index=np.flatnonzero(hole), ij=ij[hole], points=ij[hole] * 1.0))
    assert len(sub) == 24 and sub.shape == (8, 3) and np.array_equal(sub.points.min(0), [0, 3])
    thin = ij[:, 1] < 2  # 8x2: no 3x3 inside
    assert full_subgrid(Grid(index=np.flatnonzero(thin), ij=ij[thin], points=ij[thin] * 1.0)) is None


def test_a_side_is_worked_out_again_only_after_a_cell_is_taken():
    from aicalib_tf.detect.chessboard.grid_growth import GrowingGrid, _side, _work_out_side

    ii, jj = np.meshgrid(np.arange(4), np.arange(3), indexing="ij")
    pts = np.stack([10.0 + 8 * jj.ravel() + 0.1 * ii.ravel() ** 2, 20.0 + 8 * ii.ravel()], axis=1)
    lat = GrowingGrid(pts, np.ones(len(pts), bool))
    for k, (i, j) in enumerate(zip(ii.ravel(), jj.ravel())):
        if (i, j) != (0, 2):
            lat.take((int(i), int(j)), k)
    first = _side(lat, 0, 1)
    assert _side(lat, 0, 1) is first  # remembered while nothing changes
    cells, preds, tols, _ = first
    assert cells == [(4, 0), (4, 1), (4, 2)]
    np.testing.assert_array_equal(preds[0], 3 * pts[9] - 3 * pts[6] + pts[3])  # three known: quadratic
    lat.take((0, 2), 2)
    again = _side(lat, 0, -1)
    fresh = _work_out_side(lat, 0, -1)
    assert again[0] == fresh[0] == [(-1, 0), (-1, 1), (-1, 2)]
    np.testing.assert_array_equal(again[1], fresh[1])
    assert list(lat._nearest_free(preds, tols)[0]) == [-1, -1, -1]


@pytest.mark.parametrize("index", [69, 91, 274])
def test_a_board_tilted_60_degrees_assembles_unsheared(index):
    # evaluate's tilt60 scenes: one step about 2-4x the other, and a knight's step (2·col − row)
    # more orthogonal to col than row is; these were missed (no grid) before seeds took the
    # shortest pairs of steps, up to 4.5x apart, and left out multiple steps
    from aicalib_tf.bench.conditions import select_conditions

    cond = select_conditions("tilt60")[0]
    s = make_sample(cond.preset, cond.seed, index, size=cond.size, pattern=(9, 6))
    gray = cv2.GaussianBlur(s.image, (0, 0), 1.0)
    grids = assemble_grids(s.corners, gray=gray)
    assert len(grids) == 1 and len(grids[0]) == 54
    cr = np.stack(np.meshgrid(np.arange(9), np.arange(6)), -1).reshape(-1, 2)
    order = np.argmin(np.linalg.norm(grids[0].points[:, None] - s.corners[None], axis=2), axis=1)
    assert _same_lattice(grids[0].ij, cr[order])


def test_edge_contrast_is_the_bilinear_sides_difference():
    rng = np.random.default_rng(2)
    gray = rng.random((30, 40)).astype(np.float32)
    p = rng.uniform(-3, 42, (300, 2))  # some samples beyond the image: the nearest edge pixel
    q = p + rng.uniform(-8, 8, (300, 2))

    def bilinear(x, y):
        x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
        fx, fy = x - x0, y - y0
        c0, c1 = np.clip(x0, 0, 39), np.clip(x0 + 1, 0, 39)
        r0, r1 = np.clip(y0, 0, 29), np.clip(y0 + 1, 0, 29)
        g = gray.astype(np.float64)
        top = g[r0, c0] + fx * (g[r0, c1] - g[r0, c0])
        bot = g[r1, c0] + fx * (g[r1, c1] - g[r1, c0])
        return top + fy * (bot - top)

    d = q - p
    n = np.stack([-d[:, 1], d[:, 0]], 1) * 0.25
    sides = [sum(bilinear(*(p + t * d + s * n).T) for t in (0.35, 0.5, 0.65)) / 3 for s in (1, -1)]
    np.testing.assert_allclose(edge_contrast(gray, p, q), np.abs(sides[0] - sides[1]), rtol=0, atol=1e-6)


def test_edge_contrast_takes_as_many_segments_as_the_assembly_asks():
    # assemble_grids asks for MAX_CANDIDATES (3000) x 12 neighbours = 36000 segments (once more
    # than cv2.remap's maps could hold: a checker-like clutter image at 1983x453 crashed)
    rng = np.random.default_rng(0)
    gray = rng.random((60, 80)).astype(np.float32)
    p = rng.uniform(0, 79, (36000, 2))
    q = p + rng.uniform(-6, 6, (36000, 2))
    got = edge_contrast(gray, p, q)
    assert got.shape == (36000,)
    np.testing.assert_array_equal(got[-500:], edge_contrast(gray, p[-500:], q[-500:]))
    assert edge_contrast(gray, p[:0], q[:0]).shape == (0,)


def test_seed_contrast_rows_are_those_of_one_batch():
    # the seeds' edge contrasts come in growing batches as seeds ask; each row is the one that
    # edge_contrast of every point's steps at once gives, bit for bit, and rows are computed once
    rng = np.random.default_rng(1)
    gray = rng.random((90, 120)).astype(np.float32)
    pts = rng.uniform(0, 119, (40, 2))
    d2 = ((pts[:, None] - pts[None]) ** 2).sum(-1)
    np.fill_diagonal(d2, np.inf)
    near = np.argsort(d2, axis=1)[:, :12]
    whole = edge_contrast(gray, np.repeat(pts, 12, axis=0), pts[near.ravel()]).reshape(near.shape).astype(np.float64)
    order = rng.permutation(40)
    free = np.ones(40, bool)
    free[order[1]] = False  # taken by a grid: never asked, never computed
    rows = grid_seeds.SeedContrast(gray, pts, near, order, free)
    asked = [k for k in order if free[k]]
    for n, k in enumerate(asked):
        np.testing.assert_array_equal(rows.row(int(k)), whole[k])
        if n == 0:
            assert rows.done.sum() == 1  # the first seed alone
    assert not rows.done[order[1]] and rows.done.sum() == 39


def test_strip_seeds_assemble_a_strip_two_corners_wide():
    # two whole columns of a board (a bar in front hides the rest): no corner has all 8 neighbours,
    # so no 3×3 seed starts; a 3×2 seed does, with the board's own lattice
    s = make_sample("clean", 5, 0, pattern=(9, 6))
    keep = np.flatnonzero(np.arange(54) % 9 < 2)
    gray = s.image.astype(np.float32)
    assert assemble_grids(s.corners[keep], gray=gray) == []
    grids = assemble_grids(s.corners[keep], gray=gray, strips=True)
    assert len(grids) == 1 and len(grids[0]) == 12
    idx = keep[grids[0].index]
    assert _same_lattice(grids[0].ij, np.stack([idx % 9, idx // 9], 1))


def _closeup(index):
    """A fisheye_closeup scene of the benchmark (640×480, seed 21): true corners and image."""
    from data_gen.sample import draw_scene

    sc = draw_scene(get_preset("fisheye_closeup"), 21, index, size=(640, 480), pattern=(9, 6))
    return sc.corners, sc.render()


@pytest.mark.parametrize("index", [23, 27, 29])
def test_true_corners_of_close_up_fisheye_boards_assemble_into_their_lattice(index):
    # 29: a line's steps grow across the lens' centre and shrink towards the rim, so the quadratic
    # extrapolation lands nearer the corner two steps on (a double step, undone); 27: no 3×3 block
    # is a parallelogram within the tolerance, a bent seed starts the grid (the plain assembly gives
    # no full lattice on either); 23 (198°): the steps across the centre grow to 80 px and shrink to
    # 12 px at the rim, so the holes left by extrapolation are filled by interpolating along their
    # lines, the grid grows again from them, and an edge hole is predicted from its cell's shape
    corners, image = _closeup(index)
    gray = cv2.GaussianBlur(image.astype(np.float32), (0, 0), 1.0)
    grids = assemble_grids(corners, gray=gray, bend=True)
    assert len(grids) == 1 and len(grids[0]) == 54 and sorted(grids[0].shape) == [6, 9]
    g = grids[0]
    assert _same_lattice(g.ij, np.stack([g.index % 9, g.index // 9], 1))


def test_line_residuals_follow_a_bent_lattice_and_flag_a_wrong_corner():
    from aicalib_tf.detect.chessboard.lattice import curved_residuals, line_residuals

    corners, _ = _closeup(23)  # a 198° lens, the board across most of its circle
    ids = np.array([(c, r) for r in range(6) for c in range(9)])
    assert line_residuals(ids, corners).max() < 0.2 < curved_residuals(ids, corners).max()
    moved = corners.copy()
    moved[22] = (corners[22] + corners[23]) / 2  # half a step along its line
    res = line_residuals(ids, moved)
    assert int(np.argmax(res)) == 22 and res.max() > 0.5


def _python_phase(lat, whole):
    """grid_growth.grow's loop for one phase, in Python: the reference for the compiled growth."""
    grown = True
    while grown:
        grown = False
        for axis in (0, 1):
            for sign in (1, -1):
                while grid_growth._grow_side(lat, axis, sign, whole):
                    grown = True


def _lattice_with_clutter(rng, a, b):
    """A rotated, sheared a×b lattice with some corners jittered or missing, and clutter points, shuffled."""
    ii, jj = np.meshgrid(np.arange(a), np.arange(b), indexing="ij")
    th, step = rng.uniform(0, np.pi), rng.uniform(5, 30)
    u = step * np.array([np.cos(th), np.sin(th)])
    v = step * np.array([-np.sin(th), np.cos(th)]) * rng.uniform(0.6, 1.4)
    pts = ii.reshape(-1, 1) * u + jj.reshape(-1, 1) * v
    pts += rng.normal(0, rng.uniform(0, 0.25) * step, pts.shape) * (rng.random(len(pts)) < 0.2)[:, None]
    pts = pts[rng.random(len(pts)) > rng.uniform(0, 0.2)]
    clutter = rng.uniform(pts.min(0) - 50, pts.max(0) + 50, (int(rng.integers(0, 60)), 2))
    pts = np.concatenate([pts, clutter])
    return pts[rng.permutation(len(pts))]


def test_compiled_growth_takes_the_cells_the_python_growth_takes(monkeypatch):
    # every phase of every assembly (with and without a limit, whole lines or half, 3x3 and strip
    # seeds, lattices up to 40x40 whose cell grid must grow in the kernel) is run both ways
    compiled = grid_growth._grow_compiled
    phases = []

    def both(lat, whole):
        shadow = grid_growth.GrowingGrid(lat.pts, lat.free.copy(), lat.propose, lat.limit, lat.bend)
        for cell, k in lat.cells.items():
            shadow.take(cell, k)
        _python_phase(shadow, whole)
        compiled(lat, whole)
        phases.append(list(lat.cells.items()) == list(shadow.cells.items()) and np.array_equal(lat.free, shadow.free))

    monkeypatch.setattr(grid_growth, "_grow_compiled", both)
    rng = np.random.default_rng(3)
    grown = 0
    for t in range(60):
        a, b = (int(x) for x in rng.integers(3, 41, 2))
        pts = _lattice_with_clutter(rng, a, b)
        limit = (None, max(a, b) + 1, int(rng.integers(4, 12)))[t % 3]
        grids = assemble_grids(pts, rng.random(len(pts)), limit=limit)
        assemble_grids(pts, None, limit=limit, strips=True)
        grown += max((len(g) for g in grids), default=0) > 12 * 12
    assert len(phases) > 100 and all(phases)
    assert grown > 5  # some lattices grew well past the kernel's first cell grid


def test_a_corner_proposed_onto_a_cells_point_is_not_taken_again():
    # a squeezed rim corner's saddle fit can slide onto its neighbour: that point is not a second cell
    from aicalib_tf.detect.chessboard.grid_growth import GrowingGrid

    pts = np.array([[0.0, 0.0], [10.0, 0.0]])
    lat = GrowingGrid(pts, np.ones(2, bool), propose=lambda pred, step: np.array([[10.2, 0.1]] * len(pred)), limit=9)
    lat.take((0, 0), 0)
    lat.take((1, 0), 1)
    assert lat.find(np.array([[12.0, 0.0]]), np.array([3.0]))[0] == -1
