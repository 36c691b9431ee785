"""The surveyor's commands: plan a survey, capture it, calibrate the cameras from it
(``vlpcal survey plan | capture | calibrate``)."""

from __future__ import annotations

import math

import click

from .common import (
    Finite,
    UserError,
    _camera_sources,
    _floats,
    _floor_diagonal,
    _load_deployment,
    _output_file,
    echo,
    main,
)
from .view import DEFAULT_BIND

#: a free or wand survey's capture: at most this long, this many sets (10 a second)
CAPTURE_SECONDS = 180.0
CAPTURE_SETS = 1800


class NoCameraAnswered(UserError):
    """No camera sent a frame (off, unreachable, or too slow): one line naming each and why,
    exit 1 as a live ``locate`` without frames — not a mistake in the command's inputs."""

    exit_code = 1


@main.group()
def survey():
    """Survey calibration: cameras (and region maps) from LED measurements at known points.

    Example: vlpcal survey plan -d planned.yaml --out survey-plan.csv
    """


@survey.command("plan")
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
    from pathlib import Path

    from ..datasets import POINTS_COLUMNS, write_truth_csv
    from ..reports import survey_plan_figure
    from ..survey import SurveyError, plan_survey
    from ..survey.calibration import format_length
    from ..survey.plan import budget_sentence, duration_words, plan_marks

    dep = _load_deployment(deployment_path)
    free = free or free_height is not None or wand is not None
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
    _check_wand_fits(wand, dep, to_wave=True)
    sweep = hs if heights else None
    if wand is not None and not heights:  # the wand's LEDs: from the floor to 40 % + half of it
        from ..survey.plan import free_sweep

        sweep = free_sweep(dep, wand)
    route = None
    try:
        if wand is not None:
            from ..survey import free_route

            plan = plan_marks(dep, tape=tape)
            route = free_route(dep, sweep)
        elif free:
            from ..survey import free_route, plan_references

            plan = plan_references(dep, references, hs if heights else None, tape=tape)
            route = free_route(dep, (free_height,) * 2 if free_height is not None else sweep)
        else:
            plan = plan_survey(dep, step, hs, min_per_camera, tape=tape, spot_noise=spot_noise)
    except SurveyError as e:
        raise UserError(f"{deployment_path}: {e}") from None
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
    out = _output_file(out, inputs=(deployment_path,), beside=(".png",))
    from ..writing import OutputSet

    with OutputSet(out.with_suffix(".png"), out) as (png, csv_file):  # both, or neither
        if wand is not None:  # the marks' unmeasured coordinates are empty cells
            import csv

            with open(csv_file, "w", newline="", encoding="utf-8") as f:
                w = csv.writer(f, lineterminator="\n")
                w.writerow(POINTS_COLUMNS)
                w.writerows([pid, *("" if math.isnan(v) else f"{v:g}" for v in row)]
                            for pid, row in zip(plan.ids, plan.recorded))
        else:
            write_truth_csv(csv_file, plan.ids, plan.xyz, id_column=POINTS_COLUMNS[0])
        survey_plan_figure(png, dep, plan, route)
    if route is not None:
        _echo_free_plan(plan, route, out, wand)
        return
    echo(f"{len(plan.ids)} points at h = {', '.join(f'{h:g}' for h in sorted(set(hs)))} m "
         f"(grid {format_length(plan.step)}; positions to {format_length(plan.mark)}) → "
         f"{out}, map {out.with_suffix('.png')}")
    echo(budget_sentence(plan, chosen=step is None))
    few = [f"{cid} {int(n)}" for cid, n in zip(plan.camera_ids, plan.seen.sum(axis=1))
           if n < min_per_camera]
    if few:
        echo(f"note: fewer points than --min-per-camera {min_per_camera} (the finest grid "
             f"gives no more): {', '.join(few)}")
    ids = plan.camera_ids
    for k, cid in enumerate(ids):
        shared = [(ids[j], int((plan.seen[k] & plan.seen[j]).sum())) for j in range(len(ids))
                  if j != k]
        pairs = ", ".join(f"{cj} {n}" for cj, n in shared if n)
        echo(f"  {cid}: sees {int(plan.seen[k].sum())} points; shared with {pairs or '–'}")
    said = f"time: about {duration_words(plan.minutes)} with a tape (a minute a point)"
    if plan.minutes >= 60:  # hours of work: a wand needs none of it
        try:
            from ..survey import free_route
            from ..survey.plan import free_sweep

            wand_route = free_route(dep, free_sweep(dep, 0.5))
        except SurveyError:
            wand_route = None
        if wand_route is not None:
            said += (f"; a wand survey needs no tape: 5 marks on the floor (about 5 min) and "
                     f"about {duration_words(wand_route.minutes)} of waving a 0.5 m wand "
                     f"(vlpcal survey plan -d {deployment_path} --wand 0.5 --out marks.csv)")
    echo(said)


def _echo_free_plan(plan, route, out, wand=None) -> None:
    """A free survey's plan in words: the references (or a wand's frame marks) to measure, the
    route, and whether it links every camera."""
    import numpy as np

    from ..survey.calibration import format_length
    from ..survey.plan import duration_words
    if wand is not None:
        axis = {"x": "+x", "y": "+y"}[plan.axis]
        echo(f"wand survey ({wand:g} m between its LEDs; no tape): {len(plan.ids)} marks on "
             f"the floor, each seen by two cameras or more → {out} (its empty cells: not "
             f"measured), map {out.with_suffix('.png')}; put a mark where each is said "
             "(in the plan's frame, to a few cm) and let the cameras see the LED on it:")
        o = plan.xyz[0, :2]
        for pid, (x, y, _), seen in zip(plan.ids, plan.xyz, plan.seen.T):
            who = "+".join(c for c, s in zip(plan.camera_ids, seen) if s)
            what = ("the origin" if pid == "O" else
                    f"{np.hypot(x - o[0], y - o[1]):.2f} m along the plan's {axis} from O: the "
                    "calibrated frame's +x" if pid == "X" else "anywhere near, on the floor")
            echo(f"  {pid}: ({x:.2f}, {y:.2f}) m, {what}; seen by {who}")
    else:
        hs = sorted(set(plan.xyz[:, 2].round(6)))
        echo(f"{len(plan.ids)} reference points at h = {', '.join(f'{h:g}' for h in hs)} m "
             f"→ {out}, map {out.with_suffix('.png')}: measure each to "
             f"{format_length(plan.mark)} (about {duration_words(plan.minutes)}), and let "
             "the cameras see the LED there")
        for pid, (x, y, z), seen in zip(plan.ids, plan.xyz, plan.seen.T):
            who = "+".join(c for c, s in zip(plan.camera_ids, seen) if s)
            echo(f"  {pid}: ({x:.3f}, {y:.3f}, {z:.3f}) m, seen by {who}")
    stops = f"{len(route.stops)} stop{'s' if len(route.stops) > 1 else ''}"
    time = (f"about {duration_words(route.minutes)}" if route.low == route.high else
            f"one sweep each: about {duration_words(route.minutes)}")
    low = np.flatnonzero(route.tops < route.high - 1e-9)
    if route.low == route.high:
        echo(f"then, while the cameras record, drive the robot (its LED at {route.low:g} m) "
             f"through {stops} ({time}) and over the floor between them (the map shows the "
             "route); calibrate with --free-height " f"{route.low:g}:")
    else:
        what = "wave the wand" if wand is not None else "carry the LED"
        echo(f"then, while the cameras record, {what} along {stops} ({time}), sweeping "
             f"{'its LEDs' if wand is not None else 'it'} from {route.low:g} to "
             f"{route.high:g} m and back at each"
             + (f" ({len(low)} stop{'s' if len(low) != 1 else ''} only as high as said: "
                "there two cameras share a thin overlap near the floor)" if len(low) else "")
             + " (the map shows the route; walk it again until `survey capture` has "
             f"its {CAPTURE_SETS} sets, {CAPTURE_SECONDS / 60:g} min at 10 a second):")
    for n, ((x, y), pairs, quarters, t) in enumerate(
            zip(route.stops, route.pairs, route.quarters, route.tops), start=1):
        what = [f"pairs {', '.join(f'{a}+{b}' for a, b in pairs)}"] if pairs else []
        what += [", ".join(quarters)] if quarters else []
        what += [f"sweep only to {t:.2f} m"] if t < route.high - 1e-9 else []
        echo(f"  {n:2d}. ({x:.2f}, {y:.2f}) m: {'; '.join(what)}")
    lines = route.linkage.sentences()
    if len(route.groups) <= 1:
        echo(f"linked: {lines[0]}")
        return
    echo(f"warning: {lines[0]}; a free survey would refuse them after the measuring:")
    for line in lines[1:]:
        echo(f"warning: {line}")


@survey.command("capture")
@click.option("--deployment", "-d", "deployment_path", required=True,
              type=click.Path(dir_okay=False), help="The deployment (cameras as installed).")
@click.option("--points", "points_path", required=True, type=click.Path(dir_okay=False),
              help="Points to walk, in order: point_id,x,y,z (vlpcal survey plan's output).")
@click.option("--survey", "survey_path", required=True, type=click.Path(file_okay=False),
              help="Survey bundle to write (created; resumed if it exists).")
@click.option("--camera", "cameras", multiple=True, required=True, metavar="ID=SOURCE",
              help="A live camera: ID=http://…/stream (MJPEG) or ID=/dev/videoN. Repeat.")
@click.option("--yes", is_flag=True,
              help="Non-interactive: capture and accept every point (for scripted rigs).")
@click.option("--delay", type=Finite(0, 3600.0), default=None,
              help="Seconds to wait at each point before grabbing  [default: 1 with --yes, "
                   "else 0]")
@click.option("--on-point", "on_point", default=None, metavar="COMMAND",
              help="Shell command run before each point, e.g. to move a rig: {id}, {x}, {y}, "
                   "{z} are replaced (quoted), and VLPCAL_POINT_ID, _X, _Y, _Z are set.")
@click.option("--burst", default=None, type=click.IntRange(1, 100),
              help="Frame sets grabbed per point, all kept (the calibration averages their "
                   "spots).  [default: 10]")
@click.option("--check-every", default=5, show_default=True, type=click.IntRange(0),
              help="Show the per-camera calibration check every N points (0: at the end).")
@click.option("--free", is_flag=True,
              help="First record a free survey: the LED carried through the room while the "
                   "cameras stream (free/observations.csv), then the --points as references.")
@click.option("--rate", default=10.0, show_default=True, type=Finite(0.1, 100.0),
              help="With --free: moments recorded per second.")
@click.option("--duration", default=CAPTURE_SECONDS, show_default=True,
              type=Finite(1.0, 86400.0),
              help="With --free: seconds to record at most (Enter stops sooner).")
@click.option("--free-sets", default=CAPTURE_SETS, show_default=True,
              type=click.IntRange(10, 100000),
              help="With --free: moments to record in all (a resumed survey counts those it "
                   "has).")
@click.option("--wand", default=None, type=Finite(1e-6, 10000.0), metavar="LENGTH",
              help="A wand survey (implies --free): two LEDs LENGTH m apart on a rigid bar "
                   "waved through the room, both spots kept per camera; then the LED on each "
                   "frame mark of --points (survey plan --wand's file).")
@click.option("--view", "view_bind", is_flag=False, flag_value=DEFAULT_BIND, default=None,
              metavar="[HOST:PORT]",
              help=f"Show the capture live in the browser (vlpcal view's page; default "
                   f"{DEFAULT_BIND}): each camera's frames and spots, what a free survey "
                   "covered in each image and the camera pairs it linked, the point to "
                   "capture next on the plan.")
def survey_capture(deployment_path, points_path, survey_path, cameras, yes, delay, on_point,
                   burst, check_every, free, rate, duration, free_sets, wand, view_bind):
    """Capture a survey live: walk through the points while the cameras stream.

    At each point: place the LED, press Enter; a short burst is grabbed from every camera and
    what each saw is shown (pixel, peak, saturation, not seen, two blobs, no frames). Then
    accept, redo, skip or go back; an extra point can be added with its measured position.
    Each accepted point is on disk (frames, then its line in points.csv) before the next
    prompt: an interrupted session resumes where it stopped when run again. Every few points
    a quick fit per camera says whether the survey is good enough yet.

    \b
    With --free, first the free survey: carry the LED through the room (the route of `survey
    plan --free`) while every camera streams; every few seconds each camera says how much of
    its image the LED has crossed ("C3: bottom-left quarter empty") and which pairs have seen
    it together. Then the --points are captured as reference points. With --wand, the wand
    is waved instead (both its spots kept), and --points are its frame marks.

    \b
    Example:
      vlpcal survey capture -d planned.yaml --points points.csv --survey survey \\
        --camera C1=http://10.0.0.21:81/stream --camera C2=http://10.0.0.22:81/stream
    """
    import os
    import subprocess
    import sys

    from ..capture import BURST, Burst, CaptureSession, Step
    from ..datasets import DatasetError, SurveyAppender, read_points
    from ..live import LiveGrouper

    burst = BURST if burst is None else burst
    free = free or wand is not None
    dep = _load_deployment(deployment_path)
    try:  # a free survey's references may be frame marks, with empty cells
        ids, xyz = read_points(points_path, unmeasured=free)
    except DatasetError as e:
        raise UserError(str(e)) from None
    _check_survey_positions(points_path, dep, xyz, ids)
    sources = _camera_sources(cameras, dep)
    missing = [c.id for c in dep.cameras if c.id not in sources]
    if missing:
        echo(f"note: no --camera for {', '.join(missing)}: their frames stay missing",
             err=True)
    from pathlib import Path

    # every camera is asked for a frame before the walk starts (and before any file exists)
    grouper = LiveGrouper(sources, tolerance=0.05, on_event=lambda m: None)
    frames = Burst(grouper, burst)
    answers = frames.check(dep.cameras)
    if not any(ok for ok, _ in answers.values()):
        grouper.stop()
        said = "; ".join(f"{cid}: {what}" for cid, (_, what) in answers.items())
        raise NoCameraAnswered(f"no camera answered ({said}): check their power, network and "
                               "the --camera URLs before the walk; nothing was written")
    for cid, (ok, what) in answers.items():
        echo(f"camera {cid}: {what}" + ("" if ok else "; going on without it"),
             err=True)
    hub = server = None
    if view_bind is not None:
        from ..view.tap import FrameTap
        from .view import open_view

        hub, server = open_view(dep, view_bind, source=f"vlpcal survey capture → {survey_path}",
                                path=deployment_path)
        hub.tracking = False  # a survey: no tracks to come
        grouper.tap = FrameTap(hub, dep, spots=2 if wand is not None else 1)
    bundle = Path(survey_path)
    created = not bundle.exists()
    try:
        appender = SurveyAppender(survey_path)
    except DatasetError as e:
        raise UserError(str(e)) from None
    except OSError as e:
        raise UserError(f"{survey_path}: cannot write the survey there ({e.strerror})") from None
    delay = (1.0 if yes else 0.0) if delay is None else delay

    def say(line: str) -> None:
        echo(line)
        sys.stdout.flush()

    # per prompt: the keys shown, and what each means (Enter is "")
    keys = {"place": ("Enter: capture · s skip · b back · e extra point · q quit",
                      {"": "go", "e": "extra"}),
            "accept": ("Enter: accept · r redo · s skip · b back · q quit",
                       {"": "accept", "r": "redo"}),
            "retry": ("Enter: try again · s skip · b back · q quit", {"": "redo"})}

    def ask(kind: str, prompt: str) -> Step:
        if yes:
            if kind == "place":
                say(prompt)
            return Step("go" if kind == "place" else "accept")
        shown, own = keys[kind]
        choices = {**own, "s": "skip", "b": "back", "q": "quit"}
        while True:
            echo(f"{prompt}  [{shown}] > ", nl=False)
            sys.stdout.flush()
            line = sys.stdin.readline()
            if not line:  # end of input: stop, resumable
                return Step("quit")
            key = line.strip().lower()[:1]
            if key not in choices:
                keys_ok = ", ".join(k for k in choices if k)
                say(f"  ? {line.strip()!r}: press Enter or one of {keys_ok}")
                continue
            if choices[key] != "extra":
                return Step(choices[key])
            echo("  measured position of the extra point, x y z in metres > ", nl=False)
            sys.stdout.flush()
            try:
                vals = [float(t) for t in sys.stdin.readline().replace(",", " ").split()]
            except ValueError:
                vals = []
            if len(vals) == 3 and all(map(math.isfinite, vals)):
                return Step("extra", tuple(vals))
            say("  expected three numbers, e.g. 1.20 0.45 0.35")

    def move(pid, p) -> None:
        import re
        import shlex

        values = {"id": pid, **{a: f"{v:.6g}" if math.isfinite(v) else ""  # (a mark's: "")
                                for a, v in zip("xyz", p)}}
        cmd = re.sub(r"\{(id|x|y|z)\}", lambda m: shlex.quote(values[m.group(1)]), on_point)
        env = {**os.environ, **{f"VLPCAL_POINT_{k.upper()}": v for k, v in values.items()}}
        res = subprocess.run(cmd, shell=True, env=env)
        if res.returncode:
            raise UserError(f"--on-point {cmd!r} failed (exit {res.returncode}) at {pid}; "
                            "the survey so far is kept: fix the rig and run again to resume")

    grouper.on_event = lambda m: say(f"! {m}")
    free_app = None
    if free:
        try:
            free_app = _capture_free(dep, grouper, survey_path, rate, duration, free_sets, yes,
                                     say, wand, hub)
        except KeyboardInterrupt:
            grouper.stop()
            echo(f"\ninterrupted: the free sets so far are safe in {survey_path}; run the "
                 "same command to resume", err=True)
            sys.exit(130)
        frames = Burst(grouper, burst)  # the reference points' bursts start afresh
    session = CaptureSession(dep, ids, xyz, appender, frames, ask, say,
                             on_point=move if on_point else None, delay=delay,
                             check_every=0 if free else check_every, unattended=yes,
                             final_check=not free, on_stop=_view_stop(hub))
    try:
        n = session.run()
    except KeyboardInterrupt:
        n = None
    finally:
        grouper.stop()
        if server is not None:
            server.close()
        done_ids, skipped = appender.accepted()[0], appender.skipped()
        if created and not done_ids and not skipped and not (free_app and free_app.set_ids):
            import shutil

            shutil.rmtree(bundle, ignore_errors=True)  # nothing captured: leave nothing
    done = len(done_ids)
    if n is None:
        echo(f"\ninterrupted: {done} points are safe in {survey_path}; run the same "
             "command to resume", err=True)
        sys.exit(130)
    if session.stalled:
        raise click.ClickException(
            f"no camera sent frames at {session.stalled}: stopped with {done} points safe in "
            f"{survey_path}; check the cameras and run the same command to resume")
    left = [p for p in ids if p not in set(done_ids) | skipped]
    say(f"\n{n} points captured now, {done} in {survey_path}"
        + (f"; {len(left)} still to do (run again to resume)" if left else ""))
    if not left:
        say(f"next: vlpcal survey calibrate -d {deployment_path} --survey {survey_path} "
            + (f"--wand {wand:g} " if wand is not None else "") + "--out calibrated.yaml")


def _view_stop(hub):
    """A capture's ``on_stop`` for the live page: the point to capture next (None: none)."""
    if hub is None:
        return None

    def stop(pid, xyz, number, total):
        hub.survey_update(stop={"id": pid, "xyz": [float(v) if math.isfinite(v) else None
                                                   for v in xyz],
                                "number": number, "total": total})
    return stop


def _capture_free(dep, grouper, survey_path, rate, duration, max_sets, unattended, say,
                  wand=None, hub=None):
    """The free part of ``survey capture --free`` (``--wand``: a wand's): record until done,
    Enter, or the time is up; the sets are on disk as they come. Returns the appender."""
    import select
    import sys
    import time

    from ..capture import FreeRecorder
    from ..datasets import DatasetError, FreeAppender
    from ..survey import SurveyError, free_route

    try:
        app = FreeAppender(survey_path)
    except DatasetError as e:
        raise UserError(str(e)) from None
    try:
        overlapping = {p for stop in free_route(dep).pairs for p in stop}
    except SurveyError:
        overlapping = None
    on_report = None
    if hub is not None:  # what the LED (or wand) covered, to the live page
        from ..view.tap import survey_coverage

        def on_report(uv):
            hub.survey_update(coverage=survey_coverage(dep.cameras, uv))
    recorder = FreeRecorder(dep, grouper, app, rate, say, overlapping=overlapping,
                            wand=wand is not None, on_report=on_report)
    have = len(app.set_ids)
    if have >= max_sets:
        say(f"free survey: {have} sets already in {survey_path} (--free-sets {max_sets})")
        recorder.report(final=True)
        return app
    if have:
        say(f"resuming the free survey: {have} sets already in {survey_path}")
    interactive = not unattended and sys.stdin.isatty()
    what = (f"wave the wand ({wand:g} m) through the room, turning it as you go (the route of "
            "`vlpcal survey plan --wand`)" if wand is not None else
            "carry the LED through the room, sweeping it up and down (the route of `vlpcal "
            "survey plan --free`)")
    say(f"free survey: {what}; recording {rate:g} sets/s for up to {duration:g} s"
        + (", Enter stops sooner" if interactive else ""))

    def enter_pressed() -> bool:
        if not interactive:
            return False
        ready, _, _ = select.select([sys.stdin], [], [], 0)
        if ready:
            sys.stdin.readline()
        return bool(ready)

    grouper.deadline = time.monotonic() + duration + 1.0
    n = recorder.run(duration, max_sets, stop=enter_pressed)
    grouper.deadline = None
    recorder.report(final=True)
    say(f"{n} free sets recorded now, {len(app.set_ids)} in {survey_path}; next: the "
        + ("frame marks" if wand is not None else "reference points"))
    return app


class PointSigma(click.ParamType):
    """``auto`` or a positive length in metres."""

    name = "auto|metres"

    def convert(self, value, param, ctx):
        if isinstance(value, float):
            return value
        if str(value).strip().lower() == "auto":
            return "auto"
        try:
            v = float(value)
        except ValueError:
            v = float("nan")
        if not (v > 0 and v < float("inf")):
            self.fail(f"expected 'auto' or a positive length in metres, got {value!r}", param,
                      ctx)
        return v


@survey.command("calibrate")
@click.option("--deployment", "-d", "deployment_path", required=True,
              type=click.Path(dir_okay=False), help="The nominal deployment (as installed).")
@click.option("--survey", "survey_path", required=True, type=click.Path(file_okay=False),
              help="Survey bundle: points.csv and frames/ (or observations.csv); with free/, a "
                   "free survey (the LED moved freely, points.csv its reference points).")
@click.option("--out", "-o", required=True, type=click.Path(dir_okay=False),
              help="Calibrated deployment to write; a report (.report.json, .png) goes beside.")
@click.option("--lens", default="auto", show_default=True,
              type=click.Choice(("auto", "pose", "focal", "principal", "k1", "k2", "full")),
              help="Lens model per camera: auto chooses by held-out 3D error among the nested "
                   "models pose (lens as in the deployment), focal (+ fx, fy), principal "
                   "(+ cx, cy), k1 (+ radial k1), k2 (+ radial k2, tangential p1, p2), full "
                   "(+ radial k3); the others force one for every camera.")
@click.option("--intrinsics", is_flag=True, help="The same as --lens full.")
@click.option("--folds", default=5, show_default=True, type=click.IntRange(2, 20),
              help="Held-out accuracy: k-fold by survey point.")
@click.option("--point-sigma", default="auto", show_default=True, type=PointSigma(),
              help="Measurement uncertainty of a surveyed position, m per axis (e.g. 0.003 "
                   "for a tape measure, 0.0001 for a machined target); auto estimates it from "
                   "the fit.")
@click.option("--free-height", type=Finite(0, 1e4), default=None,
              help="A free survey's LED was always at this height, m (on a robot or a cart): "
                   "then two reference points suffice.")
@click.option("--wand", type=Finite(1e-6, 1e4), default=None, metavar="LENGTH",
              help="A free survey waved with a wand: two LEDs LENGTH m apart on a rigid bar "
                   "(each free frame shows both); its length fixes the scale, so frame marks "
                   "(O,0,0,0; X,,0,0; F1,,,0 …) can replace the tape.")
@click.option("--test-points", "test_path", default=None, type=click.Path(file_okay=False),
              help="Test points the calibration never sees: a bundle folder (points.csv with "
                   "frames/ or observations.csv); their error is reported.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
def survey_calibrate(deployment_path, survey_path, out, lens, intrinsics, folds, point_sigma,
                     free_height, wand, test_path, quiet):
    """Calibrate the cameras from a survey and report held-out accuracy.

    Each camera's pose and as much of its lens as the survey supports and needs (--lens auto:
    the nested models compared on held-out error, the simpler kept unless the richer is
    clearly better) are fitted to the survey points it saw, robustly (wrong spots and
    mis-measured points are reported by id); then all cameras and all surveyed positions are
    refined together, each position within its measurement precision (--point-sigma auto:
    estimated from the fit). The accuracy printed is measured on survey points left out of
    the fit (k-fold), never on the fitted ones.

    Example: vlpcal survey calibrate -d nominal.yaml --survey survey/ --out calibrated.yaml
    """
    import sys

    from ..datasets import DatasetError, read_survey_bundle
    from ..survey import FUSION_OF, SurveyError, calibrate_survey, survey_spots

    if intrinsics:
        if lens not in ("auto", "full"):
            raise UserError(f"--intrinsics is --lens full; it contradicts --lens {lens}")
        lens = "full"
    dep = _load_deployment(deployment_path)
    try:
        bundle = read_survey_bundle(survey_path)
    except DatasetError as e:
        raise UserError(str(e)) from None
    from pathlib import Path

    if Path(out).suffix.lower() not in (".yaml", ".yml"):
        raise UserError(f"{out}: the calibrated deployment is a YAML file (.yaml); its report "
                        "(.report.json) and figure (.png) go beside it")
    out = _output_file(out, inputs=(deployment_path, survey_path)
                       + ((test_path,) if test_path else ()),
                       beside=(".report.json", ".png"))
    test = _read_test_points(dep, test_path, survey_path, bundle) if test_path else None
    uv, notes = survey_spots(dep, bundle)
    for note in notes:
        echo(note, err=True)
    X, ids = bundle.xyz, bundle.point_ids
    _check_survey_positions(survey_path, dep, X, ids)
    if bundle.free_ids:
        return _calibrate_free(dep, bundle, uv, out, lens, point_sigma, free_height, notes,
                               quiet, deployment_path, survey_path, test, wand)
    for value, name in ((free_height, "--free-height"), (wand, "--wand")):
        if value is not None:
            raise UserError(f"{survey_path}: {name} is for a free survey (a free/ folder); "
                            "this bundle has none")
    try:
        with click.progressbar(length=len(dep.cameras) + 1 + folds, label="calibrating "
                               "(each camera's lens models, jointly, then k-fold)",
                               hidden=quiet, file=sys.stderr) as bar:
            result = calibrate_survey(
                dep, X, uv, ids, lens, folds, point_sigma,
                progress=lambda i, n: bar.update(max(i - bar.pos, 0)),
                sources={"deployment": str(deployment_path), "survey": str(survey_path)})
    except SurveyError as e:
        raise UserError(f"{survey_path}: {e}") from None
    _print_calibration(result, folds)
    _report_test_points(result, test)
    paths = _write_or_refuse(out, result, notes, survey_path,
                             f"Calibrated by vlpcal survey calibrate from {survey_path}.")
    label = {fusion: row for row, fusion in FUSION_OF.items()}[result.fusion]
    if all(st["mean"] is None for st in result.stats.values()):
        echo("warning: no held-out survey point got a fix (none was seen by two "
             "cameras): nothing says how well these cameras locate; survey where they "
             "overlap", err=True)
        echo(f"\nwrote {paths[0]} (fusion {result.fusion}: no fusion could be compared), "
             f"{paths[1]}, {paths[2]}")
        return
    echo(f"\nwrote {paths[0]} (fusion {result.fusion}: the table's row '{label}', the "
         f"best held out), {paths[1]}, {paths[2]}")


def _write_or_refuse(out, result, notes, survey_path, header):
    """The calibration's files — or one line when the fit is not a camera (a lens or pose no
    deployment may hold: spots that fit nothing, the wrong cameras); nothing written."""
    from ..deployment import DeploymentError
    from ..reports import write_calibration

    try:
        return write_calibration(out, result, notes, header=header)
    except DeploymentError as e:
        raise UserError(f"{survey_path}: the fit is not a camera one could hang ({e}); check "
                        "the spots and the camera ids against the deployment: nothing was "
                        "written") from None


def _read_test_points(dep, test_path, survey_path, survey):
    """``--test-points``: a bundle of measured points the calibration never sees (none of
    ``survey``'s, the bundle read already); (ids, X, spots)."""
    import os

    from ..datasets import DatasetError, read_survey_bundle
    from ..survey import survey_spots

    if os.path.realpath(test_path) == os.path.realpath(survey_path):  # (no error on a loop)
        raise UserError(f"--test-points {test_path}: is the survey itself (test points must be "
                        "points the calibration never sees)")
    try:
        tb = read_survey_bundle(test_path)
    except DatasetError as e:
        raise UserError(str(e)) from None
    if tb.free_ids:
        raise UserError(f"{test_path}: test points are measured points (points.csv with "
                        "frames/ or observations.csv), not a free survey")
    if not set(tb.camera_ids()) & {c.id for c in dep.cameras}:
        raise UserError(f"{test_path}: none of its cameras ({', '.join(tb.camera_ids()[:6])}) "
                        "is in the deployment (expected its camera ids)")
    import numpy as np

    # in a marks' frame the room is known only once calibrated: judged as the marks are
    _check_survey_positions(test_path, dep, tb.xyz, tb.point_ids,
                            frame_marks=bool(np.isnan(survey.xyz).any()))
    whole = survey.xyz[np.isfinite(survey.xyz).all(axis=1)]
    if len(whole):
        from scipy.spatial import cKDTree

        same = sorted(set(tb.point_ids) & set(survey.point_ids))
        gap = cKDTree(whole).query(tb.xyz)[0]  # each test point's nearest reference
        spread = float(np.ptp(whole, axis=0).max()) or 1.0
        at = [p for p, g in zip(tb.point_ids, gap) if g <= 1e-6 * spread]
        if same or at:
            raise UserError(f"--test-points {test_path}: point {(same or at)[0]} is also "
                            f"{'a reference point' if same else 'at a reference point'} of "
                            f"{survey_path} (test points must be points the calibration never "
                            "sees)")
    uv, notes = survey_spots(dep, tb)
    for note in notes:
        echo(f"test points: {note}", err=True)
    return tb.point_ids, tb.xyz, uv


def _report_test_points(result, test) -> None:
    """Fix the test points with the calibrated cameras: print and keep for the report."""
    if test is None:
        return
    from ..reports import test_point_errors
    from ..survey.calibration import format_length

    ids, X, uv = test
    result.test_points = tp = test_point_errors(result.deployment, X, uv, ids)
    fixed = round(tp["fixed"] * tp["points"])
    prov = result.deployment.extra.get("provenance")
    if fixed and isinstance(prov, dict):  # what `show` tells: the points held out
        held = prov.get("held_out_mean_m")
        prov["held_out_mean_m"] = {**(held if isinstance(held, dict) else {}),
                                   "test points": tp["mean"]}
    said = {"no_spot": "seen by no camera", "one_camera": "seen by one camera only",
            "inconsistent": "whose spots no camera pair agreed on",
            "degenerate": "whose rays barely meet",
            "outside_room": "that locate would refuse as outside_room (the fix beyond the "
                            "room by more than its predicted error)"}
    why = [f"{n} {said.get(status, status)}" for status, n in tp["statuses"].items()]
    unfixed = f" ({'; '.join(why)})" if why else ""
    if not fixed:
        echo(f"\ntest points: none of {tp['points']} was fixed{unfixed}")
        return
    cal = getattr(result, "calibration", None)
    sigma = cal.point_sigma if cal is not None else result.precision["point_sigma_m"]
    if cal is not None and cal.marks_only:  # marks say nothing of how a tape was read
        own = "whose own measurement error is in these figures too"
    else:
        own = (f"whose own measurement error is in these figures: at the references' "
               f"±{format_length(sigma)} per axis, about {format_length(sigma * 1.596)} of the "
               "mean")
    echo(f"\ntest points (never used by the calibration): {fixed} of {tp['points']} "
         f"fixed{unfixed}, mean {format_length(tp['mean'])}, p95 "
         f"{format_length(tp['p95'])}, max {format_length(tp['max'])} from their measured "
         f"positions ({own})")


def _calibrate_free(dep, bundle, uv, out, lens, point_sigma, free_height, notes, quiet,
                    deployment_path, survey_path, test=None, wand=None) -> None:
    """``survey calibrate`` on a bundle with a free survey (issue 15), or a wand's (26)."""
    import math
    import sys

    import numpy as np

    from ..survey import SurveyError, calibrate_free_survey, free_spots, wand_spots
    from ..survey.calibration import format_length
    from ..survey.free import WAND_PRECISION

    if free_height is not None and not (0 <= free_height < dep.ceiling_height):
        raise UserError(f"--free-height {free_height:g}: expected a height from the floor to "
                        f"below the ceiling ({dep.ceiling_height:g} m)")
    _check_wand_fits(wand, dep)
    labelled = False
    try:
        if wand is None:
            uv_free, free_notes = free_spots(dep, bundle)
        else:
            found = wand_spots(dep, bundle)
            uv_free, free_notes, labelled = found.uv, found.notes, found.labelled
    except SurveyError as e:
        raise UserError(str(e)) from None
    for k, cam in enumerate(dep.cameras):  # a spot outside its image is no spot of this camera
        u, v = uv_free[k, ..., 0], uv_free[k, ..., 1]
        off = np.isfinite(u) & ((u < -0.5) | (u > cam.width - 0.5) | (v < -0.5)
                                | (v > cam.height - 0.5))
        if off.any():
            i = int(np.flatnonzero(off.reshape(len(off), -1).any(axis=1))[0])
            j = np.flatnonzero(off[i])[0] if off.ndim > 1 else ()
            raise UserError(f"{survey_path}: free set {bundle.free_ids[i]}, camera {cam.id}: "
                            f"spot ({u[i][j]:g}, {v[i][j]:g}) is outside its "
                            f"{cam.width}×{cam.height} image (expected pixels within it)")
    for note in free_notes:
        echo(note, err=True)
    n_ref = len(bundle.point_ids)
    try:
        from ..survey.free import MAX_LEFT_OUT

        with click.progressbar(length=5 + min(n_ref, MAX_LEFT_OUT)
                               + (3 if wand is not None and not labelled else 0),
                               label="calibrating from the free survey",
                               hidden=quiet, file=sys.stderr) as bar:
            result = calibrate_free_survey(
                dep, bundle.xyz, uv, bundle.point_ids, uv_free, lens, point_sigma, free_height,
                progress=lambda i, n: bar.update(1),
                sources={"deployment": str(deployment_path), "survey": str(survey_path)},
                wand=wand, labelled=labelled)
    except SurveyError as e:
        raise UserError(f"{survey_path}: {e}") from None
    except np.linalg.LinAlgError:
        raise UserError(f"{survey_path}: the free survey's joint fit did not converge (spots "
                        "far from any consistent camera; check free/ and the deployment)") \
            from None
    cal = result.calibration
    marks = cal.in_marks_frame  # frame marks among the references
    marks_only = cal.marks_only
    refs = "marks" if marks_only else "references"
    echo(f"free survey: {result.free_sets} sets (moments a camera saw the LED), "
         f"{cal.used_sets} used (seen by "
         + ("a camera at the stated height" if free_height is not None else
            "two or more cameras")
         + f"); {sum(cal.rejected.values())} spots rejected, {cal.dropped_sets} sets of "
         f"two views that disagree dropped; {refs} ±"
         f"{cal.point_sigma * 1000:.2g} mm {'in height' if marks_only else 'per axis'} ("
         + ("estimated" if cal.point_sigma_estimated else
            "assumed" if cal.point_sigma_assumed else "as stated")
         + f"), spots ±{cal.pixel_sigma:.3g} px")
    for note in cal.notes:
        echo(f"note: {note}")
    for words in result.lens:
        echo(f"  {words}")
    echo(f"\n{'camera':8s} {'spread px':>9s} {'free sets':>9s} {'rejected':>8s} "
         f"{'moved':>9s} {'turned °':>8s}  lens")
    for r in result.cameras:
        echo(f"{r['camera'][:8]:8s} {r['spread_px']:9.3f} {r['free_sets_seen']:9d} "
             f"{r['rejected_spots']:8d} {r['moved_m'] * 1000:6.1f} mm "
             f"{r['turned_deg']:8.2f}  {r['lens_model']}")
    echo("\nwhere the free LED went, in each camera's image:")
    for r in result.cameras:
        echo(f"  {r['coverage']}")
    loo = cal.leave_one_out[np.isfinite(cal.leave_one_out)]
    if len(loo):
        tape = cal.point_sigma * 1000 * math.sqrt(3)
        own = (f"their heights only, O and X setting the frame; the floor's unevenness under "
               f"them, ±{cal.point_sigma * 1000:.1f} mm "
               f"{'assumed' if cal.point_sigma_assumed else 'as stated'}, is in these figures"
               if marks_only else f"their own tape, ±{tape:.1f} mm in 3D, included")
        echo(f"\n{refs}, each left out in turn where the rest still fix the room (its "
             f"spots place it): mean {loo.mean() * 1000:.1f} mm, max "
             f"{loo.max() * 1000:.1f} mm over {len(loo)} of them ({own})")
    else:
        echo(f"\n{refs}: too few to leave one out (the rest must still fix the room)")
    _print_suspects(cal.suspects, bundle.root / "points.csv", held_out=False)
    echo(f"your {n_ref} "
         + ("marks" if marks_only else "reference points and marks" if marks else
            "reference points")
         + (f" and the wand's length (±{WAND_PRECISION:.1%})" if wand else "")
         + f" fix the room to about {cal.datum_floor * 1000:.1f} mm (the datum floor: no "
         "calibration does better on average"
         + (f", predicted at the ±{cal.point_sigma * 1000:g} mm assumed"
            if cal.point_sigma_assumed else "") + "); "
         + ("place the LED on the marks more carefully (--point-sigma says how well), or "
            "add floor marks, to do better" if marks else
            "measure more points, or more precisely, to do better"))
    if marks:
        echo("the calibrated deployment is in the marks' frame: O is its origin, X on "
             "its +x axis, the floor marks at z = 0 (the room moved with the cameras)")
    if cal.wand_error is not None:
        w = cal.wand_error
        worst = max(w.per_camera.items(), key=lambda t: -1 if np.isnan(t[1]) else t[1])
        echo(f"wand: {w.sets} held-out sets (never in the fit) triangulate its "
             f"{wand * 1000:g} mm to ±{w.mean * 1000:.2f} mm on average (p95 "
             f"{w.p95 * 1000:.2f} mm; worst camera {worst[0]} {worst[1] * 1000:.2f} mm)"
             + (f"; {w.discarded} more whose spots do not meet (a reflection or another "
                "light taken for an end) left out" if w.discarded else ""))
    if math.isfinite(cal.predicted_error):
        echo(f"predicted: fixes with these cameras {format_length(cal.predicted_error)} "
             "off on average over the floor (the survey's adjustment, linearised; exact "
             f"cameras: {format_length(cal.exact_error)})")
    if cal.references_disagree:
        loo_mm = float(np.nanmean(cal.leave_one_out)) * 1000
        allowed = cal.left_out_allowed * 1000
        echo(f"warning: this survey fixes the cameras weakly: its references, each left "
             f"out in turn, land {loo_mm:.1f} mm from their records on average where "
             f"their own noise and the predicted error allow about {allowed:.1f} mm — "
             "cameras whose lens and pose the free LED could not tell apart; measure "
             "references where those cameras see, wave a wand (--wand), or give "
             "--test-points to see")
    elif cal.weakly_fixed:
        from ..survey import plan_references

        asked = len(plan_references(dep).ids)
        echo(f"warning: this survey fixes the cameras weakly: fixes are predicted "
             f"{format_length(cal.predicted_error)} off, where exact cameras in the frame "
             f"of your references would be "
             f"{format_length(math.hypot(cal.exact_error, cal.datum_floor))}: the free LED "
             f"cannot fix the lenses across the cameras' overlaps with {n_ref} references; "
             f"measure more (survey plan --free asks for {asked}), or give --test-points "
             "to see")
    for r in result.cameras:
        if r["moved_share"] > 0.2 or r["turned_deg"] > 20:
            echo(f"warning: camera {r['camera']} moved {format_length(r['moved_m'])} "
                 f"({r['moved_share']:.0%} of its distance to the free LED) and turned "
                 f"{r['turned_deg']:.1f}° from the deployment: is this survey from this "
                 "site, and are its camera ids right?")
    if result.scale_doubtful:
        top = max(c.position[2] for c in result.deployment.cameras)
        said = (f"the wand's length ({format_length(wand)})" if wand is not None else
                "the references' measurements (their units, a misread tape)")
        echo(f"warning: the calibrated cameras stand {result.plan_scale:.2f} × as high "
             f"above the floor as the deployment's (the highest {format_length(top)}, "
             f"under a {format_length(dep.ceiling_height)} ceiling): check {said}")
    _report_test_points(result, test)
    paths = _write_or_refuse(out, result, notes + free_notes, survey_path,
                             f"Calibrated by vlpcal survey calibrate from {survey_path} (free "
                             "survey).")
    echo(f"\nwrote {paths[0]} (fusion robust: all cameras by least squares), {paths[1]}, "
         f"{paths[2]}")


def _print_lens_table(result) -> None:
    """Per camera and lens model, the held-out 3D error with the other cameras as chosen;
    then the choice beside plain OpenCV on the same folds."""
    from ..survey import LENS_MODELS
    from ..survey.calibration import format_length

    rows = [r for r in result.cameras if r.get("lens_candidates")]
    d = result.decision
    if not rows or d is None:
        return
    if not d.points:
        echo("  no survey point was seen by two cameras: each lens was chosen by its own "
             "held-out reprojection error")
        return
    figures = [c.get("held_out_3d_m") for r in rows for c in r["lens_candidates"].values()]
    unit, scale = _unit_for([f for f in figures if f is not None])
    for cid, s in d.starts_disagree.items():
        nom = next(c for c in result.deployment.cameras if c.id == cid)
        centre = ((nom.width - 1) / 2, (nom.height - 1) / 2)
        echo(f"  {cid}: its fit ({s.model}) has more than one minimum: the principal point "
             f"{s.chained[0] - centre[0]:+.0f}, {s.chained[1] - centre[1]:+.0f} px from "
             f"the image centre (from the simpler fits) or {s.best[0] - centre[0]:+.0f}, "
             f"{s.best[1] - centre[1]:+.0f} px (from the data's own starts, "
             f"{s.cost_ratio:.3g} × lower in cost): the lower kept, then refined with "
             "the rest")
    echo(f"held-out 3D error per camera's lens model, {unit} (each camera fitted alone, "
         f"the others as chosen; * chosen: the simplest within one standard error of "
         f"the lowest; – not fitted):\n  {'camera':8s}"
         + "".join(f"{m:>11s}" for m in LENS_MODELS))
    for r in rows:
        cells = []
        for m in LENS_MODELS:
            v = r["lens_candidates"].get(m, {}).get("held_out_3d_m")
            cell = "–" if v is None else f"{v * scale:.3g}" + ("*" if m == r["lens_model"]
                                                                else "")
            cells.append(f"{cell:>11s}")
        echo(f"  {r['camera']:8s}" + "".join(cells))
    import math

    capped = (f"; {d.opencv_capped} of its points past the {format_length(d.cap_m)} cap, "
              "where a fold it could not fit or a wild fix counts" if d.opencv_capped else "")
    echo(f"  this choice {format_length(d.held_out_m)}; plain OpenCV calibrateCamera "
         f"(full lens, from the deployment's) "
         f"{format_length(d.opencv_m) if math.isfinite(d.opencv_m) else 'no fit'} on the "
         f"same folds{capped} ({d.points} points seen by two or more cameras, "
         "triangulated by least squares; the k-fold table below fits cameras and points "
         "jointly and fixes points as the locator does)")
    if d.held_out_m > d.opencv_m:
        echo(f"warning: plain OpenCV locates the held-out survey points better "
             f"({format_length(d.opencv_m)} against {format_length(d.held_out_m)})",
             err=True)


def _unit_for(values) -> tuple[str, float]:
    """One unit for a table, chosen so that its smallest figure reads with three digits."""
    return next(((u, f) for u, f in (("m", 1.0), ("cm", 100.0), ("mm", 1000.0), ("µm", 1e6))
                 if values and min(values) * f >= 0.1), ("µm", 1e6))


def _print_calibration(result, folds: int) -> None:
    """The lens decisions, the held-out table, the per-camera verdicts and the mis-measured
    points."""
    import numpy as np

    from ..survey.calibration import format_length

    n = len(result.points)
    prec = result.precision
    echo("\nlens, per camera (chosen by the held-out 3D error of survey points unless "
         "--lens forces one):")
    for sentence in result.lens:
        echo(f"  {sentence}")
    _print_lens_table(result)
    how = "estimated from the fit" if prec["estimated"] else "as stated"
    echo(f"survey positions: ±{format_length(prec['point_sigma_m'])} per axis ({how}); spots "
         f"±{prec['pixel_sigma_px']:.2g} px")
    # one unit for the table, chosen so that the best row reads with three figures
    unit, scale = _unit_for([st["mean"] for st in result.stats.values()
                             if st["mean"] is not None])
    echo(f"\nheld-out 3D error ({folds}-fold by survey point, {n} points), {unit}; the "
         "reference is the measured position itself "
         f"(±{format_length(prec['point_sigma_m'])} per axis ≈ "
         f"{format_length(prec['point_sigma_m'] * 3 ** 0.5)} in 3D):")
    echo(f"{'':32s} {'mean':>7s} {'median':>7s} {'p95':>7s} {'max':>7s} {'fixed':>6s}")
    for label, st in result.stats.items():
        if st["mean"] is None:
            echo(f"{label:32s} {'–':>7s} {'':23s} {st['fixed']:6.0%}")
            continue
        cells = " ".join(f"{st[k] * scale:7.3f}" if st[k] * scale < 10 else
                         f"{st[k] * scale:7.1f}" for k in ("mean", "median", "p95", "max"))
        echo(f"{label:32s} {cells} {st['fixed']:6.0%}")
    echo("(fixed: share of the held-out points with a fix; a point one camera saw "
         "has none)")
    echo(f"\n{'camera':8s} {'RMS px':>7s} {'points':>7s} {'lens':>9s} {'moved':>9s} "
         f"{'turned °':>9s}  rejected spots")
    for r in result.cameras:
        echo(f"{r['camera']:8s} {r['rms_px']:7.3f} {r['points']:7d} {r['lens_model']:>9s} "
             f"{format_length(r['moved_m']):>9s} {r['turned_deg']:9.2f}  "
             f"{', '.join(r['outliers']) or '–'}")
    for r in result.cameras:
        if r["moved_share"] > 0.2 or r["turned_deg"] > 20:
            traded = r["lens_model"] != "pose" and "weakly determined" in r["lens"]
            why = ("; its lens line says its fit trades the lens against the pose: the move "
                   "may be that, not the camera" if traded else
                   ": is this survey from this site, and are the camera ids the same?")
            echo(f"warning: camera {r['camera']} moved {format_length(r['moved_m'])} "
                 f"({r['moved_share']:.0%} of its distance to the survey) and turned "
                 f"{r['turned_deg']:.0f}° from the deployment{why}", err=True)
    if result.mismeasured:
        echo("\nmis-measured survey points (rejected by the cameras that saw them; how far "
             "from its record the calibrated cameras put the LED):")
        for pid, off in result.mismeasured:
            echo(f"  {pid}: {format_length(off)}" if np.isfinite(off) else f"  {pid}: –")
    _print_suspects(result.suspects, "points.csv", held_out=True)


def _print_suspects(suspects, points, held_out: bool) -> None:
    """A warning per survey point whose left-out (or held-out) error stands far beyond the
    others' (:mod:`vlpcal.survey.suspects`), with what leaving it out gives."""
    from ..survey.suspects import suspect_words

    for s in suspects:
        echo(f"warning: {suspect_words(s, held_out)} Check it and correct it in {points} "
             f"(or delete its line and its folder frames/{s.point_id}), then calibrate "
             "again.")


def _check_wand_fits(wand, dep, to_wave: bool = False) -> None:
    """Refuse a wand far longer than the room (a length in millimetres, not metres); one
    ``to_wave`` (a plan) at most the floor's diagonal, as ``simulate`` takes it."""
    if wand is not None and wand > 2 * dep.size:
        raise UserError(f"--wand {wand:g}: longer than the room ({dep.size:.3g} m across): "
                        "expected the wand's length in metres")
    if wand is not None and to_wave:
        diagonal = _floor_diagonal(dep.room)
        if wand > diagonal:
            raise UserError(f"--wand {wand:g}: longer than the room's diagonal "
                            f"({diagonal:.2f} m): it cannot be waved there")


def _check_survey_positions(survey_path, dep, X, ids, frame_marks: bool = False) -> None:
    """Refuse positions that cannot be in this room (millimetres read as metres, a typo): a
    margin of a fifth of the room's size around it, and under its ceiling; in a frame that
    marks define (``frame_marks``, or an empty cell), within the room's size of the origin."""
    import numpy as np
    from shapely import contains_xy
    from shapely.geometry import Polygon

    margin = 0.2 * dep.size
    if frame_marks or np.isnan(X).any():  # positions in the marks' frame, not the room's
        near = np.abs(np.nan_to_num(X[:, :2])).max(axis=1) <= dep.size + margin
        inside = near & ~(X[:, 2] <= -margin) & ~(X[:, 2] >= dep.ceiling_height)
    else:
        room = Polygon(dep.room).buffer(margin)
        inside = contains_xy(room, X[:, 0], X[:, 1]) & (X[:, 2] > -margin) \
            & (X[:, 2] < dep.ceiling_height)
    if not inside.all():
        i = int(np.flatnonzero(~inside)[0])
        raise UserError(f"{survey_path}: point {ids[i]} at ({X[i, 0]:g}, {X[i, 1]:g}, "
                        f"{X[i, 2]:g}) m is not in the room of {dep.name} (a margin of a fifth "
                        f"of its size) or under its {dep.ceiling_height:g} m ceiling: metres "
                        "expected")
