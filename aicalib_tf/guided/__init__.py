"""Guided calibration from a stream of frames: frame selection, guidance and a stop rule around the
calibration of :mod:`aicalib_tf.calib` (see :mod:`aicalib_tf.guided.session`)."""

__all__ = ["GuidedCalibration", "GuidedConfig", "Update"]


def __getattr__(name):
    if name in __all__:
        from aicalib_tf.guided import session

        return getattr(session, name)
    raise AttributeError(name)
