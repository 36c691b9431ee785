"""``vlpcal survey plan``: where to put the LED — a tape survey's grid, a free survey's
references and route, or a wand survey's frame marks — written with a map to print."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import click

from ..datasets import POINTS_COLUMNS, write_truth_csv
from ..reports import survey_plan_figure
from ..reports.survey_text import free_plan_lines, plan_lines
from ..survey import SurveyError, free_route, plan_references, plan_survey
from ..survey.free_plan import PROPOSED_WAND, free_sweep, plan_marks, wand_alternative
from ..writing import OutputSet
from .common import Finite, UserError, _floats, _load_deployment, _output_file
from .survey_shared import (
    CAPTURE_SECONDS,
    CAPTURE_SETS,
    FLAGS,
    _check_wand_fits,
    say_lines,
)


@click.command("plan")
@click.option("--deployment", "-d", "deployment_path", required=True,
              type=click.Path(dir_okay=False), help="The deployment (room, cameras).")
@click.option("--out", "-o", required=True, type=click.Path(dir_okay=False),
              help="points.csv to write; a printable map (.png) goes beside it.")
@click.option("--step", default=None, type=Finite(0.0005, 2000.0),
              help="Grid spacing, m.  [default: as fine as the cameras' precision needs "
                   "(given --tape and --spot-noise)]")
@click.option("--heights", default=None,
              help="LED heights to survey, m, comma-separated (two or more).  [default: "
                   "0,0.35,0.7; with --free the floor, 20 % and 40 % of the ceiling for the "
                   "references, the sweep from the floor to 40 %]")
@click.option("--free", is_flag=True,
              help="Plan a free survey: a few reference points to measure, and a route to "
                   "carry the LED along while the cameras record.")
@click.option("--free-height", default=None, type=Finite(0.0, 10000.0),
              help="Plan a free survey whose LED rides a robot at this height, m (implies "
                   "--free): the route is driven, not swept.")
@click.option("--wand", default=None, type=Finite(1e-6, 10000.0), metavar="LENGTH",
              help="Plan a wand survey, m between the wand's two LEDs (implies --free): no "
                   "tape; frame marks (O, X, F1–F3) to put on the floor instead of references, "
                   "and a route to wave the wand along.")
@click.option("--references", type=click.IntRange(2, 200), default=None,
              help="With --free: how many reference points (3 or more; 2 or more with "
                   "--free-height).  [default: 6 where cameras overlap in threes, up to 12 on "
                   "a line of cameras]")
@click.option("--min-per-camera", default=12, show_default=True, type=click.IntRange(6, 1000),
              help="Points each camera must see (more let the calibration fit more of its lens).")
@click.option("--tape", default=0.003, show_default=True, type=Finite(1e-7, 100.0),
              help="How precisely the positions will be measured, m per axis (a tape: 0.003); "
                   "positions are written to what it marks (1 mm).")
@click.option("--spot-noise", default=0.03, show_default=True, type=Finite(1e-4, 10.0),
              help="The spots' precision, px (0.03: the default detector at its best).")
def survey_plan(deployment_path, out, step, heights, free, free_height, wand, references,
                min_per_camera, tape, spot_noise):
    """Plan the survey: where to put the LED, with ids, and a map to print.

    The grid is made finer until the survey's own measurement errors add at most 10 % to the
    cameras' error (20 % for an unlucky tape), predicted from --tape and --spot-noise; the
    time it takes is said (about a minute a point). With --free: the reference points of a
    free survey, and the route to carry the LED; with --wand: frame marks instead of
    references. A free plan says, before anyone measures, whether the free LED can link every
    camera, and names those it cannot with what would link them.

    Example: vlpcal survey plan -d planned.yaml --out survey-plan.csv
    """
    dep = _load_deployment(deployment_path)
    free = free or free_height is not None or wand is not None
    hs = _plan_heights(dep, heights, free, free_height, wand, references, step)
    _check_wand_fits(wand, dep, to_wave=True)
    plan, route = _plan_of(dep, deployment_path, hs, heights, free, free_height, wand,
                           references, step, min_per_camera, tape, spot_noise)
    out = _output_file(_plan_file(out), inputs=(deployment_path,), beside=(".png",))
    _write_plan(out, dep, plan, route, wand)
    if route is not None:
        say_lines(free_plan_lines(plan, route, out, wand, CAPTURE_SETS, CAPTURE_SECONDS,
                                  names=FLAGS))
        return
    alternative = wand_alternative(dep, plan)
    say_lines(plan_lines(plan, hs, out, step is not None, min_per_camera,
                         None if alternative is None else alternative.minutes,
                         f"vlpcal survey plan -d {deployment_path} --wand {PROPOSED_WAND:g} "
                         "--out marks.csv", names=FLAGS))


def _plan_heights(dep, heights, free, free_height, wand, references, step) -> list:
    """The options checked against each other and the cameras; the LED heights to plan
    (``--heights``, or 0, 0.35 and 0.7 m)."""
    if references is not None and not free:
        raise click.BadParameter("is for a free survey (--free)", param_hint="--references")
    if wand is not None and (references is not None or free_height is not None):
        raise click.BadParameter("a wand survey plans frame marks, not references, and is "
                                 "waved by hand (drop --references and --free-height)",
                                 param_hint="--wand")
    if free and step is not None:
        raise click.BadParameter("is for a tape survey's grid; a free or wand survey plans "
                                 "a few points and a route (drop --step)", param_hint="--step")
    if references is not None and references < 3 and free_height is None:
        raise click.BadParameter(f"expected 3 or more (2 or more with --free-height), got "
                                 f"{references}", param_hint="--references")
    hs = _floats(heights or "0,0.35,0.7", "--heights")
    top = 0.9 * min(c.position[2] for c in dep.cameras)  # below the cameras, in their view
    # (a free or wand plan given no heights sweeps below its cameras by itself)
    if (heights is not None or not free) and (len(set(hs)) < 2
                                              or any(not 0 <= h < top for h in hs)):
        if heights is None:
            raise click.BadParameter(f"the default heights (0, 0.35 and 0.7 m) do not fit "
                                     f"below {top:.3g} m (nine tenths of the lowest camera's): "
                                     "give the LED heights to survey", param_hint="--heights")
        else:
            raise click.BadParameter(f"expected two or more heights, all different, from 0 to "
                                     f"below {top:.3g} m (nine tenths of the lowest camera's), "
                                     f"got {heights!r}", param_hint="--heights")
    if free_height is not None and not 0 <= free_height < top:
        raise click.BadParameter(f"expected a height from 0 to below {top:g} m (nine tenths of "
                                 f"the lowest camera's), got {free_height:g}",
                                 param_hint="--free-height")
    return hs


def _plan_of(dep, deployment_path, hs, heights, free, free_height, wand, references, step,
             min_per_camera, tape, spot_noise):
    """The plan the options ask for — a wand's frame marks, a free survey's references, or a
    tape survey's grid — and a free or wand survey's route (None for a tape survey)."""
    sweep = hs if heights else None
    if wand is not None and not heights:  # the wand's LEDs: from the floor to 40 % + half of it
        sweep = free_sweep(dep, wand)
    route = None
    try:
        if wand is not None:
            plan = plan_marks(dep, tape=tape)
            route = free_route(dep, sweep)
        elif free:
            plan = plan_references(dep, references, hs if heights else None, tape=tape)
            route = free_route(dep, (free_height,) * 2 if free_height is not None else sweep)
        else:
            plan = plan_survey(dep, step, hs, min_per_camera, tape=tape, spot_noise=spot_noise)
    except SurveyError as e:
        raise UserError(f"{deployment_path}: {e}") from None
    return plan, route


def _plan_file(out) -> Path:
    """``--out`` checked: a .csv whose folder can be made, not a survey's own record."""
    out = Path(out)
    if out.suffix.lower() != ".csv":  # its map is written beside it as .png
        raise UserError(f"{out}: the survey plan is a CSV file (.csv); its map (.png) goes "
                        "beside it")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise UserError(f"{out}: cannot make its folder ({e.strerror})") from None
    if out.is_dir():
        raise UserError(f"{out}: is a folder (expected a points.csv file to write)")
    real = out.resolve()  # (through a link: the file it would replace)
    beside = [d for d in ("frames", "free", "observations.csv") if (real.parent / d).exists()]
    if out.exists() and beside:
        raise UserError(f"{out}: is a survey's record (it has {', '.join(beside)} beside it); "
                        "the plan would replace its measurements: write the plan to another "
                        "file")
    return out


def _write_plan(out, dep, plan, route, wand) -> None:
    """The plan's points.csv (a wand's marks with their unmeasured cells empty) and its map,
    both or neither."""
    with OutputSet(out.with_suffix(".png"), out) as (png, csv_file):  # both, or neither
        if wand is not None:  # the marks' unmeasured coordinates are empty cells
            with open(csv_file, "w", newline="", encoding="utf-8") as f:
                w = csv.writer(f, lineterminator="\n")
                w.writerow(POINTS_COLUMNS)
                w.writerows([pid, *("" if math.isnan(v) else f"{v:g}" for v in row)]
                            for pid, row in zip(plan.ids, plan.recorded))
        else:
            write_truth_csv(csv_file, plan.ids, plan.xyz, id_column=POINTS_COLUMNS[0])
        survey_plan_figure(png, dep, plan, route)
