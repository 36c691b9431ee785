"""The whole calibration, as ``vlpcal survey calibrate`` runs it."""

from __future__ import annotations

import numpy as np

from ..deployment import Deployment, provenance
from ..fusion import FusionMethod
from ..geometry import rodrigues
from .calibration import SurveyError, calibrate, lens_sentence
from .coverage import camera_words, quarter_counts
from .free import calibrate_free
from .held_out import FUSION_CHOICES, held_out
from .lens import LensModel
from .marks_frame import cameras_in_marks_frame, polygons_in_marks_frame
from .regions import learn_region_map
from .results import (
    FreeCamera,
    FreeSurveyResult,
    Precision,
    SurveyResult,
    TapeCamera,
    finite_or_none,
)
from .suspects import far_beyond, suspects_of

#: the calibrated file's residual limit, in held-out residuals of its worst camera
RESIDUAL_LIMIT = 5.0


def residual_limit(cal) -> float:
    """px: :data:`RESIDUAL_LIMIT` times the worst camera's held-out reprojection error (its
    in-sample RMS when its lens was forced): a camera further off than that on a new point is
    not seeing the LED (a reflection, a lamp)."""
    worst = 0.0
    for fit, choice in zip(cal.fits, cal.lens):
        px = choice.candidates.get(choice.chosen, {}).get("held_out_px")
        worst = max(worst, px if px is not None else fit.rms_px)
    return RESIDUAL_LIMIT * worst


def calibrate_survey(dep, X, uv, ids, lens: str | dict = "auto", folds: int = 5,
                     point_sigma: float | str = "auto", progress=None,
                     sources: dict | None = None, intrinsics: bool | None = None
                     ) -> SurveyResult:
    """Calibrate ``dep``'s cameras from a survey — each camera's lens model chosen by held-out
    error (``lens="auto"``) or as given, the positions' precision estimated
    (``point_sigma="auto"``) or as given (m) — measure the held-out accuracy (k-fold) with
    those choices, learn the region map (approach (c)) and choose the fusion with the lowest
    held-out mean; returns the calibrated deployment, its provenance naming ``sources``.
    ``progress(i, n)`` counts each camera's lens models, the joint fit and each fold.
    ``intrinsics=True``: ``lens="full"``.
    """
    if intrinsics:
        lens = "full"
    cams = dep.cameras
    total = len(cams) + 1 + folds
    cal = calibrate(cams, X, uv, ids, point_sigma=point_sigma, lens=lens, folds=folds,
                    progress=(lambda i, n: progress(i, total)) if progress else None)
    if progress:
        progress(len(cams) + 1, total)
    per_point: dict = {}
    stated = dep.extra.get("fusion", {}).get("max_residual")
    limit = float(stated) if stated is not None else residual_limit(cal)
    stats = held_out(cams, X, uv, ids, dep.room, cal.models, folds, cal.point_sigma,
                     progress=(lambda i, n: progress(len(cams) + 1 + i, total))
                     if progress else None,
                     per_point=per_point, pair_method=dep.pair_method, max_residual=limit,
                     nominal_max_residual=dep.max_residual, starts=cal.cameras,
                     pixel_sigma=cal.pixel_sigma)
    rmap = learn_region_map(cal.cameras, uv, cal.adjusted, dep.room, pair_method=dep.pair_method)
    best = min(FUSION_CHOICES, key=lambda c: stats[c.label]["mean"]
               if stats[c.label]["mean"] is not None else np.inf)
    suspects = _suspect_points(cams, X, uv, ids, dep, cal, folds, per_point[best.label],
                               best.label, limit)
    extra = {k: v for k, v in dep.extra.items() if k != "provenance"}
    # (the file holds plain strings: a YAML writer knows no enum)
    extra["fusion"] = {**extra.get("fusion", {}), "method": best.fusion.value,
                       "max_residual": limit, "region_map": rmap.to_dict()}
    precision = Precision(cal.point_sigma, cal.point_sigma_estimated, cal.pixel_sigma)
    extra["provenance"] = provenance(
        "vlpcal survey calibrate", **{"from": {**(sources or {}), "points": len(ids)}},
        lens={c.camera_id: str(c.chosen) for c in cal.lens}, point_sigma_m=cal.point_sigma,
        point_sigma_estimated=cal.point_sigma_estimated,
        held_out_mean_m={k: v["mean"] for k, v in stats.items()})
    rows, words = [], []
    X, uv = np.asarray(X, float), np.asarray(uv, float)
    for nom, fit, choice, uv_k in zip(cams, cal.fits, cal.lens, uv):
        c = fit.camera
        dR = rodrigues(c.rotation) @ rodrigues(nom.rotation).T
        angle = float(np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1, 1))))
        seen = np.isfinite(uv_k).all(axis=1)
        distance = float(np.median(np.linalg.norm(X[seen] - c.center,
                                                  axis=1))) if seen.any() else float("nan")
        moved = float(np.linalg.norm(np.subtract(c.position, nom.position)))
        sentence = lens_sentence(choice, c, nom)
        words.append(sentence)
        rows.append(TapeCamera(
            camera=c.id, rms_px=fit.rms_px, points=fit.used, outliers=fit.outliers,
            nominal_position_m=list(map(float, nom.position)), moved_m=moved,
            moved_cm=moved * 100, moved_share=moved / distance, turned_deg=angle,
            lens_model=LensModel(fit.model), lens_forced=choice.forced,
            lens_candidates=choice.candidates, lens=sentence, fx=c.fx, fy=c.fy, cx=c.cx,
            cy=c.cy, dist=list(c.dist)))
    calibrated = Deployment(dep.name, dep.ceiling_height, dep.room, cal.cameras, dep.keep_out,
                            extra)
    return SurveyResult(calibrated, stats, per_point, rows, cal.mismeasured, best.fusion,
                        np.asarray(X, float), precision, words, folds, fusion_label=best.label,
                        decision=cal.decision, suspects=suspects)


def _suspect_points(nominal, X, uv, ids, dep, cal, folds, errors, label, limit) -> list:
    """The survey points whose held-out error (``errors``, m: each located by cameras
    calibrated without it, with the fusion ``label``) stands far beyond the others'
    (:func:`~.suspects.far_beyond`, the points' own noise in 3D the floor) and whose record
    two or more of the cameras that saw it reject (a wrong record is wrong in every view; a
    point in a camera's corner that the rest of the survey does not reach, or one camera's
    wrong spot, is far off held out too, but only that camera disagrees: on the simulated
    cheap-wide installs, seeds 0–4, 1–5 such points a survey stood 6–180 × beyond the others,
    none rejected by two cameras). With the others' held-out mean with them and with the
    k-fold check run again without them."""
    errors = np.asarray(errors, float)
    rejected = {}
    for fit in cal.fits:
        for p in fit.outliers:
            rejected[p] = rejected.get(p, 0) + 1
    named, beyond = far_beyond(errors, np.sqrt(3) * cal.point_sigma)
    named &= np.array([rejected.get(p, 0) >= 2 for p in ids], bool)
    if not named.any():
        return []
    keep = np.flatnonzero(~named)
    again: dict = {}
    X, uv = np.asarray(X, float), np.asarray(uv, float)
    try:
        held_out(nominal, X[keep], uv[:, keep], [ids[i] for i in keep], dep.room, cal.models,
                 folds, cal.point_sigma, per_point=again, pair_method=dep.pair_method,
                 max_residual=limit, nominal_max_residual=dep.max_residual,
                 starts=cal.cameras, pixel_sigma=cal.pixel_sigma)
        without = np.full(len(errors), np.nan)
        without[keep] = again[label]
    except SurveyError:  # the rest too few for the check
        without = np.full(len(errors), np.nan)
    both = np.isfinite(errors) & np.isfinite(without) & ~named
    with_, out = ((float(errors[both].mean()), float(without[both].mean())) if both.any()
                  else (float("nan"),) * 2)
    return suspects_of(ids, errors, named, beyond, with_, out)


def _heights_ratio(nominal, calibrated) -> float:
    """The calibrated cameras' median height above the floor (z = 0 in the references' or the
    marks' frame) over the plan's: a wrong scale shows in every height at once."""
    plan = float(np.median([c.position[2] for c in nominal]))
    got = float(np.median([c.position[2] for c in calibrated]))
    return got / plan if plan > 0 else float("nan")


def calibrate_free_survey(dep, X, uv, ids, uv_free, lens: str = "auto",
                          point_sigma: float | str = "auto", free_height: float | None = None,
                          progress=None, sources: dict | None = None,
                          wand: float | None = None, labelled: bool = False
                          ) -> FreeSurveyResult:
    """Calibrate ``dep``'s cameras from a free survey (:func:`~.free.calibrate_free`): the
    references ``X``/``uv``/``ids`` and the free sets' spots ``uv_free``; the region map
    learned from the fitted free positions, the all-camera fusion, the residual limit from
    the free spots' spread. With a ``wand`` (m), ``uv_free`` is C×M×2×2 (each camera's two
    spots, in the LEDs' order if ``labelled``). Returns the calibrated deployment and its
    report."""
    cams = dep.cameras
    cal = calibrate_free(cams, X, uv, ids, uv_free, lens=lens, point_sigma=point_sigma,
                         free_height=free_height, room=dep.room, progress=progress, wand=wand,
                         labelled=labelled)
    ok = np.isfinite(cal.free_xyz).all(axis=1)
    n_sets = int(np.shape(uv_free)[1])
    uv_free = cal.free_uv
    rmap = learn_region_map(cal.cameras, uv_free[:, ok], cal.free_xyz[ok], cal.room,
                            pair_method=dep.pair_method)
    worst = max((v for v in cal.spread_px.values() if np.isfinite(v)), default=1.0)
    extra = {k: v for k, v in dep.extra.items() if k != "provenance"}
    extra["fusion"] = {**extra.get("fusion", {}), "method": FusionMethod.ROBUST.value,
                       "max_residual": RESIDUAL_LIMIT * worst, "region_map": rmap.to_dict()}
    counted = {"marks" if cal.marks_only else "references": len(ids), "free_sets": n_sets}
    extra["provenance"] = provenance(
        "vlpcal survey calibrate", **{"from": {**(sources or {}), **counted}},
        lens={c.camera_id: str(c.chosen) for c in cal.lens}, point_sigma_m=cal.point_sigma,
        point_sigma_estimated=cal.point_sigma_estimated, datum_floor_m=cal.datum_floor,
        free_height_m=free_height, wand_m=wand, point_sigma_assumed=cal.point_sigma_assumed,
        predicted_error_m=finite_or_none(cal.predicted_error),
        wand_error_m=None if cal.wand_error is None else {
            "mean": finite_or_none(cal.wand_error.mean), "p95": finite_or_none(cal.wand_error.p95),
            "held_out_sets": cal.wand_error.sets})
    rows, words = [], []
    # in the marks' frame, each camera's move is judged against the plan moved into it
    planned = cameras_in_marks_frame(cams, cal.cameras) if cal.in_marks_frame else cams
    for nom, plan, c, choice in zip(cams, planned, cal.cameras, cal.lens):
        dR = rodrigues(c.rotation) @ rodrigues(plan.rotation).T
        angle = float(np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1, 1))))
        sentence = lens_sentence(choice, c, nom)
        words.append(sentence)
        mine = np.asarray(uv_free)[cams.index(nom)]
        seen = int(np.isfinite(mine).all(axis=1).sum())
        moved = float(np.linalg.norm(np.subtract(c.position, plan.position)))
        there = np.isfinite(cal.free_xyz).all(axis=1) & np.isfinite(mine).all(axis=1)
        where = cal.free_xyz[there] if there.any() else cal.references
        distance = float(np.median(np.linalg.norm(where - np.asarray(c.position), axis=1)))
        rows.append(FreeCamera(
            camera=c.id, spread_px=cal.spread_px[c.id], free_sets_seen=seen,
            coverage=camera_words(nom, mine, dep.room),
            quarter_sightings=quarter_counts(nom, mine).tolist(),
            rejected_spots=cal.rejected[c.id], moved_m=moved,
            moved_share=moved / max(distance, 1e-300), turned_deg=angle,
            lens_model=LensModel(choice.chosen), lens=sentence, fx=c.fx, fy=c.fy, cx=c.cx, cy=c.cy,
            dist=list(c.dist)))
    keep_out = dep.keep_out
    if cal.in_marks_frame:  # the deployment in the marks' frame
        keep_out = polygons_in_marks_frame(cams, cal.cameras, dep.keep_out)
    calibrated = Deployment(dep.name, dep.ceiling_height, cal.room, cal.cameras, keep_out,
                            extra)
    return FreeSurveyResult(calibrated, cal, rows, words, list(ids), np.asarray(X, float),
                            n_sets, free_height,
                            plan_scale=_heights_ratio(cams, cal.cameras))
