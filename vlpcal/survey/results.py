"""What a survey calibration returns: the calibrated deployment and the figures behind it, as
typed, frozen records — a tape survey's (:class:`SurveyResult`) and a free or wand survey's
(:class:`FreeSurveyResult`). Their :meth:`report` is the ``.report.json`` beside the
calibrated file; the terminal's words are :mod:`vlpcal.reports.survey_text`'s."""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from ..deployment import Deployment
from ..fusion import FusionMethod
from .free import FreeCalibration
from .lens import LensModel

#: calibrated cameras further apart (or nearer) than this ratio of the plan's are doubtful: an
#: install hung by hand keeps the plan's size to a few per cent; a wand length or a tape read
#: wrong does not
PLAN_SCALE_RATIO = 1.25
#: … or any camera above the ceiling by more than this share of its height
CEILING_SHARE = 0.03


class Record:
    """A frozen record that is also read as the report's JSON object is: ``row["moved_m"]``
    and ``row.get(…)`` give its fields, :meth:`to_dict` the object itself (fields in
    order)."""

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def __getitem__(self, key: str):
        if key not in {f.name for f in fields(self)}:
            raise KeyError(key)
        return getattr(self, key)

    def get(self, key: str, default=None):
        try:
            return self[key]
        except KeyError:
            return default


@dataclass(frozen=True)
class Precision(Record):
    """How precisely the survey's positions and spots were taken to be known."""

    point_sigma_m: float  #: per axis
    estimated: bool  #: from the fit (else as stated)
    pixel_sigma_px: float


@dataclass(frozen=True)
class TapeCamera(Record):
    """One camera calibrated from a tape survey: its fit, its move from the plan, its lens."""

    camera: str
    rms_px: float  #: reprojection RMS of its spots
    points: int  #: survey points its fit used
    outliers: list  #: ids of the points whose spots it rejected
    nominal_position_m: list
    moved_m: float
    moved_cm: float
    moved_share: float  #: of its median distance to the survey points
    turned_deg: float
    lens_model: LensModel
    lens_forced: bool
    lens_candidates: dict  #: model → held-out figures (:class:`~.calibration.LensChoice`)
    lens: str  #: the decision in words
    fx: float
    fy: float
    cx: float
    cy: float
    dist: list


@dataclass(frozen=True)
class FreeCamera(Record):
    """One camera calibrated from a free survey: its free spots' spread, where the free LED
    went in its image, its move from the plan, its lens."""

    camera: str
    spread_px: float  #: RMS reprojection of its free spots
    free_sets_seen: int
    coverage: str  #: where the free LED went in its image, in words
    quarter_sightings: list  #: sightings per image quarter
    rejected_spots: int
    moved_m: float
    moved_share: float  #: of its median distance to the free LED
    turned_deg: float
    lens_model: LensModel
    lens: str  #: the decision in words
    fx: float
    fy: float
    cx: float
    cy: float
    dist: list


@dataclass(frozen=True)
class SurveyResult:
    """A deployment calibrated from a tape survey and the figures behind it (lengths in m)."""

    deployment: Deployment
    stats: dict  #: held-out label → :func:`~.held_out.error_stats`
    per_point: dict  #: held-out label → N errors
    cameras: list[TapeCamera]
    mismeasured: list  #: (point id, m)
    fusion: FusionMethod  #: the fusion chosen by held-out mean
    points: np.ndarray  #: N×3 the survey positions as measured
    precision: Precision
    lens: list  #: per camera, the lens decision in words
    folds: int = 5  #: of the held-out check
    #: the held-out row the fusion was chosen from (:data:`FUSION_CHOICES`)
    fusion_label: str = ""
    test_points: dict | None = None  #: :func:`vlpcal.reports.test_point_errors`, when given
    #: the held-out 3D figures behind the lens models, beside plain OpenCV's
    #: (:class:`~.lens_decision.LensDecision`; None when the lens was forced as "pose")
    decision: object = None
    #: points whose held-out error stands far beyond the others' (:class:`~.suspects.Suspect`)
    suspects: list = field(default_factory=list)

    def report(self, notes=()) -> dict:
        out = {"held_out_m": self.stats, "folds": self.folds,
               "cameras": [c.to_dict() for c in self.cameras], "fusion": self.fusion,
               "lens": self.lens, "precision": self.precision.to_dict(),
               "lens_decision": None if self.decision is None else decision_report(
                   self.decision),
               "mismeasured": [{"point_id": p, "moved_m": m} for p, m in self.mismeasured],
               "suspects": [s.to_dict() for s in self.suspects],
               "notes": list(notes)}
        if self.test_points is not None:
            out["test_points"] = self.test_points
        return out


def decision_report(decision) -> dict:
    """The report's ``lens_decision``: the held-out 3D means (m) of the choice, of plain
    OpenCV on the same folds, and of every camera with one model."""
    return {"held_out_3d_m": finite_or_none(decision.held_out_m),
            "opencv_held_out_3d_m": finite_or_none(decision.opencv_m),
            "one_model_for_all_m": {m: finite_or_none(v) for m, v in decision.uniform_m.items()},
            "models": dict(decision.models), "points": decision.points,
            "cap_m": finite_or_none(decision.cap_m), "opencv_capped": decision.opencv_capped,
            "starts_disagree": {c: {"model": d.model, "chained_principal_px": list(d.chained),
                                    "kept_principal_px": list(d.best),
                                    "cost_ratio": d.cost_ratio}
                                for c, d in decision.starts_disagree.items()}}


@dataclass(frozen=True)
class FreeSurveyResult:
    """A deployment calibrated from a free survey (the LED moved freely, a few references
    measured) or a wand's, and the figures behind it."""

    deployment: Deployment
    calibration: FreeCalibration
    cameras: list[FreeCamera]
    lens: list  #: per camera, the lens decision in words
    reference_ids: list
    points: np.ndarray  #: N×3 the references as measured
    free_sets: int  #: in the bundle
    free_height: float | None = None
    fusion: FusionMethod = FusionMethod.ROBUST
    test_points: dict | None = None  #: :func:`vlpcal.reports.test_point_errors`, when given
    #: the calibrated cameras' size against the plan's: their heights over the floor over the
    #: plan's (a hand-hung install: within a few per cent of 1)
    plan_scale: float = 1.0

    @property
    def scale_doubtful(self) -> bool:
        """Whether the calibrated cameras stand a different size from the plan's — further
        apart or nearer than :data:`PLAN_SCALE_RATIO` allows: a scale from a wrong wand
        length or tape reading, not an install's error."""
        return not 1 / PLAN_SCALE_RATIO < self.plan_scale < PLAN_SCALE_RATIO \
            or self.above_ceiling

    @property
    def above_ceiling(self) -> bool:
        """Whether a calibrated camera stands higher above the floor than the ceiling by more
        than :data:`CEILING_SHARE` of its height: no install puts it there; a scale does."""
        dep = self.deployment
        top = max(c.position[2] for c in dep.cameras)
        return bool(top > (1 + CEILING_SHARE) * dep.ceiling_height)

    def report(self, notes=()) -> dict:
        cal = self.calibration
        out = {"free_survey": {"sets": self.free_sets, "used": cal.used_sets,
                                "dropped_sets": cal.dropped_sets,
                                "free_height_m": self.free_height},
               "plan_scale": self.plan_scale, "scale_doubtful": self.scale_doubtful,
               "references": [{"point_id": p, "left_out_error_m": None if not np.isfinite(e)
                               else float(e)} for p, e in zip(self.reference_ids,
                                                              cal.leave_one_out)],
               "datum_floor_m": cal.datum_floor,
               "predicted_error_m": finite_or_none(cal.predicted_error),
               "exact_cameras_error_m": finite_or_none(cal.exact_error),
               "weakly_fixed": cal.weakly_fixed,
               "references_disagree": cal.references_disagree,
               "suspects": [s.to_dict() for s in cal.suspects],
               "cameras": [c.to_dict() for c in self.cameras], "lens": self.lens,
               "fusion": self.fusion,
               "precision": {"point_sigma_m": cal.point_sigma,
                             "estimated": cal.point_sigma_estimated,
                             "pixel_sigma_px": cal.pixel_sigma},
               "notes": list(notes) + list(cal.notes)}
        if cal.wand_error is not None:
            w = cal.wand_error
            out["wand"] = {"length_m": cal.wand, "held_out_sets": w.sets,
                           "held_out_discarded": w.discarded,
                           "length_error_mean_m": finite_or_none(w.mean),
                           "length_error_p95_m": finite_or_none(w.p95),
                           "length_error_rms_m": finite_or_none(w.rms),
                           "per_camera_mean_m": {c: finite_or_none(v) for c, v in
                                                 w.per_camera.items()}}
        if self.test_points is not None:
            out["test_points"] = self.test_points
        return out


def finite_or_none(x: float) -> float | None:
    """A figure for JSON: the float, or None where it is not finite."""
    return float(x) if np.isfinite(x) else None
