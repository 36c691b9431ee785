"""The survey's terminal reports: a plan, a calibration (tape or free), its test points, in a
surveyor's words — each a function of the library's typed results that returns the lines to
print (:class:`Line`: its text, and whether it is a warning for stderr).

The words name what a user can change by its parameter (``point_sigma``, ``wand`` …); a
command passes ``names``, the same keys spelled as its flags (``--point-sigma``), so that the
terminal says what to type."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import NamedTuple

import numpy as np

from ..fusion import FixStatus
from ..survey import LENS_MODELS, FreeSurveyResult, SurveyResult, plan_references
from ..survey.calibration import format_length
from ..survey.plan import (
    MAX_PLANNED_POINTS,
    TYPICAL_SHARE,
    UNLUCKY_SHARE,
    duration_words,
)
from ..survey.suspects import suspect_words
from ..survey.wand import WAND_PRECISION

#: how the words name a parameter a user can change, by default (a Python caller's names);
#: ``plan_references`` is what plans a free survey's references
PARAMETERS = {"lens": "lens", "point_sigma": "point_sigma", "wand": "wand",
              "test_points": "test_points", "free_height": "free_height",
              "min_per_camera": "min_per_camera", "tape": "tape", "step": "step",
              "plan_references": "plan_references"}


class Line(NamedTuple):
    """One line of a terminal report; ``err``: a warning, for stderr."""

    text: str
    err: bool = False


def _unit_for(values) -> tuple[str, float]:
    """One unit for a table, chosen so that its smallest figure reads with three digits."""
    return next(((u, f) for u, f in (("m", 1.0), ("cm", 100.0), ("mm", 1000.0), ("µm", 1e6))
                 if values and min(values) * f >= 0.1), ("µm", 1e6))


# -- a survey plan ---------------------------------------------------------------------------

def budget_sentence(plan, chosen: bool, names: Mapping[str, str] = PARAMETERS) -> str:
    """What the plan's predicted calibration costs the fixes, in a surveyor's words (``chosen``:
    the grid was sized to the budget, not stated)."""
    typical, unlucky = plan.predicted
    given = f"at ±{format_length(plan.tape)} per axis and {plan.spot_noise:g} px spots"
    if not np.isfinite(typical):
        return (f"{given}: no place is triangulated by two cameras (none overlap, or they "
                "stand at one spot), so what the survey costs the fixes cannot be predicted")
    said = (f"{given}, calibrating from these points is predicted to add "
            f"{100 * (typical - 1):.0f} % to the fixes' mean error "
            f"({100 * (unlucky - 1):.0f} % for an unlucky tape)")
    if plan.coarser:
        said += "; coarser grids: " + "; ".join(
            f"{format_length(st)}: {n} points, +{100 * (a - 1):.0f} % ({100 * (b - 1):.0f} %)"
            for st, n, a, b in plan.coarser)
    if plan.meets_budget:
        return said
    if chosen:
        return (f"{said}. A finer grid would pass {MAX_PLANNED_POINTS} points: measure the "
                f"positions more precisely ({names['tape']}; the cost falls with the square "
                "of it)")
    return (f"{said}; without {names['step']} the grid is made finer until that is at most "
            f"{100 * TYPICAL_SHARE:.0f} % ({100 * UNLUCKY_SHARE:.0f} %)")


def plan_lines(plan, heights, out, step_given: bool, min_per_camera: int, wand_minutes=None,
               wand_command: str = "", names: Mapping[str, str] = PARAMETERS) -> list[Line]:
    """A tape survey's plan (:class:`~vlpcal.survey.SurveyPlan`) written to ``out``: its
    points, what calibrating from them costs the fixes, each camera's share, the time it takes
    — and, where that is hours, a wand survey's time (``wand_minutes``; ``wand_command`` plans
    it)."""
    lines = [Line(f"{len(plan.ids)} points at h = "
                  f"{', '.join(f'{h:g}' for h in sorted(set(heights)))} m "
                  f"(grid {format_length(plan.step)}; positions to "
                  f"{format_length(plan.mark)}) "
                  f"→ {out}, map {out.with_suffix('.png')}"),
             Line(budget_sentence(plan, chosen=not step_given, names=names))]
    few = [f"{cid} {int(n)}" for cid, n in zip(plan.camera_ids, plan.seen.sum(axis=1))
           if n < min_per_camera]
    if few:
        lines.append(Line(f"note: fewer points than {names['min_per_camera']} {min_per_camera} "
                          f"(the finest grid gives no more): {', '.join(few)}"))
    ids = plan.camera_ids
    for k, cid in enumerate(ids):
        shared = [(ids[j], int((plan.seen[k] & plan.seen[j]).sum())) for j in range(len(ids))
                  if j != k]
        pairs = ", ".join(f"{cj} {n}" for cj, n in shared if n)
        lines.append(Line(f"  {cid}: sees {int(plan.seen[k].sum())} points; shared with "
                          f"{pairs or '–'}"))
    said = f"time: about {duration_words(plan.minutes)} with a tape (a minute a point)"
    if wand_minutes is not None:
        said += (f"; a wand survey needs no tape: 5 marks on the floor (about 5 min) and "
                 f"about {duration_words(wand_minutes)} of waving a 0.5 m wand "
                 f"({wand_command})")
    lines.append(Line(said))
    return lines


def free_plan_lines(plan, route, out, wand=None, capture_sets: int = 1800,
                    capture_seconds: float = 180.0,
                    names: Mapping[str, str] = PARAMETERS) -> list[Line]:
    """A free survey's plan in words: the references (or a wand's frame marks) to measure, the
    route (:class:`~vlpcal.survey.FreeRoute`), and whether it links every camera; a capture
    records ``capture_sets`` sets in ``capture_seconds``."""
    lines = []
    if wand is not None:
        axis = {"x": "+x", "y": "+y"}[plan.axis]
        lines.append(Line(
            f"wand survey ({wand:g} m between its LEDs; no tape): {len(plan.ids)} marks on "
            f"the floor, each seen by two cameras or more → {out} (its empty cells: not "
            f"measured), map {out.with_suffix('.png')}; put a mark where each is said "
            "(in the plan's frame, to a few cm) and let the cameras see the LED on it:"))
        o = plan.xyz[0, :2]
        for pid, (x, y, _), seen in zip(plan.ids, plan.xyz, plan.seen.T):
            who = "+".join(c for c, s in zip(plan.camera_ids, seen) if s)
            what = ("the origin" if pid == "O" else
                    f"{np.hypot(x - o[0], y - o[1]):.2f} m along the plan's {axis} from O: the "
                    "calibrated frame's +x" if pid == "X" else "anywhere near, on the floor")
            lines.append(Line(f"  {pid}: ({x:.2f}, {y:.2f}) m, {what}; seen by {who}"))
    else:
        hs = sorted(set(plan.xyz[:, 2].round(6)))
        lines.append(Line(
            f"{len(plan.ids)} reference points at h = {', '.join(f'{h:g}' for h in hs)} m "
            f"→ {out}, map {out.with_suffix('.png')}: measure each to "
            f"{format_length(plan.mark)} (about {duration_words(plan.minutes)}), and let "
            "the cameras see the LED there"))
        for pid, (x, y, z), seen in zip(plan.ids, plan.xyz, plan.seen.T):
            who = "+".join(c for c, s in zip(plan.camera_ids, seen) if s)
            lines.append(Line(f"  {pid}: ({x:.3f}, {y:.3f}, {z:.3f}) m, seen by {who}"))
    stops = f"{len(route.stops)} stop{'s' if len(route.stops) > 1 else ''}"
    time = (f"about {duration_words(route.minutes)}" if route.low == route.high else
            f"one sweep each: about {duration_words(route.minutes)}")
    low = np.flatnonzero(route.tops < route.high - 1e-9)
    if route.low == route.high:
        lines.append(Line(
            f"then, while the cameras record, drive the robot (its LED at {route.low:g} m) "
            f"through {stops} ({time}) and over the floor between them (the map shows the "
            f"route); calibrate with {names['free_height']} {route.low:g}:"))
    else:
        what = "wave the wand" if wand is not None else "carry the LED"
        lines.append(Line(
            f"then, while the cameras record, {what} along {stops} ({time}), sweeping "
            f"{'its LEDs' if wand is not None else 'it'} from {route.low:g} to "
            f"{route.high:g} m and back at each"
            + (f" ({len(low)} stop{'s' if len(low) != 1 else ''} only as high as said: "
               "there two cameras share a thin overlap near the floor)" if len(low) else "")
            + " (the map shows the route; walk it again until `survey capture` has "
            f"its {capture_sets} sets, {capture_seconds / 60:g} min at 10 a second):"))
    for n, ((x, y), pairs, quarters, t) in enumerate(
            zip(route.stops, route.pairs, route.quarters, route.tops), start=1):
        what = [f"pairs {', '.join(f'{a}+{b}' for a, b in pairs)}"] if pairs else []
        what += [", ".join(quarters)] if quarters else []
        what += [f"sweep only to {t:.2f} m"] if t < route.high - 1e-9 else []
        lines.append(Line(f"  {n:2d}. ({x:.2f}, {y:.2f}) m: {'; '.join(what)}"))
    said = route.linkage.sentences()
    if len(route.groups) <= 1:
        lines.append(Line(f"linked: {said[0]}"))
        return lines
    lines.append(Line(f"warning: {said[0]}; a free survey would refuse them after the "
                      "measuring:"))
    lines += [Line(f"warning: {line}") for line in said[1:]]
    return lines


# -- a tape survey's calibration -------------------------------------------------------------

def calibration_lines(result: SurveyResult,
                      names: Mapping[str, str] = PARAMETERS) -> list[Line]:
    """A tape survey's calibration: the lens decisions, the held-out table, the per-camera
    verdicts and the mis-measured and suspect points."""
    n = len(result.points)
    prec = result.precision
    lines = [Line("\nlens, per camera (chosen by the held-out 3D error of survey points unless "
                  f"{names['lens']} forces one):")]
    lines += [Line(f"  {sentence}") for sentence in result.lens]
    lines += _lens_table(result)
    how = "estimated from the fit" if prec.estimated else "as stated"
    lines.append(Line(f"survey positions: ±{format_length(prec.point_sigma_m)} per axis "
                      f"({how}); spots ±{prec.pixel_sigma_px:.2g} px"))
    # one unit for the table, chosen so that the best row reads with three figures
    unit, scale = _unit_for([st["mean"] for st in result.stats.values()
                             if st["mean"] is not None])
    lines.append(Line(f"\nheld-out 3D error ({result.folds}-fold by survey point, {n} points), "
                      f"{unit}; the reference is the measured position itself "
                      f"(±{format_length(prec.point_sigma_m)} per axis ≈ "
                      f"{format_length(prec.point_sigma_m * 3 ** 0.5)} in 3D):"))
    lines.append(Line(f"{'':32s} {'mean':>7s} {'median':>7s} {'p95':>7s} {'max':>7s} "
                      f"{'fixed':>6s}"))
    for label, st in result.stats.items():
        if st["mean"] is None:
            lines.append(Line(f"{label:32s} {'–':>7s} {'':23s} {st['fixed']:6.0%}"))
            continue
        cells = " ".join(f"{st[k] * scale:7.3f}" if st[k] * scale < 10 else
                         f"{st[k] * scale:7.1f}" for k in ("mean", "median", "p95", "max"))
        lines.append(Line(f"{label:32s} {cells} {st['fixed']:6.0%}"))
    lines.append(Line("(fixed: share of the held-out points with a fix; a point one camera saw "
                      "has none)"))
    lines.append(Line(f"\n{'camera':8s} {'RMS px':>7s} {'points':>7s} {'lens':>9s} "
                      f"{'moved':>9s} {'turned °':>9s}  rejected spots"))
    for r in result.cameras:
        lines.append(Line(f"{r.camera:8s} {r.rms_px:7.3f} {r.points:7d} {r.lens_model:>9s} "
                          f"{format_length(r.moved_m):>9s} {r.turned_deg:9.2f}  "
                          f"{', '.join(r.outliers) or '–'}"))
    for r in result.cameras:
        if r.moved_share > 0.2 or r.turned_deg > 20:
            traded = r.lens_model != "pose" and "weakly determined" in r.lens
            why = ("; its lens line says its fit trades the lens against the pose: the move "
                   "may be that, not the camera" if traded else
                   ": is this survey from this site, and are the camera ids the same?")
            lines.append(Line(f"warning: camera {r.camera} moved {format_length(r.moved_m)} "
                              f"({r.moved_share:.0%} of its distance to the survey) and turned "
                              f"{r.turned_deg:.0f}° from the deployment{why}", err=True))
    if result.mismeasured:
        lines.append(Line("\nmis-measured survey points (rejected by the cameras that saw them; "
                          "how far from its record the calibrated cameras put the LED):"))
        lines += [Line(f"  {pid}: {format_length(off)}" if np.isfinite(off) else
                       f"  {pid}: –") for pid, off in result.mismeasured]
    lines += suspect_lines(result.suspects, "points.csv", held_out=True)
    return lines


def _lens_table(result: SurveyResult) -> list[Line]:
    """Per camera and lens model, the held-out 3D error with the other cameras as chosen;
    then the choice beside plain OpenCV on the same folds."""
    rows = [r for r in result.cameras if r.lens_candidates]
    d = result.decision
    if not rows or d is None:
        return []
    if not d.points:
        return [Line("  no survey point was seen by two cameras: each lens was chosen by its "
                     "own held-out reprojection error")]
    lines = []
    figures = [c.get("held_out_3d_m") for r in rows for c in r.lens_candidates.values()]
    unit, scale = _unit_for([f for f in figures if f is not None])
    for cid, s in d.starts_disagree.items():
        nom = next(c for c in result.deployment.cameras if c.id == cid)
        centre = ((nom.width - 1) / 2, (nom.height - 1) / 2)
        lines.append(Line(
            f"  {cid}: its fit ({s.model}) has more than one minimum: the principal point "
            f"{s.chained[0] - centre[0]:+.0f}, {s.chained[1] - centre[1]:+.0f} px from "
            f"the image centre (from the simpler fits) or {s.best[0] - centre[0]:+.0f}, "
            f"{s.best[1] - centre[1]:+.0f} px (from the data's own starts, "
            f"{s.cost_ratio:.3g} × lower in cost): the lower kept, then refined with "
            "the rest"))
    lines.append(Line(f"held-out 3D error per camera's lens model, {unit} (each camera fitted "
                      f"alone, the others as chosen; * chosen: the simplest within one "
                      f"standard error of the lowest; – not fitted):\n  {'camera':8s}"
                      + "".join(f"{m:>11s}" for m in LENS_MODELS)))
    for r in rows:
        cells = []
        for m in LENS_MODELS:
            v = r.lens_candidates.get(m, {}).get("held_out_3d_m")
            cell = "–" if v is None else f"{v * scale:.3g}" + ("*" if m == r.lens_model
                                                                else "")
            cells.append(f"{cell:>11s}")
        lines.append(Line(f"  {r.camera:8s}" + "".join(cells)))
    capped = (f"; {d.opencv_capped} of its points past the {format_length(d.cap_m)} cap, "
              "where a fold it could not fit or a wild fix counts" if d.opencv_capped else "")
    lines.append(Line(
        f"  this choice {format_length(d.held_out_m)}; plain OpenCV calibrateCamera "
        f"(full lens, from the deployment's) "
        f"{format_length(d.opencv_m) if math.isfinite(d.opencv_m) else 'no fit'} on the "
        f"same folds{capped} ({d.points} points seen by two or more cameras, "
        "triangulated by least squares; the k-fold table below fits cameras and points "
        "jointly and fixes points as the locator does)"))
    if d.held_out_m > d.opencv_m:
        lines.append(Line(f"warning: plain OpenCV locates the held-out survey points better "
                          f"({format_length(d.opencv_m)} against "
                          f"{format_length(d.held_out_m)})", err=True))
    return lines


def suspect_lines(suspects, points, held_out: bool) -> list[Line]:
    """A warning per survey point whose left-out (or held-out) error stands far beyond the
    others' (:mod:`vlpcal.survey.suspects`), with what leaving it out gives; ``points``: the
    file to correct."""
    return [Line(f"warning: {suspect_words(s, held_out)} Check it and correct it in {points} "
                 f"(or delete its line and its folder frames/{s.point_id}), then calibrate "
                 "again.") for s in suspects]


def written_lines(result: SurveyResult | FreeSurveyResult, paths) -> list[Line]:
    """What a calibration wrote (``paths``: the deployment, report and figure) and the fusion
    it chose — or, for a tape survey no held-out point of which got a fix, the warning that
    nothing measured these cameras."""
    if isinstance(result, FreeSurveyResult):
        return [Line(f"\nwrote {paths[0]} (fusion robust: all cameras by least squares), "
                     f"{paths[1]}, {paths[2]}")]
    if all(st["mean"] is None for st in result.stats.values()):
        return [Line("warning: no held-out survey point got a fix (none was seen by two "
                     "cameras): nothing says how well these cameras locate; survey where they "
                     "overlap", err=True),
                Line(f"\nwrote {paths[0]} (fusion {result.fusion}: no fusion could be "
                     f"compared), {paths[1]}, {paths[2]}")]
    return [Line(f"\nwrote {paths[0]} (fusion {result.fusion}: the table's row "
                 f"'{result.fusion_label}', the best held out), {paths[1]}, {paths[2]}")]


# -- a free (or wand) survey's calibration ---------------------------------------------------

def free_calibration_lines(result: FreeSurveyResult, nominal, points_file,
                           names: Mapping[str, str] = PARAMETERS) -> list[Line]:
    """A free survey's calibration from the ``nominal`` deployment: what the free LED gave,
    each camera's fit and coverage, the references left out in turn, the datum floor, the
    wand's held-out length, the predicted error, and every warning (``points_file``: the
    references' file, to correct a suspect in)."""
    cal = result.calibration
    free_height, marks_only = result.free_height, cal.marks_only
    refs = "marks" if marks_only else "references"
    lines = [Line(
        f"free survey: {result.free_sets} sets (moments a camera saw the LED), "
        f"{cal.used_sets} used (seen by "
        + ("a camera at the stated height" if free_height is not None else
           "two or more cameras")
        + f"); {sum(cal.rejected.values())} spots rejected, {cal.dropped_sets} sets of "
        f"two views that disagree dropped; {refs} ±"
        f"{cal.point_sigma * 1000:.2g} mm {'in height' if marks_only else 'per axis'} ("
        + ("estimated" if cal.point_sigma_estimated else
           "assumed" if cal.point_sigma_assumed else "as stated")
        + f"), spots ±{cal.pixel_sigma:.3g} px")]
    lines += [Line(f"note: {note}") for note in cal.notes]
    lines += [Line(f"  {words}") for words in result.lens]
    lines.append(Line(f"\n{'camera':8s} {'spread px':>9s} {'free sets':>9s} {'rejected':>8s} "
                      f"{'moved':>9s} {'turned °':>8s}  lens"))
    lines += [Line(f"{r.camera[:8]:8s} {r.spread_px:9.3f} {r.free_sets_seen:9d} "
                   f"{r.rejected_spots:8d} {r.moved_m * 1000:6.1f} mm "
                   f"{r.turned_deg:8.2f}  {r.lens_model}") for r in result.cameras]
    lines.append(Line("\nwhere the free LED went, in each camera's image:"))
    lines += [Line(f"  {r.coverage}") for r in result.cameras]
    lines += _reference_lines(result, points_file, names)
    lines += _free_warning_lines(result, nominal, names)
    return lines


def _reference_lines(result: FreeSurveyResult, points_file,
                     names: Mapping[str, str]) -> list[Line]:
    """What fixes a free survey's frame: the references left out in turn, the suspects among
    them, the datum floor, the marks' frame, the wand's held-out length, the predicted
    error."""
    cal = result.calibration
    wand = cal.wand
    n_ref = len(result.reference_ids)
    marks, marks_only = cal.in_marks_frame, cal.marks_only  # frame marks among them; all
    refs = "marks" if marks_only else "references"
    lines = []
    loo = cal.leave_one_out[np.isfinite(cal.leave_one_out)]
    if len(loo):
        tape = cal.point_sigma * 1000 * math.sqrt(3)
        own = (f"their heights only, O and X setting the frame; the floor's unevenness under "
               f"them, ±{cal.point_sigma * 1000:.1f} mm "
               f"{'assumed' if cal.point_sigma_assumed else 'as stated'}, is in these figures"
               if marks_only else f"their own tape, ±{tape:.1f} mm in 3D, included")
        lines.append(Line(f"\n{refs}, each left out in turn where the rest still fix the room "
                          f"(its spots place it): mean {loo.mean() * 1000:.1f} mm, max "
                          f"{loo.max() * 1000:.1f} mm over {len(loo)} of them ({own})"))
    else:
        lines.append(Line(f"\n{refs}: too few to leave one out (the rest must still fix the "
                          "room)"))
    lines += suspect_lines(cal.suspects, points_file, held_out=False)
    lines.append(Line(
        f"your {n_ref} "
        + ("marks" if marks_only else "reference points and marks" if marks else
           "reference points")
        + (f" and the wand's length (±{WAND_PRECISION:.1%})" if wand else "")
        + f" fix the room to about {cal.datum_floor * 1000:.1f} mm (the datum floor: no "
        "calibration does better on average"
        + (f", predicted at the ±{cal.point_sigma * 1000:g} mm assumed"
           if cal.point_sigma_assumed else "") + "); "
        + (f"place the LED on the marks more carefully ({names['point_sigma']} says how "
           "well), or add floor marks, to do better" if marks else
           "measure more points, or more precisely, to do better")))
    if marks:
        lines.append(Line("the calibrated deployment is in the marks' frame: O is its origin, "
                          "X on its +x axis, the floor marks at z = 0 (the room moved with the "
                          "cameras)"))
    if cal.wand_error is not None:
        w = cal.wand_error
        worst = max(w.per_camera.items(), key=lambda t: -1 if np.isnan(t[1]) else t[1])
        lines.append(Line(
            f"wand: {w.sets} held-out sets (never in the fit) triangulate its "
            f"{wand * 1000:g} mm to ±{w.mean * 1000:.2f} mm on average (p95 "
            f"{w.p95 * 1000:.2f} mm; worst camera {worst[0]} {worst[1] * 1000:.2f} mm)"
            + (f"; {w.discarded} more whose spots do not meet (a reflection or another "
               "light taken for an end) left out" if w.discarded else "")))
    if math.isfinite(cal.predicted_error):
        lines.append(Line(f"predicted: fixes with these cameras "
                          f"{format_length(cal.predicted_error)} off on average over the "
                          "floor (the survey's adjustment, linearised; exact cameras: "
                          f"{format_length(cal.exact_error)})"))
    return lines


def _free_warning_lines(result: FreeSurveyResult, nominal,
                        names: Mapping[str, str]) -> list[Line]:
    """A free survey's warnings: cameras it fixes weakly, cameras far from the ``nominal``
    deployment, a doubtful scale."""
    cal = result.calibration
    wand = cal.wand
    n_ref = len(result.reference_ids)
    lines = []
    if cal.references_disagree:
        loo_mm = float(np.nanmean(cal.leave_one_out)) * 1000
        allowed = cal.left_out_allowed * 1000
        lines.append(Line(
            f"warning: this survey fixes the cameras weakly: its references, each left "
            f"out in turn, land {loo_mm:.1f} mm from their records on average where "
            f"their own noise and the predicted error allow about {allowed:.1f} mm — "
            "cameras whose lens and pose the free LED could not tell apart; measure "
            f"references where those cameras see, wave a wand ({names['wand']}), or give "
            f"{names['test_points']} to see"))
    elif cal.weakly_fixed:
        asked = len(plan_references(nominal).ids)
        lines.append(Line(
            f"warning: this survey fixes the cameras weakly: fixes are predicted "
            f"{format_length(cal.predicted_error)} off, where exact cameras in the frame "
            f"of your references would be "
            f"{format_length(math.hypot(cal.exact_error, cal.datum_floor))}: the free LED "
            f"cannot fix the lenses across the cameras' overlaps with {n_ref} references; "
            f"measure more ({names['plan_references']} asks for {asked}), or give "
            f"{names['test_points']} to see"))
    for r in result.cameras:
        if r.moved_share > 0.2 or r.turned_deg > 20:
            lines.append(Line(
                f"warning: camera {r.camera} moved {format_length(r.moved_m)} "
                f"({r.moved_share:.0%} of its distance to the free LED) and turned "
                f"{r.turned_deg:.1f}° from the deployment: is this survey from this "
                "site, and are its camera ids right?"))
    if result.scale_doubtful:
        top = max(c.position[2] for c in result.deployment.cameras)
        said = (f"the wand's length ({format_length(wand)})" if wand is not None else
                "the references' measurements (their units, a misread tape)")
        lines.append(Line(
            f"warning: the calibrated cameras stand {result.plan_scale:.2f} × as high "
            f"above the floor as the deployment's (the highest {format_length(top)}, "
            f"under a {format_length(nominal.ceiling_height)} ceiling): check {said}"))
    return lines


# -- test points -----------------------------------------------------------------------------

#: a test point's status, in words (fusion's, and the locator's outside_room)
_UNFIXED = {FixStatus.NO_SPOT: "seen by no camera",
            FixStatus.ONE_CAMERA: "seen by one camera only",
            FixStatus.INCONSISTENT: "whose spots no camera pair agreed on",
            FixStatus.DEGENERATE: "whose rays barely meet",
            "outside_room": "that locate would refuse as outside_room (the fix beyond the "
                            "room by more than its predicted error)"}


def test_point_lines(result: SurveyResult | FreeSurveyResult) -> list[Line]:
    """How far the calibrated cameras fix the test points from their measured positions
    (``result.test_points``, none: no line), with the measurement's own share of that."""
    tp = result.test_points
    if tp is None:
        return []
    fixed = round(tp["fixed"] * tp["points"])
    why = [f"{n} {_UNFIXED.get(status, status)}" for status, n in tp["statuses"].items()]
    unfixed = f" ({'; '.join(why)})" if why else ""
    if not fixed:
        return [Line(f"\ntest points: none of {tp['points']} was fixed{unfixed}")]
    free = isinstance(result, FreeSurveyResult)
    sigma = result.calibration.point_sigma if free else result.precision.point_sigma_m
    if free and result.calibration.marks_only:  # marks say nothing of how a tape was read
        own = "whose own measurement error is in these figures too"
    else:
        own = (f"whose own measurement error is in these figures: at the references' "
               f"±{format_length(sigma)} per axis, about {format_length(sigma * 1.596)} of the "
               "mean")
    return [Line(f"\ntest points (never used by the calibration): {fixed} of {tp['points']} "
                 f"fixed{unfixed}, mean {format_length(tp['mean'])}, p95 "
                 f"{format_length(tp['p95'])}, max {format_length(tp['max'])} from their "
                 f"measured positions ({own})")]
