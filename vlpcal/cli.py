"""The ``vlpcal`` command. Thin: parses options and calls the layers below.

Heavy modules (cv2, scipy, casadi, matplotlib) are imported inside commands, so ``vlpcal
--help`` starts fast.
"""

from __future__ import annotations

import math

import click

from . import __version__


class UserError(click.ClickException):
    """A user's mistake (a wrong path, a malformed file): one line, exit code 2."""

    exit_code = 2


class OneLineErrors(click.Group):
    """A wrong option value (a folder given for a file, a missing file) is a user's mistake
    like any other: one line naming the option and where to look, not a usage block."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except click.UsageError as e:
            if type(e).__name__ == "NoArgsIsHelpError":  # a bare group: its help, as asked
                raise
            where = e.ctx.command_path if e.ctx else "vlpcal"
            raise UserError(f"{e.format_message()} (see {where} --help)") from None


@click.group(cls=OneLineErrors, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="vlpcal")
def main():
    """vlpcal: centimetre-level 3D positioning of an LED from a few cheap ceiling cameras.

    Units are metres and radians; the world frame has z up and the floor at z = 0. Start
    with the demo, then plan (installer), survey (surveyor) and locate (integrator).

    Example: vlpcal demo
    """


def _load_deployment(path):
    from .deployment import DeploymentError, load

    try:
        return load(path)
    except DeploymentError as e:
        raise UserError(str(e)) from None


def _output_file(path, inputs=(), beside=()):
    """``path`` as a file to write, checked before any work: not a folder, in a folder that
    exists and takes a new file, none of the command's ``inputs`` (files or folders: the output
    may not be one of them or lie inside one), and neither are the files it writes ``beside``
    it (suffixes, e.g. ``.png``) folders or inputs."""
    import os
    import tempfile
    from pathlib import Path

    out = Path(path)
    if out.is_dir() or not out.parent.is_dir():
        raise UserError(f"{out}: cannot write there (expected a file in an existing folder)")
    targets = [out] + [out.with_suffix(s) for s in beside]
    for t in targets:
        r = t.resolve()
        for src in inputs:
            src = Path(src).resolve()
            if r == src or src in r.parents:
                raise UserError(f"{out}: is (or would write {t.name} over) the command's own "
                                f"input {src}; choose another output file")
        if t != out and t.is_dir():
            raise UserError(f"{out}: would write {t} beside it, which is a folder")
    try:
        fd, probe = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".probe", dir=out.parent)
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise UserError(f"{out}: cannot write in {out.parent} ({e.strerror})") from None
    return out


def _mount(site) -> str:
    """The site's mounting grid, said in the unit a person would use."""
    from .planning import mount_step

    step = mount_step(site)
    return f"{step * 100:.3g} cm" if step >= 0.01 else f"{step * 1000:.3g} mm"


def _floats(text: str, option: str) -> list[float]:
    try:
        return [float(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise click.BadParameter(f"expected numbers separated by commas, got {text!r}",
                                 param_hint=option) from None


@main.command()
@click.option("--profile", "profile_name", default="paper-2024", show_default=True,
              help="Simulation profile: paper-2024, cheap-wide or qvga.")
@click.option("--seed", default=0, show_default=True, type=click.IntRange(0),
              help="Seed of the install and frames.")
@click.option("--out", type=click.Path(file_okay=False), required=False,
              help="Folder to write (created; must not exist unless --overwrite).")
@click.option("--survey-step", default=0.3, show_default=True, type=click.FloatRange(0.05, 2.0),
              help="Spacing of the survey grid, m.")
@click.option("--survey-heights", default="0,0.35,0.7", show_default=True,
              help="LED heights of the survey, m, comma-separated.")
@click.option("--test-points", default=100, show_default=True, type=click.IntRange(0),
              help="Random test positions to render as a locate frames folder.")
@click.option("--trajectory", default=0, show_default=True, type=click.IntRange(0),
              help="Frames of a robot's LED path (h = 0.15 m) to render instead of test points.")
@click.option("--overwrite", is_flag=True, help="Replace what is in --out.")
@click.option("--describe", is_flag=True, help="Print the profile's parameters and sources.")
def simulate(profile_name, seed, out, survey_step, survey_heights, test_points, trajectory,
             overwrite, describe):
    """Simulate an install: nominal and true deployments, a survey bundle, a frames folder.

    Writes OUT/nominal.yaml (the cameras as planned), OUT/truth.yaml (as really installed, for
    evaluation), OUT/survey/ (a survey bundle, tape-measure noise on points.csv),
    OUT/frames/ (a locate frames folder) and OUT/frames.truth.csv.

    Example: vlpcal simulate --profile cheap-wide --seed 3 --out sim-cheap
    """
    from pathlib import Path

    import numpy as np

    from .sim.profiles import get_profile
    from .sim.scene import make_scene
    from .sim.writers import (
        grid_points,
        simulate_frames,
        simulate_survey,
        write_deployments,
    )
    from .sim.writers import (
        trajectory as path_of,
    )

    try:
        profile = get_profile(profile_name)
    except ValueError as e:
        raise click.BadParameter(str(e), param_hint="--profile") from None
    if describe:
        click.echo(f"{profile.name}: {profile.description}")
        for key, text in profile.sources.items():
            click.echo(f"  {key}: {text}")
        return
    if not out:
        raise click.UsageError("--out is required (the folder to write)")
    out = Path(out)
    if out.exists() and any(out.iterdir()) and not overwrite:
        raise click.UsageError(f"{out} exists and is not empty (use --overwrite to replace)")
    heights = _floats(survey_heights, "--survey-heights")
    top = profile.ceiling_height - 0.5
    if not heights or any(not 0 <= h <= top for h in heights):
        raise click.BadParameter(f"expected LED heights from 0 to {top:g} m (0.5 m under the "
                                 f"ceiling), got {survey_heights!r}",
                                 param_hint="--survey-heights")
    scene = make_scene(profile, seed)
    pts = grid_points(scene, survey_step, heights)
    if not len(pts):
        raise click.BadParameter("no camera sees any point of that survey grid",
                                 param_hint="--survey-step")
    out.mkdir(parents=True, exist_ok=True)
    # --overwrite replaces what this command writes, all of it (never anything else)
    import shutil

    for name in ("survey", "frames"):
        shutil.rmtree(out / name, ignore_errors=True)
    (out / "frames.truth.csv").unlink(missing_ok=True)
    nominal, truth = write_deployments(scene, out)
    simulate_survey(scene, out / "survey", pts, seed=seed, overwrite=True)
    click.echo(f"{profile.name} (seed {seed}): {nominal}, {truth}")
    click.echo(f"survey: {len(pts)} points at h = {', '.join(map(str, heights))} m "
               f"→ {out / 'survey'}")
    if trajectory:
        test = path_of(scene, trajectory, seed=seed)
    else:
        rng = np.random.default_rng([seed, 11])
        cand = grid_points(scene, 0.02, (0.0, 0.15, 0.35, 0.7), min_cameras=2)
        test = cand[rng.choice(len(cand), min(test_points, len(cand)), replace=False)]
    if len(test):
        simulate_frames(scene, out / "frames", test, seed=seed + 1, overwrite=True)
        click.echo(f"frames: {len(test)} {'trajectory' if trajectory else 'test'} positions "
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
    careful install by hand, plans and simulates the survey, calibrates, then locates an LED
    on a robot driving around the room with the paper's pipeline and vlpcal's on the same
    frames. Prints one table and writes every file a real user would have into --out.

    Example: vlpcal demo --out my-demo
    """
    from .demo import REDO, DemoError, format_table, run_demo

    try:
        res = run_demo(out, seed, say=lambda m: click.echo(m, err=True))
    except DemoError as e:
        raise UserError(str(e)) from None
    p, s = res.planned, res.survey
    click.echo(f"\nvlpcal demo (seed {seed}): {p['cameras']} cameras planned ({p['family']}); "
               f"survey of {s['points']} points, held-out 3D error {s['held_out_nominal_cm']:.2f} "
               f"cm with the\ncameras as planned, {s['held_out_calibrated_cm']:.2f} cm calibrated "
               f"(worst camera {s['worst_camera_rms_px']:.2f} px RMS); the robot: "
               f"{res.frames} frames.\n3D error in cm:\n")
    click.echo(format_table(res))
    click.echo(f"\nThe paper's pipeline: NI-P spots, its pair method, fusions (a)–(c) with the "
               f"cameras as planned.\nvlpcal: blob spots, robust all-camera least squares (the "
               f"calibrated file uses\nthe fusion its survey chose: {s['fusion']}). fixes/s: "
               "JPEG decoding included, one core.")
    click.echo(f"\nwrote {res.folder}/ in {res.seconds:.0f} s:")
    for name, (what, _) in REDO.items():
        click.echo(f"  {name:21s} {what}")
    click.echo("\nredo any step by hand, e.g. (inside the folder):")
    for _, cmd in REDO.values():
        if cmd:
            click.echo(f"  {cmd}")


@main.command()
@click.option("--deployment", "-d", "deployment_path", required=True,
              type=click.Path(dir_okay=False), help="Deployment YAML (docs/formats.md).")
@click.option("--frames", "frames_dir", type=click.Path(file_okay=False),
              help="Folder of <frame_id>/<camera_id>.jpg.")
@click.option("--observations", type=click.Path(dir_okay=False),
              help="CSV frame_id,camera_id,u,v of spots the cameras found themselves.")
@click.option("--camera", "cameras", multiple=True, metavar="ID=SOURCE",
              help="Live source per camera: an MJPEG URL (ESP32-CAM: http://IP:81/stream) or "
                   "a video device (/dev/video0). Repeat for each camera.")
@click.option("--out", "-o", default="-", show_default=True,
              help="Fixes file (.csv or .jsonl), or - for stdout.")
@click.option("--format", "fmt", type=click.Choice(["csv", "jsonl"]), default=None,
              help="Output format (default: from --out's extension; csv for stdout).")
@click.option("--batch", default=512, show_default=True, type=click.IntRange(1),
              help="Frame sets located together (folders).")
@click.option("--tolerance", default=0.05, show_default=True, type=click.FloatRange(0.001),
              help="Live: frames arriving within this many seconds form one set.")
@click.option("--duration", type=click.FloatRange(0), default=None,
              help="Live: stop after this many seconds.")
@click.option("--max-sets", type=click.IntRange(1), default=None,
              help="Live: stop after this many frame sets.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar or summary.")
def locate(deployment_path, frames_dir, observations, cameras, out, fmt, batch, tolerance,
           duration, max_sets, quiet):
    """Turn camera frames into 3D fixes (metres, world frame, z up).

    One row per frame set: frame_id,x,y,z,status first (the contract), then the cameras used,
    the predicted RMS error sigma_m, the worst reprojection residual and each camera's status.
    A frame set without a fix keeps its row with empty x, y, z and a status saying why.

    Example: vlpcal locate -d deployment.yaml --frames frames/ --out fixes.csv
    """
    import sys
    import time
    from collections import Counter

    from .locator import FixWriter, Locator

    sources = [name for name, given in (("--frames", frames_dir),
                                         ("--observations", observations),
                                         ("--camera", cameras)) if given]
    if len(sources) != 1:
        raise click.UsageError("give exactly one input: --frames DIR, --observations CSV or "
                               "--camera ID=SOURCE …")
    loc = Locator(_load_deployment(deployment_path))
    say = (lambda msg: None) if quiet else (lambda msg: click.echo(msg, err=True))
    live = bool(cameras)
    try:
        writer = FixWriter(out, fmt, extra_columns=("t_s",) if live else ())
    except OSError as e:
        raise UserError(f"{out}: cannot write the fixes there ({e.strerror})") from None
    t0 = time.perf_counter()
    statuses: Counter = Counter()
    notes = []
    try:
        if frames_dir:
            n = _locate_folder(loc, frames_dir, writer, batch, statuses, notes, quiet)
        elif observations:
            n = _locate_observations(loc, observations, writer, statuses, notes)
        else:
            n = _locate_live(loc, cameras, writer, tolerance, duration, max_sets, statuses,
                             notes, say)
    except KeyboardInterrupt:
        notes.append("interrupted: the fixes so far are kept")
        n = sum(statuses.values())
    except click.ClickException:
        writer.abort()
        raise
    except BrokenPipeError:  # the reader of stdout has what it wanted (| head): stop quietly
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return
    writer.close()
    secs = time.perf_counter() - t0
    if n and not quiet:
        ok = statuses.get("ok", 0)
        parts = ", ".join(f"{k} {v}" for k, v in statuses.most_common())
        say(f"{n} frame sets: {ok / n:.1%} fixed ({parts}); {n / secs:,.0f} sets/s"
            + (f" → {out}" if out != "-" else ""))
    for note in notes:
        say(note)
    if not n:
        say("no frame sets located")
    sys.stdout.flush()


def _locate_folder(loc, frames_dir, writer, batch, statuses, notes, quiet) -> int:
    from .datasets import DatasetError, read_frames_folder

    try:
        folder = read_frames_folder(frames_dir)
    except DatasetError as e:
        raise UserError(str(e)) from None
    absent = [c for c in loc.camera_ids if c not in folder.camera_ids]
    if absent:
        notes.append(f"{frames_dir}: no frames at all from camera(s) {', '.join(absent)} of "
                     f"{loc.deployment.name}: is this the right deployment for these frames?")
    unknown = sorted(set(folder.camera_ids) - set(loc.camera_ids))
    if unknown:
        files = sum(1 for (_, c) in folder.files if c in unknown)
        notes.append(f"ignored {files} frames of camera(s) {', '.join(unknown)} that "
                     f"{loc.deployment.name} does not have")
    ids = folder.frame_ids
    with click.progressbar(length=len(ids), label="locating", file=None if not quiet else
                           open("/dev/null", "w"), show_pos=True) as bar:
        for s in range(0, len(ids), batch):
            chunk = ids[s:s + batch]
            sets = []
            for fid in chunk:
                fs = {}
                for cid in loc.camera_ids:
                    path = folder.files.get((fid, cid))
                    if path is not None:
                        try:
                            fs[cid] = path.read_bytes()
                        except OSError:
                            fs[cid] = b""  # unreadable: reported as a corrupt frame
                sets.append(fs)
            fixes = loc.locate_batch(sets, chunk)
            statuses.update(fixes.counts())
            writer.write(fixes)
            bar.update(len(chunk))
    return len(ids)


def _locate_observations(loc, path, writer, statuses, notes) -> int:
    import numpy as np

    from .datasets import DatasetError, read_observations

    try:
        obs, ids = read_observations(path, "frame_id")
    except DatasetError as e:
        raise UserError(str(e)) from None
    index = {c: k for k, c in enumerate(loc.camera_ids)}
    frame_index = {f: n for n, f in enumerate(ids)}
    uv = np.full((len(index), len(ids), 2), np.nan)
    unknown = set()
    for (fid, cid), p in obs.items():
        if cid in index:
            uv[index[cid], frame_index[fid]] = p
        else:
            unknown.add(cid)
    if unknown:
        notes.append(f"ignored spots of camera(s) {', '.join(sorted(unknown))} that "
                     f"{loc.deployment.name} does not have")
    fixes = loc.locate_pixels(uv, frame_ids=ids)
    statuses.update(fixes.counts())
    writer.write(fixes)
    return len(ids)


def _camera_sources(cameras, dep) -> dict:
    """``--camera ID=SOURCE`` values → camera id → frame source, checked against ``dep``."""
    from .live import open_source

    ids = [c.id for c in dep.cameras]
    sources = {}
    for spec in cameras:
        cid, sep, src = spec.partition("=")
        if not sep or not cid or not src:
            raise UserError(f"--camera {spec!r}: expected ID=SOURCE, e.g. "
                            "C1=http://10.0.0.21:81/stream")
        if cid not in ids:
            raise UserError(f"--camera {spec!r}: {dep.name} has no camera {cid!r} "
                            f"(it has {', '.join(ids)})")
        if cid in sources:
            raise UserError(f"--camera {spec!r}: camera {cid} given twice")
        sources[cid] = open_source(src)
    return sources


def _locate_live(loc, cameras, writer, tolerance, duration, max_sets, statuses, notes,
                 say) -> int:
    import time

    from .live import LiveGrouper

    sources = _camera_sources(cameras, loc.deployment)
    t_end = time.monotonic() + duration if duration else None
    grouper = LiveGrouper(sources, tolerance, on_event=say, deadline=t_end)
    n = 0
    try:
        for fs in grouper:
            fixes = loc.locate_batch([fs.frames], [f"{fs.index:06d}"])
            statuses.update(fixes.counts())
            writer.write(fixes, {"t_s": round(fs.t, 3)})
            n += 1
            if (max_sets and n >= max_sets) or (t_end and time.monotonic() > t_end):
                break
    finally:
        grouper.stop()
    st = grouper.stats
    if not n:
        why = "; ".join(f"{c}: {st.ended.get(c, 'no frames')}" for c in sources)
        raise click.ClickException(f"no frames from any camera, nothing located ({why})")
    for cid in loc.camera_ids:
        if cid in sources:
            notes.append(f"camera {cid}: {st.frames[cid]} frames, absent from "
                         f"{st.missing[cid]} of {st.sets} sets"
                         + (f"; {st.dropped[cid]} dropped (the locator fell behind)"
                            if st.dropped[cid] else "")
                         + (f"; stopped: {st.ended[cid]}" if cid in st.ended else ""))
    return n


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
@click.option("--step", default=0.3, show_default=True, type=click.FloatRange(0.05, 2.0),
              help="Grid spacing, m (made finer where a camera or pair needs more points).")
@click.option("--heights", default="0,0.35,0.7", show_default=True,
              help="LED heights to survey, m, comma-separated (two or more).")
@click.option("--min-per-camera", default=12, show_default=True, type=click.IntRange(6),
              help="Points each camera must see (more let the calibration fit more of its lens).")
def survey_plan(deployment_path, out, step, heights, min_per_camera):
    """Plan the survey: where to put the LED, with ids, and a map to print.

    Example: vlpcal survey plan -d planned.yaml --out survey-plan.csv
    """
    from pathlib import Path

    from .datasets import POINTS_COLUMNS, write_truth_csv
    from .reports import survey_plan_figure
    from .survey import SurveyError, plan_survey

    dep = _load_deployment(deployment_path)
    hs = _floats(heights, "--heights")
    if len(hs) < 2 or any(not 0 <= h < dep.ceiling_height - 0.3 for h in hs):
        raise click.BadParameter(f"expected two or more heights from 0 to "
                                 f"{dep.ceiling_height - 0.3:g} m, got {heights!r}",
                                 param_hint="--heights")
    try:
        plan = plan_survey(dep, step, hs, min_per_camera)
    except SurveyError as e:
        raise UserError(f"{deployment_path}: {e}") from None
    out = Path(out)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise UserError(f"{out}: cannot make its folder ({e.strerror})") from None
    if out.is_dir():
        raise UserError(f"{out}: is a folder (expected a points.csv file to write)")
    write_truth_csv(out, plan.ids, plan.xyz, id_column=POINTS_COLUMNS[0])
    survey_plan_figure(out.with_suffix(".png"), dep, plan)
    click.echo(f"{len(plan.ids)} points at h = {', '.join(f'{h:g}' for h in sorted(set(hs)))} m "
               f"→ {out}, map {out.with_suffix('.png')}")
    ids = plan.camera_ids
    for k, cid in enumerate(ids):
        shared = [(ids[j], int((plan.seen[k] & plan.seen[j]).sum())) for j in range(len(ids))
                  if j != k]
        pairs = ", ".join(f"{cj} {n}" for cj, n in shared if n)
        click.echo(f"  {cid}: sees {int(plan.seen[k].sum())} points; shared with {pairs or '–'}")


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
@click.option("--delay", type=click.FloatRange(0), default=None,
              help="Seconds to wait at each point before grabbing  [default: 1 with --yes, "
                   "else 0]")
@click.option("--on-point", "on_point", default=None, metavar="COMMAND",
              help="Shell command run before each point, e.g. to move a rig: {id}, {x}, {y}, "
                   "{z} are replaced (quoted), and VLPCAL_POINT_ID, _X, _Y, _Z are set.")
@click.option("--burst", default=5, show_default=True, type=click.IntRange(1, 100),
              help="Frame sets grabbed per point.")
@click.option("--check-every", default=5, show_default=True, type=click.IntRange(0),
              help="Show the per-camera calibration check every N points (0: at the end).")
def survey_capture(deployment_path, points_path, survey_path, cameras, yes, delay, on_point,
                   burst, check_every):
    """Capture a survey live: walk through the points while the cameras stream.

    At each point: place the LED, press Enter; a short burst is grabbed from every camera and
    what each saw is shown (pixel, peak, saturation, not seen, two blobs, no frames). Then
    accept, redo, skip or go back; an extra point can be added with its measured position.
    Each accepted point is on disk (frames, then its line in points.csv) before the next
    prompt: an interrupted session resumes where it stopped when run again. Every few points
    a quick fit per camera says whether the survey is good enough yet.

    \b
    Example:
      vlpcal survey capture -d planned.yaml --points points.csv --survey survey \\
        --camera C1=http://10.0.0.21:81/stream --camera C2=http://10.0.0.22:81/stream
    """
    import os
    import subprocess
    import sys

    from .capture import Burst, CaptureSession, Step
    from .datasets import DatasetError, SurveyAppender, read_points
    from .live import LiveGrouper

    dep = _load_deployment(deployment_path)
    try:
        ids, xyz = read_points(points_path)
    except DatasetError as e:
        raise UserError(str(e)) from None
    sources = _camera_sources(cameras, dep)
    missing = [c.id for c in dep.cameras if c.id not in sources]
    if missing:
        click.echo(f"note: no --camera for {', '.join(missing)}: their frames stay missing",
                   err=True)
    from pathlib import Path

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
        click.echo(line)
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
            click.echo(f"{prompt}  [{shown}] > ", nl=False)
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
            click.echo("  measured position of the extra point, x y z in metres > ", nl=False)
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

        values = {"id": pid, "x": f"{p[0]:.6g}", "y": f"{p[1]:.6g}", "z": f"{p[2]:.6g}"}
        cmd = re.sub(r"\{(id|x|y|z)\}", lambda m: shlex.quote(values[m.group(1)]), on_point)
        env = {**os.environ, **{f"VLPCAL_POINT_{k.upper()}": v for k, v in values.items()}}
        res = subprocess.run(cmd, shell=True, env=env)
        if res.returncode:
            raise UserError(f"--on-point {cmd!r} failed (exit {res.returncode}) at {pid}; "
                            "the survey so far is kept: fix the rig and run again to resume")

    grouper = LiveGrouper(sources, tolerance=0.05, on_event=lambda m: say(f"! {m}"))
    session = CaptureSession(dep, ids, xyz, appender, Burst(grouper, burst), ask, say,
                             on_point=move if on_point else None, delay=delay,
                             check_every=check_every, unattended=yes)
    try:
        n = session.run()
    except KeyboardInterrupt:
        n = None
    finally:
        grouper.stop()
        done_ids, skipped = appender.accepted()[0], appender.skipped()
        if created and not done_ids and not skipped:
            import shutil

            shutil.rmtree(bundle, ignore_errors=True)  # nothing captured: leave nothing
    done = len(done_ids)
    if n is None:
        click.echo(f"\ninterrupted: {done} points are safe in {survey_path}; run the same "
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
            "--out calibrated.yaml")


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
              help="Survey bundle: points.csv and frames/ (or observations.csv).")
@click.option("--out", "-o", required=True, type=click.Path(dir_okay=False),
              help="Calibrated deployment to write; a report (.report.json, .png) goes beside.")
@click.option("--lens", default="auto", show_default=True,
              type=click.Choice(("auto", "pose", "focal", "principal", "k1", "k2", "full")),
              help="Lens model per camera: auto chooses by held-out error among the nested "
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
@click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
def survey_calibrate(deployment_path, survey_path, out, lens, intrinsics, folds, point_sigma,
                     quiet):
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

    from .datasets import DatasetError, read_survey_bundle
    from .reports import write_calibration
    from .survey import FUSION_OF, SurveyError, calibrate_survey, survey_spots

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
    out = _output_file(out, inputs=(deployment_path, survey_path),
                       beside=(".report.json", ".png"))
    uv, notes = survey_spots(dep, bundle)
    for note in notes:
        click.echo(note, err=True)
    X, ids = bundle.xyz, bundle.point_ids
    _check_survey_positions(survey_path, dep, X, ids)
    try:
        with click.progressbar(length=folds + 1, label="calibrating (lens choice and all, "
                               "then k-fold)", hidden=quiet) as bar:
            result = calibrate_survey(
                dep, X, uv, ids, lens, folds, point_sigma,
                progress=lambda i, n: bar.update(1),
                sources={"deployment": str(deployment_path), "survey": str(survey_path)})
    except SurveyError as e:
        raise UserError(f"{survey_path}: {e}") from None
    _print_calibration(result, folds)
    paths = write_calibration(out, result, notes,
                              header=f"Calibrated by vlpcal survey calibrate from {survey_path}.")
    label = {fusion: row for row, fusion in FUSION_OF.items()}[result.fusion]
    click.echo(f"\nwrote {paths[0]} (fusion: {result.fusion}, the row '{label}'), "
               f"{paths[1]}, {paths[2]}")


def _print_calibration(result, folds: int) -> None:
    """The lens decisions, the held-out table, the per-camera verdicts and the mis-measured
    points."""
    import numpy as np

    from .survey.calibration import format_length

    n = len(result.points)
    prec = result.precision
    click.echo("\nlens, per camera (chosen by held-out reprojection error unless --lens forces "
               "one):")
    for sentence in result.lens:
        click.echo(f"  {sentence}")
    rows = [r for r in result.cameras if r.get("lens_candidates")]
    if rows:
        from .survey import LENS_MODELS

        click.echo(f"held-out reprojection error per lens model, px (* chosen; – not "
                   f"supported or not tried):\n  {'camera':8s}"
                   + "".join(f"{m:>11s}" for m in LENS_MODELS))
        for r in rows:
            cells = []
            for m in LENS_MODELS:
                px = r["lens_candidates"].get(m, {}).get("held_out_px")
                cell = "–" if px is None else f"{px:.3g}" + ("*" if m == r["lens_model"] else "")
                cells.append(f"{cell:>11s}")
            click.echo(f"  {r['camera']:8s}" + "".join(cells))
    how = "estimated from the fit" if prec["estimated"] else "as stated"
    click.echo(f"survey positions: ±{format_length(prec['point_sigma_m'])} per axis ({how}); spots "
               f"±{prec['pixel_sigma_px']:.2g} px")
    # one unit for the table, chosen so that the best row reads with three figures
    means = [st["mean"] for st in result.stats.values() if st["mean"] is not None]
    unit, scale = next(((u, f) for u, f in (("m", 1.0), ("cm", 100.0), ("mm", 1000.0),
                                            ("µm", 1e6)) if means and min(means) * f >= 0.1),
                       ("µm", 1e6))
    click.echo(f"\nheld-out 3D error ({folds}-fold by survey point, {n} points), {unit}; the "
               "reference is the measured position itself "
               f"(±{format_length(prec['point_sigma_m'])} per axis ≈ "
               f"{format_length(prec['point_sigma_m'] * 3 ** 0.5)} in 3D):")
    click.echo(f"{'':32s} {'mean':>7s} {'median':>7s} {'p95':>7s} {'max':>7s} {'fixed':>6s}")
    for label, st in result.stats.items():
        if st["mean"] is None:
            click.echo(f"{label:32s} {'–':>7s} {'':23s} {st['fixed']:6.0%}")
            continue
        cells = " ".join(f"{st[k] * scale:7.3f}" if st[k] * scale < 10 else
                         f"{st[k] * scale:7.1f}" for k in ("mean", "median", "p95", "max"))
        click.echo(f"{label:32s} {cells} {st['fixed']:6.0%}")
    click.echo("(fixed: share of the held-out points with a fix; a point one camera saw "
               "has none)")
    click.echo(f"\n{'camera':8s} {'RMS px':>7s} {'points':>7s} {'lens':>9s} {'moved':>9s} "
               f"{'turned °':>9s}  rejected spots")
    for r in result.cameras:
        click.echo(f"{r['camera']:8s} {r['rms_px']:7.3f} {r['points']:7d} {r['lens_model']:>9s} "
                   f"{format_length(r['moved_m']):>9s} {r['turned_deg']:9.2f}  "
                   f"{', '.join(r['outliers']) or '–'}")
    for r in result.cameras:
        if r["moved_share"] > 0.2 or r["turned_deg"] > 20:
            click.echo(f"warning: camera {r['camera']} moved {format_length(r['moved_m'])} "
                       f"({r['moved_share']:.0%} of its distance to the survey) and turned "
                       f"{r['turned_deg']:.0f}° from the deployment: is this survey from this "
                       "site, and are the camera ids the same?", err=True)
    if result.mismeasured:
        click.echo("\nmis-measured survey points (rejected by the cameras that saw them; how far "
                   "from its record the calibrated cameras put the LED):")
        for pid, off in result.mismeasured:
            click.echo(f"  {pid}: {format_length(off)}" if np.isfinite(off) else f"  {pid}: –")


def _check_survey_positions(survey_path, dep, X, ids) -> None:
    """Refuse positions that cannot be in this room (millimetres read as metres, a typo): a
    margin of a fifth of the room's size around it, and under its ceiling."""
    import numpy as np
    from shapely import contains_xy
    from shapely.geometry import Polygon

    size = max(float(np.ptp(np.asarray(dep.room, float), axis=0).max()), dep.ceiling_height)
    margin = 0.2 * size
    room = Polygon(dep.room).buffer(margin)
    inside = contains_xy(room, X[:, 0], X[:, 1]) & (X[:, 2] > -margin) \
        & (X[:, 2] < dep.ceiling_height)
    if not inside.all():
        i = int(np.flatnonzero(~inside)[0])
        raise UserError(f"{survey_path}: point {ids[i]} at ({X[i, 0]:g}, {X[i, 1]:g}, "
                        f"{X[i, 2]:g}) m is not in the room of {dep.name} (a margin of a fifth "
                        f"of its size) or under its {dep.ceiling_height:g} m ceiling: metres "
                        "expected")


@main.command()
@click.option("--site", "site_path", required=True, type=click.Path(dir_okay=False),
              help="Site file (format vlpcal-site, docs/formats.md).")
@click.option("--out", "-o", required=True, type=click.Path(dir_okay=False),
              help="Deployment to write; maps per LED height (.png) go beside it.")
@click.option("--candidate", default=1, show_default=True, type=click.IntRange(1),
              help="Which ranked candidate to export.")
@click.option("--max-cameras", default=120, show_default=True, type=click.IntRange(2),
              help="Give up above this many cameras.")
@click.option("--quiet", "-q", is_flag=True, help="No progress lines.")
def plan(site_path, out, candidate, max_cameras, quiet):
    """Plan a camera layout: the fewest cameras that meet the site's requirements.

    Every lattice of the site's grid families (square with two spacings, triangular, linear)
    on the 10 cm mounting grid, both camera yaws, cameras clipped to the room; then, when the
    site allows "free" layouts (the default), a local search from the best lattice removes
    cameras and moves the others while the layout still meets the requirements. Every
    candidate is judged by the reference model of docs/formats.md (coverage and predicted
    95th-percentile error). Prints the ranked candidates, writes the chosen one.

    Example: vlpcal plan --site layouts/paper-linear.site.yaml --out deployment.yaml
    """

    from .deployment import save
    from .planning import SiteError, load_site, plan_site, planned_deployment
    from .reports import plan_maps

    try:
        site = load_site(site_path)
    except SiteError as e:
        raise UserError(str(e)) from None
    if not str(out).lower().endswith((".yaml", ".yml")):
        raise UserError(f"{out}: the planned deployment is a YAML file (.yaml); its maps (.png) "
                        "go beside it")
    out = _output_file(out, inputs=(site_path,), beside=(".png",))
    say = (lambda m: None) if quiet else (lambda m: click.echo(m, err=True))
    result = plan_site(site, max_cameras, progress=say)
    r = site.requirements
    if not result.candidates:
        c = result.closest
        best = (f"for comparison, a dense lattice of {c.count} cameras covers "
                f"{c.evaluation.coverage:.1%} with p95 {c.evaluation.p95 * 100:.2f} cm"
                if c else "no layout could be evaluated")
        raise click.ClickException(
            f"{site_path}: no layout of up to {max_cameras} cameras meets coverage "
            f"{r.coverage:.0%} with p95 ≤ {r.max_error_p95 * 100:g} cm ({best}); relax the "
            "requirements, lower the LED heights or use a camera with more pixels")
    k = len(result.candidates)
    click.echo(f"{site.name}: {result.candidates[0].count} cameras meet the requirements "
               f"({k} candidate{'s' if k > 1 else ''}; {result.tried} layouts judged, "
               f"{result.seconds:.1f} s)\n")
    click.echo(f"{'#':>2s} {'layout':10s} {'cams':>4s} {'x×y':>6s} {'spacing m':>12s} "
               f"{'yaw':>5s} {'coverage':>8s} {'mean cm':>8s} {'p95 cm':>7s}")
    for k, c in enumerate(result.candidates, start=1):
        xs = {round(cam.position[0], 6) for cam in c.cameras}
        ys = {round(cam.position[1], 6) for cam in c.cameras}
        grid = f"{len(xs)}×{len(ys)}"
        sp = "×".join(f"{v:.2f}" for v in c.spacing) if c.spacing else "–"
        yaw = "/".join(str(a) for a in sorted({round(math.degrees(math.atan2(
            cam.R[0][1], cam.R[0][0]))) % 180 for cam in c.cameras}))
        click.echo(f"{k:2d} {c.family:10s} {c.count:4d} {grid:>6s} {sp:>12s} {yaw:>5s} "
                   f"{c.evaluation.coverage:8.1%} {c.evaluation.mean * 100:8.2f} "
                   f"{c.evaluation.p95 * 100:7.2f}")
    for family, why in result.missing.items():
        click.echo(f"   {family:10s} {why}")
    click.echo(f"x×y: distinct camera positions along x and y (cameras on a {_mount(site)} "
               "grid from the room's lower-left corner, half a step from the walls); yaw: "
               f"degrees from the room's x axis to each image's {site.camera.width} px side "
               "(the maps draw it)")
    if candidate > len(result.candidates):
        raise UserError(f"--candidate {candidate}: the plan has {k} candidate"
                        f"{'s' if k > 1 else ''}, numbered from 1")
    chosen = result.candidates[candidate - 1]
    dep = planned_deployment(site, chosen, candidate, site_path)
    save(dep, out, header=f"Planned by vlpcal plan from {site_path}: candidate {candidate}.")
    say("  drawing the maps…")
    plan_maps(out.with_suffix(".png"), site, chosen)
    click.echo(f"\nwrote {out} (candidate {candidate}) and {out.with_suffix('.png')}")


@main.command("check")
@click.option("--site", "site_path", required=True, type=click.Path(dir_okay=False),
              help="Site file with the requirements (format vlpcal-site, docs/formats.md).")
@click.option("--deployment", "-d", "deployment_path", required=True,
              type=click.Path(dir_okay=False),
              help="The layout to judge: any deployment (planned, installed, calibrated, "
                   "edited by hand).")
@click.option("--maps", type=click.Path(dir_okay=False), default=None,
              help="Also write the maps per LED height (as vlpcal plan does) to this .png.")
def check(site_path, deployment_path, maps):
    """Judge a layout against a site's requirements with the reference model.

    The same model that vlpcal plan uses: the sample points of the site's room (minus keep-out)
    at the lowest, middle and highest LED height; a point counts when enough of the layout's
    cameras see it, and the predicted error at the site's spot noise decides the p95. Prints
    coverage, p95 and a verdict with the reason; exits 0 when the layout meets the site, 1 when
    it does not.

    Example: vlpcal check --site site.yaml -d layouts/paper-linear.deployment.yaml
    """

    import numpy as np

    from .planning import Candidate, SiteError, evaluate, load_site
    from .reports import plan_maps

    try:
        site = load_site(site_path)
    except SiteError as e:
        raise UserError(str(e)) from None
    dep = _load_deployment(deployment_path)
    if maps is not None:
        if not str(maps).lower().endswith(".png"):
            raise UserError(f"{maps}: the maps are a PNG picture (.png)")
        maps = _output_file(maps, inputs=(site_path, deployment_path))
    ev = evaluate(site, list(dep.cameras))
    r = site.requirements
    levels = sorted(set(ev.points[:, 2].round(6)))
    hs = ", ".join(f"{h:g}" for h in levels)
    n = len(dep.cameras)
    click.echo(f"{deployment_path}: {n} camera{'' if n == 1 else 's'} judged against "
               f"{site_path} ({site.name}; LED at {hs} m, {r.min_cameras} cameras per point, "
               f"spot noise {r.pixel_noise:g} px):")
    model = site.camera
    other = sorted({c.id for c in dep.cameras if (c.width, c.height) != (model.width,
                                                                         model.height)})
    if other:
        click.echo(f"  note: {', '.join(other[:5])}{' …' if len(other) > 5 else ''} have another "
                   "image size than the site's camera model; each camera is judged as it is")
    from shapely import contains_xy
    from shapely.geometry import Polygon

    xy = np.array([c.position[:2] for c in dep.cameras]).reshape(-1, 2)
    outside = [c.id for c, inside in zip(dep.cameras, contains_xy(Polygon(site.room), xy[:, 0],
                                                                   xy[:, 1])) if not inside]
    high = [c.id for c in dep.cameras if not 0 < c.position[2] <= site.ceiling_height]
    if outside or high:
        click.echo(f"  note: camera(s) {', '.join((outside + high)[:5])} hang outside the "
                   "room or above its ceiling; judged as they are")
    p95 = f"{ev.p95 * 100:.2f} cm" if math.isfinite(ev.p95) else "–"
    mean = f"{ev.mean * 100:.2f} cm" if math.isfinite(ev.mean) else "–"
    click.echo(f"  coverage {ev.coverage:.1%} (required {r.coverage:.1%}): the share of the "
               f"floor's sample points seen by {r.min_cameras} or more cameras")
    click.echo(f"  predicted error over those points: p95 {p95} (required ≤ "
               f"{r.max_error_p95 * 100:.3g} cm), mean {mean}")
    why = []
    if ev.coverage < r.coverage:
        why.append(f"coverage {ev.coverage:.1%} < {r.coverage:.1%}")
    if not ev.p95 <= r.max_error_p95:
        why.append(f"p95 {ev.p95 * 100:.3f} cm > {r.max_error_p95 * 100:.3f} cm")
    if dep.room != site.room:
        click.echo("  note: the deployment's room differs from the site's; the site's is used")
    if maps is not None:
        cand = Candidate(f"as in {deployment_path}", 0, 0, (), (), 0.0, list(dep.cameras), ev)
        plan_maps(maps, site, cand)
        click.echo(f"  maps: {maps}")
    if why:
        click.echo(f"verdict: does not meet the site ({'; '.join(why)})")
        raise SystemExit(1)
    click.echo("verdict: meets the site")


@main.command("export")
@click.option("--deployment", "-d", "deployment_path", required=True,
              type=click.Path(dir_okay=False), help="The deployment whose cameras to export.")
@click.option("--to", "fmt", type=click.Choice(["anipose", "opencv"]), default=None,
              help="anipose: aniposelib CameraGroup TOML; opencv: cv::FileStorage YAML  "
                   "[default: from --out's extension, .toml or .yaml]")
@click.option("--out", "-o", required=True, type=click.Path(dir_okay=False),
              help="File to write (.toml for anipose, .yaml for opencv).")
@click.option("--units", type=click.Choice(["m", "cm", "mm"]), default="m", show_default=True,
              help="Length unit of the anipose translations (anipose itself uses the "
                   "calibration board's, often mm). The OpenCV file is always in metres.")
def export_cameras(deployment_path, fmt, out, units):
    """Export a deployment's cameras for other tools, in their order, convention stated.

    Both formats hold OpenCV's model: camera matrix, distortion [k1, k2, p1, p2, k3], rvec
    (world → camera) and tvec = −R · position; the world is the room's (z up, floor at 0).
    aniposelib sorts camera sections as text, so sections are zero-padded (cam_00 … cam_11)
    and keep their order for any number of cameras.

    Example: vlpcal export -d planned.yaml --to anipose -o calibration.toml
    """

    from .deployment import atomic_write_text
    from .interchange import to_anipose_toml, to_opencv_yaml

    dep = _load_deployment(deployment_path)
    out = _output_file(out)
    kind = {".toml": "anipose", ".yaml": "opencv", ".yml": "opencv"}.get(out.suffix.lower())
    if fmt is None and kind is None:
        raise UserError(f"{out}: give --to anipose or --to opencv (or name the file .toml or "
                        ".yaml)")
    if fmt and kind and fmt != kind:
        raise UserError(f"{out}: a {out.suffix} name for --to {fmt} (vlpcal import reads "
                        f"{'.toml' if fmt == 'anipose' else '.yaml'} files as {fmt}): rename it")
    fmt = fmt or kind
    if fmt == "opencv" and units != "m":
        raise UserError("--units: the OpenCV file is always in metres (--units is for anipose)")
    if fmt == "anipose":
        text = to_anipose_toml(dep.cameras, units, {"deployment": dep.name})
    else:
        text = to_opencv_yaml(dep.cameras)
    atomic_write_text(out, text)
    click.echo(f"wrote {len(dep.cameras)} cameras of {dep.name} to {out} ({fmt}"
               f"{', ' + units if fmt == 'anipose' else ', m'})")


@main.command("import")
@click.option("--cameras", "cameras_path", required=True, type=click.Path(dir_okay=False),
              help="aniposelib TOML (.toml) or the OpenCV YAML vlpcal export writes (.yaml).")
@click.option("--base", "-b", "base_path", required=True, type=click.Path(dir_okay=False),
              help="A deployment or site file giving the room (its cameras are replaced).")
@click.option("--out", "-o", required=True, type=click.Path(dir_okay=False),
              help="Deployment to write.")
@click.option("--units", type=click.Choice(["m", "cm", "mm"]), default=None,
              help="Length unit of an aniposelib TOML that does not state one in [metadata] "
                   "(aniposelib's own files do not).")
def import_cameras(cameras_path, base_path, out, units):
    """Make a deployment from cameras calibrated by another tool.

    The cameras' world frame must be the room's (z up, floor at z = 0, metres once scaled):
    an anipose calibration is in its first camera's or its board's frame until aligned to
    the floor. Cameras must hang between the floor and 0.5 m above the ceiling, within 1 m
    of the room in plan. The room, keep-out areas and settings come from --base; its region
    map and pixel corrections are dropped, with a note, unless the cameras are the base's.

    Example: vlpcal import --cameras calibration.toml --units mm -b site.yaml -o cams.yaml
    """
    from pathlib import Path

    from .deployment import Deployment, DeploymentError, from_dict, provenance, save
    from .interchange import (
        InterchangeError,
        check_world_frame,
        from_anipose_toml,
        from_opencv_yaml,
        same_cameras,
    )
    from .planning import site_from_dict
    from .reading import ReadError, load_yaml, read_text

    path = Path(cameras_path)
    try:
        text = read_text(path, "a camera file (TOML or YAML)")
        base_doc = load_yaml(base_path, "a vlpcal deployment or site file")
    except ReadError as e:
        if "not valid YAML" not in str(e):
            raise UserError(str(e)) from None
        base_doc = None  # said below, with what the base must be
    kind = base_doc.get("format") if isinstance(base_doc, dict) else None
    if kind not in ("vlpcal-site", "vlpcal-deployment"):
        raise UserError(f"{base_path}: not a vlpcal deployment or site file (expected YAML "
                        "with format: vlpcal-deployment or vlpcal-site)")
    try:
        if kind == "vlpcal-site":
            site = site_from_dict(base_doc, str(base_path))
            base = Deployment(site.name, site.ceiling_height, site.room, [], site.keep_out)
        else:
            base = from_dict(base_doc, str(base_path))
    except DeploymentError as e:
        raise UserError(str(e)) from None
    try:
        if path.suffix.lower() == ".toml":
            cams = from_anipose_toml(text, str(path), units)
        elif path.suffix.lower() in (".yaml", ".yml"):
            if units:
                raise InterchangeError("--units: the OpenCV file states its unit (units:); "
                                       "--units is for aniposelib TOML")
            cams = from_opencv_yaml(text, str(path))
        else:
            raise InterchangeError(f"{path}: unknown kind (expected .toml for anipose or .yaml "
                                   "for OpenCV FileStorage)")
        check_world_frame(cams, base.ceiling_height, str(path), base.room)
    except InterchangeError as e:
        raise UserError(str(e)) from None
    extra = {k: v for k, v in base.extra.items() if k != "provenance"}
    if not same_cameras(cams, base.cameras):
        # a region map and pixel corrections were learned for the base's cameras: with other
        # cameras (or the same ones calibrated anew) they no longer hold
        dropped = [k for k in ("corrections",) if k in extra]
        if "region_map" in extra.get("fusion", {}):
            extra["fusion"] = {k: v for k, v in extra["fusion"].items() if k != "region_map"}
            if extra["fusion"].get("method") == "region":
                extra["fusion"].pop("method")
            dropped.append("fusion.region_map")
        for k in dropped:
            extra.pop(k, None)
        if dropped:
            click.echo(f"dropped {', '.join(dropped)} of {base_path}: learned for other "
                       "cameras (run survey calibrate to learn them again)", err=True)
    extra["provenance"] = provenance("vlpcal import", **{"from": {"cameras": str(path),
                                                                  "base": str(base_path)}})
    out = _output_file(out)
    dep = Deployment(base.name, base.ceiling_height, base.room, cams, base.keep_out, extra)
    try:
        save(dep, out, header=f"Cameras imported by vlpcal import from {path}.")
    except DeploymentError as e:
        raise UserError(f"{path}: {e}") from None
    click.echo(f"wrote {out}: {len(cams)} cameras ({', '.join(c.id for c in cams)}) in the room "
               f"of {base.name}")

