"""``vlpcal survey capture``: a survey captured live — the LED walked through the points
while the cameras stream, each point on disk before the next prompt; with ``--free``, a free
(or wand) survey recorded first."""

from __future__ import annotations

import math
import os
import re
import select
import shlex
import shutil
import subprocess
import sys
import time
from functools import partial
from pathlib import Path

import click

from ..capture import BURST, Burst, CaptureSession, FreeRecorder, Step
from ..datasets import DatasetError, FreeAppender, SurveyAppender, read_points
from ..live import LiveGrouper
from ..survey import SurveyError, free_route
from .common import Finite, UserError, _camera_sources, _load_deployment, echo
from .survey_shared import CAPTURE_SECONDS, CAPTURE_SETS, _check_survey_positions
from .view import DEFAULT_BIND


class NoCameraAnswered(UserError):
    """No camera sent a frame (off, unreachable, or too slow): one line naming each and why,
    exit 1 as a live ``locate`` without frames — not a mistake in the command's inputs."""

    exit_code = 1


#: per prompt: the keys shown, and what each means (Enter is "")
KEYS = {"place": ("Enter: capture · s skip · b back · e extra point · q quit",
                  {"": "go", "e": "extra"}),
        "accept": ("Enter: accept · r redo · s skip · b back · q quit",
                   {"": "accept", "r": "redo"}),
        "retry": ("Enter: try again · s skip · b back · q quit", {"": "redo"})}


class _Prompt:
    """The surveyor's answer at each step of a capture (:class:`~vlpcal.capture.Step`), read
    from stdin — or, ``unattended``, always go on and accept."""

    def __init__(self, unattended: bool, say):
        self.unattended, self.say = unattended, say

    def __call__(self, kind: str, prompt: str) -> Step:
        if self.unattended:
            if kind == "place":
                self.say(prompt)
            return Step("go" if kind == "place" else "accept")
        shown, own = KEYS[kind]
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
                self.say(f"  ? {line.strip()!r}: press Enter or one of {keys_ok}")
                continue
            if choices[key] != "extra":
                return Step(choices[key])
            step = self._extra()
            if step is not None:
                return step

    def _extra(self) -> Step | None:
        """An extra point's measured position, asked for (None: not three numbers)."""
        echo("  measured position of the extra point, x y z in metres > ", nl=False)
        sys.stdout.flush()
        try:
            vals = [float(t) for t in sys.stdin.readline().replace(",", " ").split()]
        except ValueError:
            vals = []
        if len(vals) == 3 and all(map(math.isfinite, vals)):
            return Step("extra", tuple(vals))
        self.say("  expected three numbers, e.g. 1.20 0.45 0.35")
        return None


def _move_rig(on_point: str, pid, p) -> None:
    """``--on-point``: the shell command that moves a rig to point ``pid`` at ``p`` (its
    {id}, {x}, {y}, {z} filled in, quoted, and in the environment); a failure stops the
    capture, the survey so far kept."""
    values = {"id": pid, **{a: f"{v:.6g}" if math.isfinite(v) else ""  # (a mark's: "")
                            for a, v in zip("xyz", p)}}
    cmd = re.sub(r"\{(id|x|y|z)\}", lambda m: shlex.quote(values[m.group(1)]), on_point)
    env = {**os.environ, **{f"VLPCAL_POINT_{k.upper()}": v for k, v in values.items()}}
    res = subprocess.run(cmd, shell=True, env=env)
    if res.returncode:
        raise UserError(f"--on-point {cmd!r} failed (exit {res.returncode}) at {pid}; "
                        "the survey so far is kept: fix the rig and run again to resume")


@click.command("capture")
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
    grouper, frames = _cameras_answering(dep, sources, burst)
    hub = server = None
    if view_bind is not None:
        hub, server = _live_page(dep, grouper, view_bind, deployment_path, survey_path, wand)
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

    ask = _Prompt(yes, say)
    move = partial(_move_rig, on_point)
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


def _cameras_answering(dep, sources, burst):
    """Every camera asked for a frame before the walk starts (and before any file exists):
    each said with its answer on stderr; none answering is :class:`NoCameraAnswered`.
    Returns the live grouper and its bursts."""
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
    return grouper, frames


def _live_page(dep, grouper, view_bind, deployment_path, survey_path, wand):
    """``--view``: the capture on the live page (each camera's frames and spots, a wand's
    two). Returns its hub and server."""
    from ..view.tap import FrameTap  # (the web framework: only for a live page)
    from .view import open_view

    hub, server = open_view(dep, view_bind, source=f"vlpcal survey capture → {survey_path}",
                            path=deployment_path)
    hub.tracking = False  # a survey: no tracks to come
    grouper.tap = FrameTap(hub, dep, spots=2 if wand is not None else 1)
    return hub, server


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
        from ..view.tap import survey_coverage  # (the web framework: only for a live page)

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
