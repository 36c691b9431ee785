"""A survey calibration's files — the calibrated deployment, its ``.report.json`` and its
figure, written as one set — and the held-out evidence of test points it never saw."""

from __future__ import annotations

import json
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..deployment import dumps
from ..locator import Locator
from ..survey import FreeSurveyResult, SurveyResult, error_stats
from ..writing import OutputSet
from .calibration_figures import calibration_figure, free_calibration_figure


def test_point_errors(dep, X, uv, ids) -> dict:
    """Held-out evidence a calibration never saw: measured test points ``X`` (N×3)
    and their spots ``uv`` (C×N×2, as :func:`~vlpcal.survey.survey_spots` gives them: the
    deployment's pixel corrections applied) located with the calibrated deployment ``dep`` by
    its :class:`~vlpcal.locator.Locator` — its fusion, region map, residual limit and its
    judgement of what is no position in the room (``outside_room``, ``degenerate``), so that a
    point counts as fixed exactly when ``locate`` with the same file would fix it;
    the errors of the fixed ones against the measured positions, whose own tape is in them.
    Returns the report's ``test_points`` entry (``statuses``: how many points got each status
    other than ``ok``)."""
    X = np.asarray(X, float)
    uv = np.asarray(uv, float)
    offsets = dep.pixel_offsets  # the locator applies them itself, to the spots as detected
    raw = uv + np.array([offsets.get(c.id, (0.0, 0.0)) for c in dep.cameras])[:, None, :]
    fixes = Locator(dep).locate_pixels(raw)
    err = np.linalg.norm(fixes.X - X, axis=1)
    views = np.isfinite(uv).all(axis=2).sum(axis=0)
    status = [str(s) for s in fixes.status]
    return {"points": len(X), **error_stats(err), "seen_by_fewer_than_two": int((views < 2).sum()),
            "statuses": dict(Counter(s for s in status if s != "ok")),
            "per_point": [{"point_id": p, "error_m": float(e) if np.isfinite(e) else None,
                           "status": st} for p, e, st in zip(ids, err, status)]}


def write_calibration(out, result: SurveyResult | FreeSurveyResult, notes=(),
                      header: str = "") -> tuple[Path, Path, Path]:
    """A survey calibration's files: the calibrated deployment ``out``, ``.report.json`` and
    ``.png`` beside it, as one :class:`~vlpcal.writing.OutputSet` (an error or a kill leaves
    the previous set whole). Returns the deployment, report and figure paths."""
    out = Path(out)
    paths = out.with_suffix(".report.json"), out.with_suffix(".png"), out  # the deployment last
    with OutputSet(*paths) as (report, png, dep):
        dep.write_text(dumps(result.deployment, header=header), encoding="utf-8")
        report.write_text(json.dumps(result.report(notes), indent=2), encoding="utf-8")
        if isinstance(result, FreeSurveyResult):
            free_calibration_figure(png, result)
        else:
            calibration_figure(png, result.stats, result.per_point, result.points,
                               result.deployment.cameras,
                               [r for r in result.cameras if r.get("lens_candidates")],
                               result.cameras, f"{out.name}: survey calibration of "
                               f"{result.deployment.name}, held-out error")
    return paths[2], paths[0], paths[1]




def with_test_points(result: SurveyResult | FreeSurveyResult, X, uv, ids):
    """``result`` with the errors of test points it never saw (:func:`test_point_errors`:
    ``X`` N×3, ``uv`` C×N×2, ``ids``); when any was fixed, their mean also joins the
    provenance's held-out means, which ``vlpcal show`` tells."""
    tp = test_point_errors(result.deployment, X, uv, ids)
    dep = result.deployment
    prov = dep.extra.get("provenance")
    if round(tp["fixed"] * tp["points"]) and isinstance(prov, dict):
        held = prov.get("held_out_mean_m")
        prov = {**prov, "held_out_mean_m": {**(held if isinstance(held, dict) else {}),
                                            "test points": tp["mean"]}}
        dep = replace(dep, extra={**dep.extra, "provenance": prov})
    return replace(result, deployment=dep, test_points=tp)
