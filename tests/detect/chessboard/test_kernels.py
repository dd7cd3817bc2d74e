"""aicalib_tf.kernels: the compiled loops against closed-form answers."""

import numpy as np

from aicalib_tf.detect.chessboard.lattice_kernels import lattice_predict, nearest_predict, nearest_steps
from aicalib_tf.detect.corners.sampling import sample_windows


def test_lattice_predict_recovers_an_exact_homography_and_refuses_a_line():
    h = np.array([[31.0, 4.0, 120.0], [-3.0, 27.0, 90.0], [1.2e-3, -8e-4, 1.0]])
    c, r = np.meshgrid(np.arange(6), np.arange(4))
    ids = np.stack([c.ravel(), r.ravel()], 1).astype(np.float64)

    def project(q):
        p = np.c_[q, np.ones(len(q))] @ h.T
        return p[:, :2] / p[:, 2:]

    pts = project(ids)
    want = np.array([[[-1.0, -1.0], [7.0, 2.0], [2.5, 1.5]]])
    near = np.arange(len(ids))[None]
    got = lattice_predict(ids, pts, near, want)
    assert np.abs(got[0] - project(want[0])).max() < 1e-8
    line = np.flatnonzero(ids[:, 1] == 0)[None]  # collinear ids: no homography
    assert np.isnan(lattice_predict(ids, pts, line, want)).all()


def test_nearest_predict_fits_each_want_to_its_k_nearest_ids_ties_to_the_lower_index():
    rng = np.random.default_rng(3)
    c, r = np.meshgrid(np.arange(7), np.arange(5))
    ids = np.stack([c.ravel(), r.ravel()], 1).astype(np.float64)
    pts = ids * 20.0 + rng.normal(0, 1.5, ids.shape)  # a bent lattice: each set's fit differs
    want = np.array([[3.0, 2.0], [-1.0, 0.0], [2.5, 1.5], [8.0, 4.0], [0.2, 3.9]])
    d2 = ((want[:, None, :] - ids[None]) ** 2).sum(-1)
    near = np.sort(np.argsort(d2, axis=1, kind="stable")[:, :12], axis=1)  # a stable sort, the first 12, in index order
    expect = lattice_predict(ids, pts, near, want[:, None, :])[:, 0]
    assert np.array_equal(nearest_predict(ids, pts, want, 12), expect)
    assert not np.array_equal(nearest_predict(ids, pts, want, 8), expect)


def test_sample_windows_is_bilinear_with_replicated_borders():
    rng = np.random.default_rng(3)
    img = rng.random((7, 9)).astype(np.float32)
    pts = np.array([[4.25, 3.5], [0.1, 0.2], [8.7, 6.9]])
    got = sample_windows(img, pts, 2)
    d = np.arange(-2, 3)
    for p, row in zip(pts, got):
        xs, ys = np.meshgrid(p[0] + d, p[1] + d)
        want = []
        for x, y in zip(xs.ravel(), ys.ravel()):
            x0, y0 = int(np.floor(x)), int(np.floor(y))
            fx, fy = x - x0, y - y0
            v = lambda yy, xx: float(img[min(max(yy, 0), 6), min(max(xx, 0), 8)])
            want.append((1 - fy) * ((1 - fx) * v(y0, x0) + fx * v(y0, x0 + 1))
                        + fy * ((1 - fx) * v(y0 + 1, x0) + fx * v(y0 + 1, x0 + 1)))
        np.testing.assert_allclose(row, want, atol=1e-6)


def test_seed_block_places_the_3x3_block_of_a_lattice_and_no_block_on_a_line():
    from aicalib_tf.detect.chessboard.grid_growth import TOLERANCE
    from aicalib_tf.detect.chessboard.grid_seeds import _OFFS, MAX_CELL_AREA, MAX_SPAN_RATIO, MAX_STEP_RATIO
    from aicalib_tf.detect.chessboard.grid_kernels import seed_block

    u, v = np.array([10.0, 1.0]), np.array([-2.0, 9.0])
    ij = np.array([(i, j) for j in range(-2, 3) for i in range(-2, 3)], np.float64)
    pts = 100 + ij[:, :1] * u + ij[:, 1:] * v
    k = 12  # (0, 0)
    d2 = ((pts - pts[k]) ** 2).sum(1)
    d2[k] = np.inf
    near = np.argsort(d2)[:12].astype(np.int64)
    rules = (_OFFS[None], 1, TOLERANCE, MAX_STEP_RATIO, MAX_CELL_AREA, MAX_SPAN_RATIO)
    b, ua, va, found = seed_block(pts, k, near, np.zeros(0), np.ones(len(pts), bool), *rules)
    assert b == 0
    steps = {tuple(np.round(pts[near[ua]] - pts[k], 6)), tuple(np.round(pts[near[va]] - pts[k], 6))}
    assert steps <= {tuple(u), tuple(-u), tuple(v), tuple(-v)} and len(steps) == 2  # the board's own steps
    got = pts[found] - pts[k]
    want = _OFFS[:, :1] * (pts[near[ua]] - pts[k]) + _OFFS[:, 1:] * (pts[near[va]] - pts[k])
    np.testing.assert_allclose(got, want, atol=1e-9)
    line = np.flatnonzero(ij[:, 1] == 0)  # one row of the lattice only: no two directions
    k_line = int(np.flatnonzero(line == k)[0])
    near_line = np.array([i for i in range(len(line)) if i != k_line], np.int64)
    assert seed_block(pts[line], k_line, near_line, np.zeros(0), np.ones(len(line), bool), *rules)[0] == -1


def _residuals_reference(ids, pts, k=8):
    """lattice_residuals written as array code: each corner against a fit of its k nearest other ids."""
    d2 = ((pts[:, None, :] - pts[None, :, :]) ** 2).sum(-1)  # in pts' precision
    np.fill_diagonal(d2, np.inf)
    step = np.sqrt(d2.min(axis=1))
    di = ((ids[:, None, :] - ids[None, :, :]) ** 2).sum(-1).astype(np.float64)
    np.fill_diagonal(di, np.inf)
    near = np.argsort(di, axis=1, kind="stable")[:, :k]
    fids, fpts = ids.astype(np.float64), pts.astype(np.float64)
    pred = lattice_predict(fids, fpts, near, fids[:, None, :])[:, 0]
    unit = np.array([[1, 0], [-1, 0], [0, 1], [0, -1]])
    have = set(map(tuple, ids.tolist()))
    alone = np.array([not any((i + a, j + b) in have for a, b in unit) for i, j in ids.tolist()])
    if alone.any():
        qs = lattice_predict(fids, fpts, near[alone], fids[alone, None, :] + unit[None])
        lat = np.linalg.norm(qs - pred[alone, None, :], axis=2).min(axis=1)
        step[alone] = np.where(np.isfinite(lat), np.minimum(step[alone], lat), step[alone])
    res = np.linalg.norm(pred - pts, axis=1) / step
    return np.where(np.isfinite(res), res, 0.0)


def test_lattice_residuals_match_the_array_code_in_float32_and_float64():
    from aicalib_tf.detect.chessboard.lattice import lattice_residuals

    rng = np.random.default_rng(0)
    c, r = np.meshgrid(np.arange(9), np.arange(6))
    grid = np.stack([c.ravel(), r.ravel()], 1)
    lone = 0
    for trial in range(60):
        ids = grid[rng.random(len(grid)) < rng.uniform(0.3, 1.0)]  # holes: some corners have no found neighbour
        if len(ids) < 9:
            continue
        h = np.array([[20 + rng.normal(), rng.normal(), 100], [rng.normal(), 20 + rng.normal(), 80],
                      [rng.normal(0, 1e-3), rng.normal(0, 1e-3), 1]])
        p = np.c_[ids, np.ones(len(ids))] @ h.T
        pts = p[:, :2] / p[:, 2:] + rng.normal(0, 0.3, (len(ids), 2))
        pts = pts.astype(np.float32) if trial % 2 else pts
        have = set(map(tuple, ids.tolist()))
        lone += sum(not any((i + a, j + b) in have for a, b in ((1, 0), (-1, 0), (0, 1), (0, -1))) for i, j in ids.tolist())
        assert np.array_equal(lattice_residuals(ids, pts), _residuals_reference(ids, pts))
    assert lone > 0


def test_lattice_residuals_of_two_corners_at_one_place_are_zero_as_in_the_array_code():
    # no step to divide by: the reference's x / 0 is not finite and counts 0; the loop must not raise
    from aicalib_tf.detect.chessboard.lattice import lattice_residuals

    c, r = np.meshgrid(np.arange(4), np.arange(3))
    ids = np.stack([c.ravel(), r.ravel()], 1)
    for dtype in (np.float64, np.float32):
        pts = (ids * 20.0 + 5.0).astype(dtype)
        pts[5] = pts[4]
        got = lattice_residuals(ids, pts)
        assert got[4] == 0.0 and got[5] == 0.0 and np.isfinite(got).all()
        assert np.array_equal(got, _residuals_reference(ids, pts))


def test_nearest_steps_gives_the_spacing_at_the_nearest_point():
    pts = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 4.0], [30.0, 0.0]])  # spacings 10, 4, 4, 20
    want = np.array([[1.0, 1.0], [9.0, 3.0], [29.0, 0.0], [5.0, 0.0]])  # the last is a tie: the first point counts
    assert np.array_equal(nearest_steps(pts, want), [10.0, 4.0, 20.0, 10.0])
