"""Reports: what commands and the demo give the user beside their results — the figures
(PNG, :mod:`.figures`), a survey calibration's files and report (:mod:`.calibration_files`),
and the survey's terminal text (:mod:`.survey_text`), each a function of the library's typed
results."""

from .calibration_files import test_point_errors, with_test_points, write_calibration
from .figures import (
    calibration_figure,
    demo_figure,
    free_calibration_figure,
    plan_maps,
    run_figure,
    save_figure,
    survey_plan_figure,
    track_figure,
)

__all__ = ["calibration_figure", "demo_figure", "free_calibration_figure", "plan_maps",
           "run_figure", "save_figure", "survey_plan_figure", "test_point_errors",
           "track_figure", "with_test_points", "write_calibration"]
