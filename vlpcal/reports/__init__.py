"""Reports: what commands and the demo give the user beside their results — the figures
(PNG: a plan's :mod:`.figures`, a calibration's :mod:`.calibration_figures`, a run's
:mod:`.run_figures`), a survey calibration's files and report (:mod:`.calibration_files`),
and the survey's terminal text (:mod:`.survey_text`), each a function of the library's typed
results."""

from .calibration_figures import calibration_figure, free_calibration_figure
from .calibration_files import test_point_errors, with_test_points, write_calibration
from .figures import plan_maps, save_figure, survey_plan_figure
from .run_figures import demo_figure, run_figure, track_figure

__all__ = ["calibration_figure", "demo_figure", "free_calibration_figure", "plan_maps",
           "run_figure", "save_figure", "survey_plan_figure", "test_point_errors",
           "track_figure", "with_test_points", "write_calibration"]
