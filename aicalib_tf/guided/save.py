"""Saving a guided session: the full model choice over the kept views, the quality checks, the files.

Shared by the video/camera command line (:mod:`aicalib_tf.guided.workflow`) and the live page
(:mod:`aicalib_tf.live`). The files are those of the photo path (camera.yaml, camera.json,
camera_info.yaml, report.png, report.txt), written into a folder that replaces ``out`` as a whole
(:class:`aicalib_tf.outfolder.OutputFolder`).
"""

from __future__ import annotations

import dataclasses

from aicalib_tf.calib.fit import Calibration, CalibrationError, fit_views
from aicalib_tf.calib.quality import assess

__all__ = ["calibrate_session", "save_calibration_set", "save_session", "MIN_SAVED_VIEWS", "PARTIAL_HEAD"]

PARTIAL_HEAD = "PARTIAL calibration (the run was stopped early)\n"  # the report's first line for a partial run

MIN_SAVED_VIEWS = 3  # a calibration needs at least this many kept views


def calibrate_session(session, meta: dict) -> tuple[Calibration, list]:
    """(calibration with its quality, the views it used) of a session's final views (kept, or chosen
    among the views seen: :meth:`~aicalib_tf.guided.session.GuidedCalibration.final_views`); CalibrationError
    with fewer than :data:`MIN_SAVED_VIEWS`."""
    if len(session.views) < MIN_SAVED_VIEWS:
        raise CalibrationError(f"only {len(session.views)} views kept so far; need at least {MIN_SAVED_VIEWS} "
                               "(show the board in more places)")
    views = session.final_views()
    cal = session.result(meta={**meta, "used_frames": [int(v.name.removeprefix("frame")) for v in views]}, views=views)
    used = [v for v in views if v.name in set(cal.views)]
    return dataclasses.replace(cal, quality=assess(cal, used, fit=fit_views)), used


def save_calibration_set(cal: Calibration, used, out, head=()) -> str:
    """Write the calibration's files into ``out`` (replaced as a whole); returns the report text."""
    from aicalib_tf.calib.report import format_report, report_figure
    from aicalib_tf.calib.workflow import write_calibration_files
    from aicalib_tf.outfolder import OutputFolder

    report = "\n".join([*head, format_report(cal, used, skipped={}, total=len(used) + len(cal.rejected))])
    if cal.meta.get("partial"):
        report = PARTIAL_HEAD + report
    figure = report_figure(cal, used)
    with OutputFolder(out, "calibration") as folder:
        write_calibration_files(folder.path, cal, report, figure)
    return report


def save_session(session, out, meta: dict, head=()) -> str:
    """Calibrate a session's kept views and write the files into ``out``; returns the report text."""
    cal, used = calibrate_session(session, meta)
    return save_calibration_set(cal, used, out, head)
