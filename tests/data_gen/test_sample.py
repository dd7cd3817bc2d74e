import numpy as np

from data_gen import draw_scene, make_sample


def test_scene_renders_the_sample_image_every_time():
    for preset, index in (("occluded", 3), ("hard", 5), ("clutter", 0)):
        s = make_sample(preset, 21, index, size=(320, 240))
        sc = draw_scene(preset, 21, index, size=(320, 240))
        assert np.array_equal(sc.render(), s.image)
        assert np.array_equal(sc.render(), s.image)  # the noise is drawn afresh from the same state
        assert np.array_equal(sc.corners, s.corners) and np.array_equal(sc.visible, s.visible)


def test_scene_moves_only_the_board():
    sc = draw_scene("occluded", 21, 3, size=(320, 240))
    assert sc.has_board and len(sc.occluders) > 0
    moved = sc.render(sc.rvec, sc.tvec + np.array([sc.board.square_size, 0.0, 0.0]))
    diff = np.abs(moved.astype(int) - sc.render().astype(int)) > 8
    assert diff.any()
    # the shift changes pixels near the board only: none far outside the corners' bounding box
    cols, rows = sc.board.pattern_size
    step = np.linalg.norm(np.diff(sc.corners.reshape(rows, cols, 2), axis=1), axis=2).max()  # px, one square
    lo, hi = sc.corners.min(0) - 3 * step, sc.corners.max(0) + 3 * step
    ys, xs = np.nonzero(diff)
    assert np.all((xs >= lo[0]) & (xs <= hi[0]) & (ys >= lo[1]) & (ys <= hi[1]))
