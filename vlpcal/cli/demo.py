"""The demo and the simulator: every user's step on a simulated room (``vlpcal demo``,
``vlpcal simulate``)."""

from __future__ import annotations

import click

from .common import Finite, UserError, _floats, _floor_diagonal, _load_deployment, echo, main


@main.command()
@click.option("--profile", "profile_name", default=None,
              help="Simulation profile: paper-2024 (the default), cheap-wide or qvga.")
@click.option("--deployment", "-d", "deployment_path", type=click.Path(dir_okay=False),
              default=None,
              help="Instead of a profile: your deployment (any cameras, room, keep-outs) as "
                   "the planned install, its cameras hung with a careful install's errors.")
@click.option("--seed", default=0, show_default=True, type=click.IntRange(0),
              help="Seed of the install and frames.")
@click.option("--out", type=click.Path(file_okay=False), required=False,
              help="Folder to write (created; must not exist unless --overwrite).")
@click.option("--survey-step", default=None, type=Finite(0.001, 2.0),
              help="Spacing of the survey grid, m.  [default: 0.3, or a sixth of the room's "
                   "shorter side in a smaller room]")
@click.option("--survey-heights", default="0,0.35,0.7", show_default=True,
              help="LED heights of the survey, m, comma-separated.")
@click.option("--test-points", default=100, show_default=True, type=click.IntRange(0, 100_000),
              help="Random test positions to render as a locate frames folder.")
@click.option("--trajectory", default=0, show_default=True, type=click.IntRange(0, 100_000),
              help="Frames of a robot's LED path (h = 0.15 m) to render instead of test points.")
@click.option("--free-sets", default=0, show_default=True, type=click.IntRange(0, 100_000),
              help="Also a free survey (OUT/free-survey/): this many moments of an LED carried "
                   "through the room, with the reference points survey plan --free asks for.")
@click.option("--free-height", type=Finite(0, 1e4), default=None,
              help="The free survey's LED on a robot at this height, m (instead of a pole).")
@click.option("--references", type=click.IntRange(2, 200), default=None,
              help="Reference points of the free survey (default: as survey plan --free).")
@click.option("--wand", type=Finite(), default=None, metavar="LENGTH",
              help="The free survey's LED is a wand's two, LENGTH m apart on a rigid bar waved "
                   "by hand (with --free-sets); their true positions in "
                   "OUT/free-survey.truth.csv.")
@click.option("--robot-speed", type=Finite(0.0, 50.0, min_open=True), default=None,
              help="Also a robot's LED driving at this speed, m/s, seen by unsynchronised "
                   "cameras (OUT/streams/: <camera_id>/<frame_no>.jpg and times.csv, 30 fps "
                   "each from a random phase, 2 ms jitter, 5 % dropped) for vlpcal track.")
@click.option("--body", type=click.IntRange(2, 3), default=None, metavar="N",
              help="With --robot-speed or --publish: the robot carries N LEDs (2: 0.3 m apart "
                   "along its heading; 3: a triangle, the full pose), each with its blink "
                   "code; the deployments gain their leds: and bodies: blocks (body R1; with "
                   "--publish, the same seed's --out folder holds them).")
@click.option("--seconds", default=10.0, show_default=True, type=Finite(0.1, 600.0),
              help="With --robot-speed: how long the robot drives.")
@click.option("--publish", default=None, metavar="mqtt://…/PREFIX",
              help="Instead of a folder: the install's cameras publish their spots of a robot's "
                   "LED (--robot-speed, default 1 m/s) live on PREFIX/spots/<camera_id> for "
                   "--seconds, each at 30 fps from its own phase (for vlpcal locate or track "
                   "--spots).")
@click.option("--overwrite", is_flag=True, help="Replace what is in --out.")
@click.option("--describe", is_flag=True, help="Print the profile's parameters and sources.")
def simulate(profile_name, deployment_path, seed, out, survey_step, survey_heights,
             test_points, trajectory, free_sets, free_height, references, wand, robot_speed,
             body, seconds, publish, overwrite, describe):
    """Simulate an install: nominal and true deployments, a survey bundle, a frames folder.

    The install is a named profile (--profile) or your own deployment (-d): its cameras as
    planned, hung with the errors of a careful install by hand (vlpcal demo's).

    Writes OUT/nominal.yaml (the cameras as planned), OUT/truth.yaml (as really installed, for
    evaluation), OUT/survey/ (a survey bundle, tape-measure noise on points.csv),
    OUT/frames/ (a locate frames folder) and OUT/frames.truth.csv; with --free-sets, a free
    survey OUT/free-survey/ (reference points and free/ sets; the free LED's true positions in
    OUT/free-survey.truth.csv) — with --wand, a wand's two LEDs; with --robot-speed, a moving
    robot's LED seen by unsynchronised cameras, OUT/streams/ (for vlpcal track).

    Examples: vlpcal simulate --profile cheap-wide --seed 3 --out sim-cheap;
    vlpcal simulate -d my-site.yaml --free-sets 1800 --wand 0.5 --out sim-mine
    """
    from pathlib import Path

    from ..sim.profiles import get_profile, profile_of_deployment
    from ..sim.scene import make_scene
    from ..sim.writers import grid_points

    if profile_name is not None and deployment_path is not None:
        raise click.UsageError("give --profile NAME or -d DEPLOYMENT, not both")
    if deployment_path is not None:
        from ..demo import DEMO_ERRORS

        profile = profile_of_deployment(_load_deployment(deployment_path), DEMO_ERRORS)
    else:
        try:
            profile = get_profile(profile_name or "paper-2024")
        except ValueError as e:
            raise click.BadParameter(str(e), param_hint="--profile") from None
    if describe:
        echo(f"{profile.name}: {profile.description}")
        for key, text in profile.sources.items():
            echo(f"  {key}: {text}")
        return
    if publish:
        ctx = click.get_current_context()
        given = [p.opts[0] for p in ctx.command.params if p.name in _FOLDER_ONLY and
                 ctx.get_parameter_source(p.name) == click.core.ParameterSource.COMMANDLINE]
        if given:  # said, not ignored: --out with --publish wrote nothing
            raise UserError(f"{given[0]}: is for a simulated folder; --publish sends spots to "
                            "the broker and writes no files (run simulate --out FOLDER, same "
                            "--profile and --seed, for the deployments)")
        _publish_spots(profile, seed, publish, robot_speed or 1.0, seconds, body)
        return
    if not out:
        raise click.UsageError("--out is required (the folder to write)")
    out = Path(out)
    if out.exists() and any(out.iterdir()) and not overwrite:
        raise click.UsageError(f"{out} exists and is not empty (use --overwrite to replace)")
    heights = _floats(survey_heights, "--survey-heights")
    # under the cameras, in their view: a site of any size (0.5 m under a 2.3 m ceiling)
    top = min(profile.ceiling_height - 0.5,
              0.9 * min(c.position[2] for c in profile.nominal))
    if top <= 0:
        top = 0.78 * min(profile.ceiling_height, *(c.position[2] for c in profile.nominal))
    if not heights or any(not 0 <= h <= top for h in heights):
        raise click.BadParameter(f"expected LED heights from 0 to {top:.3g} m (under the "
                                 f"cameras), got {survey_heights!r}",
                                 param_hint="--survey-heights")
    scene = make_scene(profile, seed)
    if survey_step is None:
        xs, ys = zip(*profile.room)
        survey_step = min(0.3, min(max(xs) - min(xs), max(ys) - min(ys)) / 6)
    pts = grid_points(scene, survey_step, heights)
    if not len(pts):
        step_given = click.get_current_context().get_parameter_source("survey_step") \
            == click.core.ParameterSource.COMMANDLINE
        if step_given:
            raise click.BadParameter("no camera sees any point of that survey grid",
                                     param_hint="--survey-step")
        raise UserError("no camera sees any point of the room's free floor (cameras that look "
                        "away from the room, or keep-outs that cover it)")
    # --overwrite replaces what this command writes, all of it, as one folder (never
    # anything else: a folder holding other files is refused)
    import os

    from ..writing import OutputSet

    if out.exists():
        foreign = sorted(set(os.listdir(out)) - SIMULATED)
        if foreign:
            raise UserError(f"{out}: holds {foreign[0]}, which vlpcal simulate does not "
                            "write; choose another --out (--overwrite replaces only a folder "
                            "of simulate's files)")
    if free_sets and free_height is not None and not 0 <= free_height <= top:
        raise click.BadParameter(f"expected a height from 0 to {top:g} m",
                                 param_hint="--free-height")
    for value, name in ((free_height, "--free-height"), (references, "--references"),
                        (wand, "--wand")):
        if value is not None and not free_sets:
            raise click.BadParameter("is for a free survey (--free-sets N)", param_hint=name)
    if wand is not None:
        _check_wand(profile, wand, free_height)
    if body is not None and not robot_speed:
        raise click.BadParameter("is for a robot's streams (--robot-speed M/S)",
                                 param_hint="--body")
    given = click.get_current_context().get_parameter_source("seconds")
    if given == click.core.ParameterSource.COMMANDLINE and not robot_speed:
        raise click.BadParameter("is for a robot's streams (--robot-speed M/S) or --publish",
                                 param_hint="--seconds")
    if references is not None and references < 3 and free_height is None:
        raise click.BadParameter(f"expected 3 or more (2 or more with --free-height: fewer "
                                 f"cannot fix the room's frame), got {references}",
                                 param_hint="--references")
    refs = route = None
    if free_sets:  # the references the free survey's planner asks for, before any work
        from ..sim.writers import deployment_of
        from ..survey import SurveyError, free_route, plan_references

        nominal = deployment_of(scene, "nominal")
        try:
            if wand is not None:  # no tape: frame marks, and the install in their frame
                from ..survey.free_plan import plan_marks

                refs = plan_marks(nominal)
            else:
                refs = plan_references(nominal, references)
        except SurveyError as e:
            raise UserError(f"--free-sets: {e}") from None
        if deployment_path is not None and free_height is None:
            # your own site: the LED carried along the route survey plan gives it
            from ..survey.free_plan import free_sweep

            try:
                route = free_route(nominal, free_sweep(nominal, wand))
            except SurveyError as e:
                echo(f"free survey: no route ({e}); the LED wanders the room instead")
    out.parent.mkdir(parents=True, exist_ok=True)
    with OutputSet(out, folders=True) as (stage,):
        stage.chmod(0o755)
        leds = blocks = None
        if robot_speed:  # a robot's LED, or the LEDs it carries (and the deployments' blocks)
            from ..sim.streams import BODY_LAYOUTS, body_blocks, body_leds, robot_path

            leds = origin = robot_path(scene, robot_speed, height=0.0 if body else 0.15,
                                       seed=seed)
            if body:
                leds, yaw = body_leds(origin, BODY_LAYOUTS[body], seed=seed)
                blocks = body_blocks(leds, BODY_LAYOUTS[body])
        _simulate_into(stage, out, scene, profile, seed, pts, heights, free_sets, free_height,
                       refs, wand, trajectory, test_points, deployment_path is not None, route,
                       blocks)
        if robot_speed:
            from ..sim.streams import simulate_streams

            frames = simulate_streams(scene, stage / "streams", leds, seconds, seed=seed)
            if body:  # the body's pose at each camera frame's time
                import numpy as np

                _write_body_truth(stage / "streams.bodies.truth.csv", origin, yaw,
                                  np.unique(np.concatenate([t for _, t, _ in frames.values()])))
            echo(f"streams: a robot at up to {robot_speed:g} m/s (slower in its turns) "
                 + (f"carrying {body} blinking LEDs (body R1) " if body else "")
                 + f"for {seconds:g} s, cameras "
                 f"not synchronised → {out / 'streams'} (truth in "
                 f"{out / 'streams.truth.csv'}"
                 + (f", the body's in {out / 'streams.bodies.truth.csv'}" if body else "")
                 + ")")


def _write_body_truth(path, origin, yaw, t) -> None:
    """``t,body,x,y,z,yaw,pitch,roll``: where the simulated robot (body R1, level) was."""
    import csv

    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(("t", "body", "x", "y", "z", "yaw", "pitch", "roll"))
        w.writerows((f"{tt:.6f}", "R1", *(f"{v:.6f}" for v in p), f"{a:.6f}", "0", "0")
                    for tt, p, a in zip(t, origin(t), yaw(t)))


#: what vlpcal simulate writes in its --out folder
SIMULATED = {"nominal.yaml", "truth.yaml", "survey", "frames", "frames.truth.csv",
             "free-survey", "free-survey.truth.csv", "streams", "streams.truth.csv",
             "streams.bodies.truth.csv"}


def _check_wand(profile, length: float, free_height) -> None:
    """``--wand``: a bar a hand can wave in this room, before any work."""
    from ..sim.writers import longest_wand, wand_fits

    if free_height is not None:
        raise click.BadParameter("is waved by hand: give --free-height (a robot's LED) or "
                                 "--wand, not both", param_hint="--wand")
    diagonal = _floor_diagonal(profile.room)
    if not 0 < length <= diagonal:
        raise click.BadParameter(f"expected a length above 0 m and at most the room's "
                                 f"diagonal ({diagonal:.2f} m), got {length:g}",
                                 param_hint="--wand")
    if not wand_fits(profile, length):
        raise click.BadParameter(f"a wand {length:g} m long cannot be waved in this room "
                                 f"without its ends crossing a wall or keep-out; at most "
                                 f"{longest_wand(profile):.2f} m here", param_hint="--wand")


#: simulate's options that shape the folder it writes, which --publish does not write
_FOLDER_ONLY = ("out", "overwrite", "survey_step", "survey_heights", "test_points", "trajectory",
                "free_sets", "free_height", "references", "wand")


def _publish_spots(profile, seed, url, speed, seconds, body=None) -> None:
    """``simulate --publish``: the reference publisher of spots (:mod:`vlpcal.sim.publish`);
    the robot (and its ``body``'s LEDs) as ``--robot-speed`` renders it into a folder."""
    from ..mqtt import MqttError
    from ..sim.publish import play_spots, spot_schedule
    from ..sim.scene import make_scene
    from ..sim.streams import BODY_LAYOUTS, body_leds, robot_path
    from .mqtt import parse_mqtt

    target = parse_mqtt(url, "--publish")
    scene = make_scene(profile, seed)
    path = robot_path(scene, speed, height=0.0 if body else 0.15, seed=seed)
    leds = body_leds(path, BODY_LAYOUTS[body], seed=seed)[0] if body else path
    events = spot_schedule(scene, leds, seconds, seed=seed)
    seen = sum(len(uv) > 0 for _, _, uv in events)
    what = (f"a robot carrying {body} blinking LEDs (body R1)" if body else "a robot's LED",
            "with a spot" if body else "with the LED")
    echo(f"{profile.name}: {len(scene.true)} cameras publishing {len(events)} frames' "
         f"spots ({seen} {what[1]}) of {what[0]} at {speed:g} m/s over {seconds:g} s on "
         f"{target.shown()}/spots/…", err=True)
    try:
        res = play_spots(target, events, say=lambda m: echo(m, err=True))
    except MqttError as e:
        raise UserError(f"--publish {e}") from None
    unsent = len(events) - res["sent"]
    echo(f"published {res['sent']} spot messages, {res['spots']} {what[1]} (p99 "
         f"{res['late_p99_ms']:.1f} ms behind schedule)"
         + (f"; {unsent} of the {len(events)} not sent (the broker went away)"
            if unsent else ""), err=True)


def _into_frame(points, o, x):
    """``points`` N×3 in the frame whose origin is ``o`` and +x the direction to ``x`` (the
    floor's, z kept), with the exact zeros that frame gives ``o`` and ``x`` where it should."""
    import math

    import numpy as np

    a = math.atan2(x[1] - o[1], x[0] - o[0])
    c, s = math.cos(a), math.sin(a)
    d = np.asarray(points, float) - [o[0], o[1], 0.0]
    out = np.c_[c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]]
    return np.where(np.abs(out) < 1e-12, 0.0, out)


def _simulate_into(stage, out, scene, profile, seed, pts, heights, free_sets, free_height,
                   refs, wand, trajectory, test_points, own: bool, route=None,
                   blocks=None) -> None:
    """Write the simulated install into ``stage`` (``out`` once renamed), saying what goes
    where (``refs``: the free survey's planned references; ``own``: a user's deployment,
    whose install and look are said too; ``route``: the free survey's planned route, as
    planned, or None: the LED wanders the room; ``blocks``: the deployments' ``leds:`` and
    ``bodies:``, of a robot's LEDs)."""
    import os

    import numpy as np

    from ..sim.writers import (
        free_floor,
        grid_points,
        simulate_frames,
        simulate_survey,
        write_deployments,
    )
    from ..sim.writers import (
        trajectory as path_of,
    )

    write_deployments(scene, stage, blocks)
    marks = None
    if free_sets and wand is not None:
        # the marks define the room's frame: O its origin, X on its +x axis, the floor z = 0;
        # truth.yaml and everything simulated are in that frame, nominal.yaml as planned
        import math

        from ..sim.scene import in_frame
        from ..sim.writers import deployment_of

        o, x = refs.xyz[0], refs.xyz[1]
        scene = in_frame(scene, o[:2], math.atan2(x[1] - o[1], x[0] - o[0]))
        from ..deployment import save

        save(deployment_of(scene, "true", blocks), stage / "truth.yaml",
             header=f"Simulated {scene.profile.name} install (seed {scene.seed}): the cameras "
                    "as they really are, in the frame the wand survey's marks define (for "
                    "evaluation only).")
        marks = (refs.ids, np.isfinite(refs.recorded))
        pts = _into_frame(pts, o, x)
        if route is not None:
            from dataclasses import replace

            moved = _into_frame(np.c_[route.stops, np.zeros(len(route.stops))], o, x)
            route = replace(route, stops=moved[:, :2])
        echo(f"the wand survey's marks define the frame: O at ({o[0]:.2f}, {o[1]:.2f}) m "
             f"of the plan is (0, 0, 0), X at ({x[0]:.2f}, {x[1]:.2f}) m on its +x axis; "
             "truth.yaml and every position written are in that frame")
    simulate_survey(scene, stage / "survey", pts, seed=seed, overwrite=True)
    n_cams = len(scene.true)
    echo(f"{profile.name} (seed {seed}): {out / 'nominal.yaml'}, {out / 'truth.yaml'}")
    if own:
        src = profile.sources
        echo(f"  {n_cams} camera{'s' * (n_cams != 1)} hung with "
             f"{src['install errors']}; frames look like "
             f"{src['look']}")
    shots = sum(int(c.project(pts)[2].sum()) for c in scene.true)
    echo(f"survey: {len(pts)} points at h = {', '.join(map(str, heights))} m, "
         f"{shots} frames from {n_cams} camera{'s' * (n_cams != 1)} → "
         f"{out / 'survey'}")
    if free_sets:
        from ..sim.writers import simulate_free_survey

        simulate_free_survey(scene, stage / "free-survey",
                             refs.xyz if marks is None else _into_frame(refs.xyz, *refs.xyz[:2]),
                             free_sets, seed=seed, height=free_height, overwrite=True,
                             wand=wand, truth=stage / "free-survey.truth.csv", marks=marks,
                             route=route)
        sets = list((stage / "free-survey" / "free" / "frames").iterdir())
        jpegs = sum(len(os.listdir(d)) for d in sets)
        what = (f"(a robot at h = {free_height:g} m)" if free_height is not None else
                f"(a wand: two LEDs {wand:g} m apart, waved by hand)" if wand is not None
                else "(an LED on a pole)")
        if route is not None:
            stops = len(route.stops)
            what += (f" along survey plan's route ({stops} stops)" if free_sets >= stops else
                     f" at {free_sets} of survey plan's {stops} stops")
        echo(f"free survey: {len(refs.ids)} "
             f"{'marks' if marks is not None else 'reference points'} and {free_sets} "
             "free sets "
             f"{what} → {out / 'free-survey'}; {len(sets)} of the sets have frames "
             f"({jpegs} in all: a camera saw "
             f"{'an LED' if wand is not None else 'the LED'}; the others are left out, "
             f"as a capture leaves them); truth in {out / 'free-survey.truth.csv'}")
    if trajectory:
        test = path_of(scene, trajectory, seed=seed)
    else:
        rng = np.random.default_rng([seed, 11])
        # a 2 cm grid to draw from, coarser in a room so large that it would pass 50 000
        # floor points (its test points stay as random; the draw stays quick)
        area = free_floor(profile, 0.05).area
        cand = grid_points(scene, max(0.02, float(np.sqrt(area / 50_000))),
                           (0.0, 0.15, 0.35, 0.7), min_cameras=2)
        test = cand[rng.choice(len(cand), min(test_points, len(cand)), replace=False)]
    if len(test):
        simulate_frames(scene, stage / "frames", test, seed=seed + 1, overwrite=True)
        echo(f"frames: {len(test)} {'trajectory' if trajectory else 'test'} positions "
             f"→ {out / 'frames'} (truth in {out / 'frames.truth.csv'})")


@main.command()
@click.option("--out", "-o", default="vlpcal-demo", show_default=True,
              type=click.Path(file_okay=False),
              help="Folder to write (replaced if an earlier demo wrote it).")
@click.option("--seed", default=0, show_default=True, type=click.IntRange(0),
              help="Seed of the simulated install, survey and frames.")
def demo(out: str, seed: int):
    """Run the built-in demo: plan, install, survey, calibrate and locate, all simulated.

    Plans a camera grid for a built-in 3 × 2.4 m lab, hangs the cameras with the errors of a
    careful install by hand, simulates a free survey (a dozen measured points and three
    minutes of a moving LED) and, for comparison, a tape survey, calibrates, then locates an LED
    on a robot driving around the room with the paper's pipeline and vlpcal's on the same
    frames. Prints one table and writes every file a real user would have into --out.

    Example: vlpcal demo --out my-demo
    """
    from ..demo import REDO, DemoError, format_table, run_demo

    try:
        res = run_demo(out, seed, say=lambda m: echo(m, err=True))
    except DemoError as e:
        raise UserError(str(e)) from None
    p, s, f = res.planned, res.survey, res.free
    robot = {r.label: r for r in res.rows}
    free_cm = robot["vlpcal: calibrated, free survey"].mean_cm
    tape_cm = robot["vlpcal: calibrated, tape survey"].mean_cm
    echo(f"\nvlpcal demo (seed {seed}): {p['cameras']} cameras planned ({p['family']}); "
         f"the robot: {res.frames} frames.\n"
         f"free survey: {f['references']} points measured + {f['minutes']:g} min of the "
         f"LED carried through the room → the robot's mean error {free_cm:.2f} cm\n"
         f"  (its references fix the room to about {f['datum_floor_cm']:.2f} cm; the "
         f"tape survey's {f['test_points']} points, never used by it, are "
         f"{f['test_points_cm']:.2f} cm off, their tape included)\n"
         f"tape survey: {s['points']} points measured → {tape_cm:.2f} cm (held out: "
         f"{s['held_out_nominal_cm']:.2f} cm with the cameras as planned, "
         f"{s['held_out_calibrated_cm']:.2f} cm calibrated)\n3D error in cm:\n")
    echo(format_table(res))
    echo(f"\nThe paper's pipeline: NI-P spots, its pair method, fusions (a)–(c) with the "
         f"cameras as planned.\nvlpcal: blob spots, robust all-camera least squares (the "
         f"tape-calibrated file\nuses the fusion its survey chose: {s['fusion']}). fixes/s: "
         "JPEG decoding included, one core.")
    echo(f"\nwrote {res.folder}/ in {res.seconds:.0f} s:")
    for name, (what, _) in REDO.items():
        echo(f"  {name:21s} {what}")
    echo("\nredo any step by hand, e.g. (inside the folder):")
    for _, cmd in REDO.values():
        if cmd:
            echo(f"  {cmd}")
