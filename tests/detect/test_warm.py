"""The warm-up views reach the full-board and the partial-board paths of the pipeline."""

from aicalib_tf.detect.pipeline import detect_corners
from aicalib_tf.detect.warm import synthetic_board, warm


def test_warm_views_give_a_full_and_a_partial_board():
    full = detect_corners(synthetic_board(), (9, 6))
    cut = detect_corners(synthetic_board(shift=(230.0, 0.0)), (9, 6))
    assert full.complete and len(full.corners) == 54
    assert not cut.complete and 9 <= len(cut.corners) < 54


def test_warm_returns_its_time_and_plans_the_frame_size():
    from aicalib_tf.cnn.model import load_model

    model = load_model("default")
    assert warm(model, (800, 600)) > 0.0
    assert (1, 600, 800, 1) in model.planned_shapes()
