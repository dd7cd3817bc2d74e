"""aicalib_tf.kernels: the compiled loops against closed-form answers."""

import numpy as np

from aicalib_tf.kernels import lattice_predict, sample_windows


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
