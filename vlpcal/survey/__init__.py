"""Survey layer: what measured LED positions teach about an install.

- :mod:`.calibration`: each camera's pose and lens from the survey points it saw, then every
  camera and surveyed position together, with the survey's measurement precision estimated
  from the fit;
- :mod:`.camera_fit`: one camera fitted to its points; :mod:`.least_squares`: the robust
  solvers behind every fit;
- :mod:`.lens`: the nested lens models and how well a survey determines them;
  :mod:`.lens_decision`: each camera's model chosen by the held-out 3D error, beside plain
  OpenCV;
- :mod:`.held_out`: honest accuracy, k-fold by survey point;
- :mod:`.regions`: the paper's approach (c), the best pair per floor region;
- :mod:`.free`: a free survey (the LED moved freely, a few references measured) — its
  refusals :mod:`.free_checks`, starts :mod:`.free_start`, joint fit :mod:`.free_fit`, lens
  models :mod:`.free_lens`; a wand's :mod:`.wand`; the frame the references or marks fix
  :mod:`.datum`, :mod:`.marks_frame`, :mod:`.network`, :mod:`.frame_error`;
- :mod:`.plan`: where to put the LED for a tape survey, :mod:`.free_plan` for a free or wand
  survey (:mod:`.linkage`: whether a free LED can link every
  camera; :mod:`.budget`: what a tape survey costs the fixes); :mod:`.spots`: the survey's
  spots as the locator sees them; :mod:`.pipeline`: the whole of ``vlpcal survey
  calibrate``; :mod:`.results`: what it returns, typed.
"""

from .calibration import (
    Calibration,
    LensChoice,
    SurveyError,
    calibrate,
    estimate_precision,
    fold_of,
    refine_jointly,
)
from .camera_fit import CameraFit, fit_camera
from .free_plan import FreeRoute, free_route, plan_references
from .held_out import FUSION_CHOICES, HELD_OUT, HeldOutCase, error_stats, held_out
from .lens import LENS_MODELS, MIN_POINTS_POSE, LensModel, lens_params, lens_support
from .pipeline import calibrate_free_survey, calibrate_survey
from .plan import MIN_POINTS_PLANNED, SurveyPlan, plan_survey
from .regions import learn_region_map, region_cell
from .results import (
    FreeCamera,
    FreeSurveyResult,
    Precision,
    SurveyResult,
    TapeCamera,
)
from .spots import WandSpots, free_spots, survey_spots, wand_spots

__all__ = [
    "FUSION_CHOICES", "HELD_OUT", "HeldOutCase", "LensModel", "Precision", "TapeCamera",
    "FreeCamera", "LENS_MODELS", "MIN_POINTS_PLANNED", "MIN_POINTS_POSE",
    "Calibration", "CameraFit", "LensChoice", "SurveyError", "SurveyPlan", "SurveyResult",
    "calibrate", "calibrate_survey", "error_stats", "estimate_precision",
    "fit_camera", "fold_of", "held_out", "learn_region_map", "lens_params", "lens_support",
    "plan_survey", "plan_references", "free_route", "FreeRoute", "refine_jointly", "region_cell",
    "survey_spots",
    "free_spots", "wand_spots", "WandSpots",
    "calibrate_free_survey", "FreeSurveyResult",
]
