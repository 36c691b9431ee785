"""Honest accuracy: survey points located by cameras calibrated without them (k-fold)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..fusion import FusionMethod, fuse
from ..geometry import Camera
from .calibration import SurveyError, calibrate, fold_of
from .regions import learn_region_map


def error_stats(err_m) -> dict:
    """mean, median, p90, p95, max (m) and the share of points with a fix (None: no fix)."""
    e = np.asarray(err_m, float)
    ok = np.isfinite(e)
    if not ok.any():
        return {"mean": None, "median": None, "p90": None, "p95": None, "max": None,
                "fixed": 0.0}
    e = e[ok]
    return {"mean": float(e.mean()), "median": float(np.median(e)),
            "p90": float(np.percentile(e, 90)), "p95": float(np.percentile(e, 95)),
            "max": float(e.max()), "fixed": float(ok.mean())}


class HeldOutCase(NamedTuple):
    """One row of the held-out comparison: which cameras, which fusion, and its label (the
    row's name in the table and the report's ``held_out_m`` key)."""

    label: str
    cameras: str  #: "nominal" or "calibrated"
    fusion: FusionMethod


#: the held-out comparisons, in the table's order; the calibrated ones are the fusions a
#: calibrated deployment may be given
HELD_OUT = (HeldOutCase("nominal, (a) mean of pairs", "nominal", FusionMethod.MEAN),
            HeldOutCase("nominal, (b) nearest pair", "nominal", FusionMethod.NEAREST),
            HeldOutCase("nominal, all-camera LS", "nominal", FusionMethod.ROBUST),
            HeldOutCase("calibrated, (a) mean of pairs", "calibrated", FusionMethod.MEAN),
            HeldOutCase("calibrated, (b) nearest pair", "calibrated", FusionMethod.NEAREST),
            HeldOutCase("calibrated, (c) region map", "calibrated", FusionMethod.REGION),
            HeldOutCase("calibrated, all-camera LS", "calibrated", FusionMethod.ROBUST))
#: the fusions a tape survey chooses among, by held-out mean
FUSION_CHOICES = tuple(c for c in HELD_OUT if c.cameras == "calibrated")


def held_out(nominal: list[Camera], X, uv, ids, room, lens: str | dict = "pose", folds: int = 5,
             point_sigma: float = 0.003, progress=None, seed: int = 0,
             per_point: dict | None = None, pair_method: str = "paper",
             max_residual: float = 2.0, nominal_max_residual: float | None = None,
             starts: list[Camera] | None = None, pixel_sigma: float | None = None) -> dict:
    """k-fold accuracy by survey point: calibrate on the other folds (with the lens models
    ``lens`` and the positions' precision ``point_sigma`` m), locate this fold's points from
    their spots, compare with their measured positions. Never the fitted points. The nominal
    cameras are judged with ``nominal_max_residual`` (their own file's limit), the calibrated
    ones with ``max_residual``. ``starts``: the calibration on every point, whose minimum each
    fold's fit starts from, and ``pixel_sigma`` its spots' precision (px): each fold is then
    one joint fit, the whole survey's starts and precision taken as they are.

    Returns label → :func:`error_stats` (metres) over all folds, for :data:`HELD_OUT`; the
    per-point errors go into ``per_point`` (label → N errors, m) when given.
    """
    X = np.asarray(X, float)
    uv = np.asarray(uv, float)
    fold = fold_of(len(X), folds, seed)
    errors = {label: np.full(len(X), np.nan) for label, _, _ in HELD_OUT}
    for f in range(folds):
        test, train = np.flatnonzero(fold == f), np.flatnonzero(fold != f)
        try:
            cal = calibrate(nominal, X[train], uv[:, train], [ids[i] for i in train],
                            point_sigma=point_sigma, lens=lens, starts=starts,
                            pixel_sigma=pixel_sigma)
        except SurveyError as e:
            raise SurveyError(f"too few points for a {folds}-fold held-out check ({e} in a "
                              f"fold of {len(train)}); add points or use fewer folds") from None
        rmap = learn_region_map(cal.cameras, uv[:, train], cal.adjusted, room,
                                pair_method=pair_method)
        for label, which, method in HELD_OUT:
            cams = cal.cameras if which == "calibrated" else nominal
            limit = max_residual if which == "calibrated" or nominal_max_residual is None \
                else nominal_max_residual
            fixed = fuse(cams, uv[:, test], method, region_map=rmap, pair_method=pair_method,
                         max_residual=limit).X
            errors[label][test] = np.linalg.norm(fixed - X[test], axis=1)
        if progress:
            progress(f + 1, folds)
    if per_point is not None:
        per_point.update(errors)
    return {label: error_stats(e) for label, e in errors.items()}
