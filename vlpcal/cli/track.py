"""The robot integrator's command: an LED's track from cameras that are not synchronised
(``vlpcal track``)."""

from __future__ import annotations

import re

import click

from .common import (
    Finite,
    FitCheck,
    UserError,
    _load_deployment,
    _output_file,
    _same_file,
    dataset_error,
    echo,
    main,
)
from .mqtt import mqtt_options, open_publisher, parse_mqtt, publisher_summary, subscriber_notes
from .view import DEFAULT_BIND


@main.command()
@click.option("--deployment", "-d", "deployment_path", required=True,
              type=click.Path(dir_okay=False), help="Deployment YAML (docs/formats.md).")
@click.option("--frames", "frames_dir", default=None, type=click.Path(file_okay=False),
              help="Asynchronous frames: <camera_id>/<frame_no>.jpg and times.csv "
                   "(camera_id,frame_no,t: capture time, s, on one clock).")
@click.option("--camera", "cameras", multiple=True, metavar="ID=SOURCE",
              help="Live source per camera instead of --frames: an MJPEG URL (ESP32-CAM: "
                   "http://IP:81/stream; its X-Timestamp is used) or a video device. Repeat "
                   "for each camera.")
@click.option("--spots", "spots_url", default=None, metavar="mqtt://…/PREFIX",
              help="Instead of frames: the spots cameras publish on PREFIX/spots/<camera_id> "
                   "({\"t\": capture time, UTC s, \"u\": px, \"v\": px}; docs/mqtt.md).")
@click.option("--duration", type=Finite(0, 1e7, min_open=True), default=None,
              help="Live: stop after this many seconds.  [default: until Ctrl-C or every "
                   "camera stops]")
@click.option("--lag", type=Finite(0, 60), default=None,
              help="Seconds after a frame's capture its row is written: 0 writes each row as "
                   "its frame comes (the window then ends at it: for a robot that steers by "
                   "it, at a larger error); at most half the window.  [default: half the "
                   "fit's window (2 frame periods), the smoothest]")
@click.option("--leds", "spots", type=click.IntRange(1, 64), default=None,
              help="The most LEDs in view (spots looked for in each frame).  [default: the "
                   "deployment's leds: block's count, else 1]")
@click.option("--out", "-o", required=True, type=click.Path(dir_okay=False),
              help="Tracks file to write (.csv).")
@click.option("--fps", default=None, type=Finite(0.1, 10000.0),
              help="The cameras' frame rate.  [default: from times.csv, the slowest camera's]")
@click.option("--keep-going", is_flag=True,
              help="Go on when the frames do not fit the deployment (most moments two cameras "
                   "see a spot not placed: another install's deployment, cameras swapped, a "
                   "stale calibration); said once as a warning.  [default: stop, exit 2]")
@mqtt_options
@click.option("--quiet", "-q", is_flag=True, help="No progress bar or summary.")
@click.option("--plot", "plot", default=None, type=click.Path(dir_okay=False),
              metavar="PNG", help="Also draw the run: each id's path on the plan and its "
                                  "sigma_m over time (a PNG, written at the end).")
@click.option("--view", "view_bind", is_flag=False, flag_value=DEFAULT_BIND, default=None,
              metavar="[HOST:PORT]",
              help=f"Show the run live in the browser (vlpcal view's page; default "
                   f"{DEFAULT_BIND}): the cameras' frames and spots, the tracks on the plan.")
def track(deployment_path, frames_dir, cameras, spots_url, duration, lag, spots, out, fps,
          keep_going, publish, qos, ca_file, quiet, plot, view_bind):
    """Track moving LEDs from cameras that are not synchronised.

    Each camera frame is a ray at its own capture time; the LED's path over a short window is
    fitted to every ray in it, so no two views need to be simultaneous. One row per camera
    frame that saw an LED: t,led,x,y,z,vx,vy,vz,sigma_m,cameras,status (m, m/s; t in s on the
    frames' clock, or UTC seconds live; status ok where two cameras or more placed it,
    one_camera where one camera saw it and its motion carried it, degenerate — no position —
    where that guess is as uncertain as a tenth of the room, times_unchecked — no position —
    live before the cameras' capture times were checked against each other, the first
    second or so of a moving LED). With the deployment's leds:
    block, each LED is named by its blink code; without, tracks are T1, T2…

    Example: vlpcal track -d deployment.yaml --frames streams/ --out tracks.csv
    """
    dep = _load_deployment(deployment_path)
    if sum(map(bool, (frames_dir, cameras, spots_url))) != 1:
        raise UserError("give exactly one of --frames DIR, --camera ID=SOURCE … (one per "
                        "camera) or --spots mqtt://…")
    if ca_file:  # what the tracks must never overwrite
        _output_file(out, inputs=(deployment_path, ca_file), what="the tracks")
    if spots is not None and spots < len(dep.leds):  # a warning: -q hides none
        echo(f"warning: --leds {spots}: {deployment_path} has {len(dep.leds)} LEDs in "
             f"its leds: block; each frame is searched for {spots} spot(s), so the "
             "others are not tracked whenever more are in view", err=True)
    if plot is not None:
        if not str(plot).lower().endswith(".png"):
            raise UserError(f"--plot {plot}: the figure is a PNG picture (.png)")
        plot = _output_file(plot, inputs=(deployment_path,) + ((frames_dir,) if frames_dir
                                                               else ()), what="the figure")
        if _same_file(plot, _output_file(out, inputs=(deployment_path,), what="the tracks")):
            raise UserError(f"--plot {plot}: the same file as --out")
    if view_bind is not None and frames_dir:
        raise UserError("--view shows a live run (--camera or --spots); a folder of frames is "
                        "tracked faster than it could be watched")
    publisher = open_publisher(publish, qos, ca_file, dep, deployment_path)
    check = FitCheck(keep_going, "the rows so far are kept" if publisher or spots_url or cameras
                     else "nothing was written")
    hub = server = None
    try:
        if view_bind is not None:
            from .view import open_view

            hub, server = open_view(dep, view_bind, source=f"vlpcal track → {out}",
                                    path=deployment_path)
        if spots_url:
            rows = _track_spots(dep, deployment_path, parse_mqtt(spots_url, "--spots"),
                                ca_file, duration, lag, spots, out, fps, quiet, publisher,
                                check, hub)
        elif cameras:
            rows = _track_live(dep, deployment_path, cameras, duration, lag, spots, out, fps,
                               quiet, publisher, check, hub)
        else:
            rows = _track(dep, deployment_path, frames_dir, duration, lag, spots, out, fps,
                          quiet, publisher, check, plot)
        if plot is not None:
            from ..reports import track_figure
            from ..writing import OutputSet

            if not frames_dir:  # (a folder's figure is written with its tracks: _track)
                with OutputSet(plot) as (png,):
                    track_figure(png, dep, rows, f"{dep.name}: vlpcal track → {out}")
            if not quiet:
                echo(f"figure → {plot}", err=True)
    finally:
        if server is not None:
            server.close()
        if publisher:
            publisher.close()
            if not quiet:
                echo(publisher_summary(publisher), err=True)


class _Layouts:
    """Says, once each, the pairs of a body's LEDs that lie apart otherwise than its layout
    (:meth:`~vlpcal.tracking.Tracker.layout_misfits`; a warning: -q hides none): every
    ``every`` calls during a live run, so a service says it within seconds, and at the end."""

    def __init__(self, tracker, every: int = 300):
        self.tracker, self.every, self.calls, self.said = tracker, every, 0, set()

    def __call__(self, end: bool = False) -> None:
        self.calls += 1
        if not self.tracker.bodies or not (end or self.calls % self.every == 0):
            return
        for misfit in self.tracker.layout_misfits():
            if (misfit.body, misfit.leds) not in self.said:
                self.said.add((misfit.body, misfit.leds))
                echo(f"warning: {misfit.message()}", err=True)


#: why a frame could not be measured, said of frames
_UNREADABLE = {"wrong_size": "of another size than their camera's", "corrupt_frame": "not whole "
               "JPEGs"}


def _no_rows(tracker, source, unreadable=None, what: str = "frame") -> UserError:
    """Why a run gave no row at all (``unreadable``: frames not measured, by reason;
    ``what`` a frame is: a camera frame, or a spot message)."""
    fit = tracker.fit
    if unreadable and not tracker.frames_with_spot:
        why = "; ".join(f"{n} frames {_UNREADABLE.get(w, w)}" for w, n in unreadable.items()) \
            + " (is it the deployment of these cameras?)"
    elif not tracker.frames_with_spot:
        why = (f"no {what} had a spot (is the LED on and in view, and the exposure right?)"
               if what == "frame" else f"no {what} carried a spot (is the LED on and in view?)")
    elif not fit.moments:
        why = (f"{tracker.frames_with_spot} frames had a spot, but never two cameras' at "
               "about the same moment (a track needs two cameras)")
    else:
        why = (f"of {fit.moments} spots seen while another camera saw one, none was "
               "placed: no two cameras' spots meet as one LED; is it the right deployment?")
    return UserError(f"{source}: no rows: {why}")


def _published(publisher, rows, utc: float = 0.0):
    """``rows`` (track updates) published as they are made, when --publish asks; returned."""
    if publisher:
        from ..mqtt import track_message

        for r in rows:
            publisher.publish(r.led, track_message(r.t + utc, r),
                              "bodies" if r.pose is not None else "fixes")
    return rows


def _track(dep, deployment_path, frames_dir, duration, lag, spots, out, fps, quiet,
           publisher, check, plot=None) -> list:
    import sys

    from ..datasets import DatasetError, read_async_frames
    from ..live import FrameIntervals
    from ..tracking import Tracker
    from ..tracking.recording import recording_spots, tracked_again

    if duration is not None:
        raise click.BadParameter("is for live cameras (--camera)", param_hint="--duration")
    try:
        folder = read_async_frames(frames_dir)
    except DatasetError as e:
        raise dataset_error(e) from None
    unknown = sorted(set(folder.camera_ids) - {c.id for c in dep.cameras})
    if unknown:
        raise UserError(f"{frames_dir}: cameras {', '.join(unknown)} are not in "
                        f"{deployment_path} (expected its camera ids)")
    for cid, lo, hi, others in folder.alone():  # a warning: -q hides none
        echo(f"warning: {folder.root / 'times.csv'}: {cid}'s capture times "
             f"({lo:.6g}–{hi:.6g} s) never overlap those of {', '.join(others)}, so its "
             "frames are never seen with theirs: are all the times on one clock?",
             err=True)
    if fps is None:  # the slowest camera's median frame interval
        intervals = FrameIntervals(kept=None)
        for t, cid, _ in folder.events:
            intervals.add(cid, t)
        fps = 1.0 / intervals.period(default=1 / 30, least=1)
        if not 0.1 <= fps <= 10000:
            raise UserError(f"{frames_dir}/times.csv: its cameras' frames are "
                            f"{1 / fps:.3g} s apart (expected capture times in seconds: "
                            "0.1 to 10 000 frames a second); or give --fps")
    # the folder, and what it holds through links (times.csv, each camera's folder)
    from pathlib import Path

    held = [Path(frames_dir) / "times.csv", *(Path(frames_dir) / c for c in folder.camera_ids)]
    out = _output_file(out, inputs=(deployment_path, frames_dir, *held), what="the tracks")
    tracker = Tracker(dep, period=1.0 / fps, spots=spots, lag=lag)
    rows = []
    with click.progressbar(length=len(folder.events), label="tracking", hidden=quiet,
                           file=sys.stderr) as bar:
        found = recording_spots(folder, tracker, progress=bar.update)
    spotted, missing, unreadable = found.spotted, found.missing, found.unreadable
    if missing == len(folder.events):
        raise UserError(f"{frames_dir}: none of the {missing} frames times.csv lists is there "
                        "(expected <camera_id>/<frame_no>.jpg); nothing was written")
    drifts = tracker.search_times(spotted)  # the cameras' times, searched on the recording
    drifted = f"{folder.root / 'times.csv'}: {drifts[0].message()}" if drifts else ""
    check.also = lambda watch: drifted or _wandering_said(watch)  # (said with the fit
    # watch's verdict, which names a wrong deployment first: a clock's drift looks alike)
    for t, cid, uv in tracker.in_order(spotted):
        rows.extend(_published(publisher, tracker.update_spots(cid, t, uv)))
        check(tracker)  # (a deployment that does not fit is said first: its skews wander too)
    if drifts and not check.said:  # times that place no frame right
        if not check.keep_going:
            raise UserError(f"{drifted} (nothing was written)")
        echo(f"warning: {drifted} (going on: --keep-going)", err=True)
    rows += _published(publisher, tracker.finish())
    if tracker.latencies() and publisher is None:  # rows from the first frame at the
        tracker, rows = tracked_again(tracker, spotted, check)  # times the run found
    _said_latencies(tracker)
    _Layouts(tracker)(end=True)
    wrong = {m.body for m in tracker.layout_misfits()}
    if wrong:  # its rows before the verdict were skewed by the layout too: none written
        kept = [r for r in rows if not (r.pose is not None and r.led in wrong)]
        if len(kept) < len(rows):
            echo(f"warning: {len(rows) - len(kept)} rows of {', '.join(sorted(wrong))} "
                 "given before its layout was judged are left out of the file", err=True)
        rows = kept
    if not rows:
        raise _no_rows(tracker, frames_dir, unreadable)
    _write_tracks(out, rows, pose_columns=bool(tracker.bodies),
                  figure=(plot, dep, f"{dep.name}: vlpcal track → {out}") if plot else None)
    if not quiet:
        bad = "; ".join(f"{n} frames {_UNREADABLE.get(w, w)}" for w, n in unreadable.items())
        echo(f"{len(folder.events)} camera frames ({fps:g} fps) → {_summary(rows)} → {out}"
             + _lag_said(tracker)
             + (f"; {missing} listed frames missing" if missing else "")
             + (f"; {bad} (not used)" if bad else ""), err=True)
    return rows


def _said_latencies(tracker) -> None:
    """Cameras whose capture times the run found to run late or early, said (a warning: a
    camera's clock or link to see to)."""
    for cid, late in sorted(tracker.latencies().items()):
        if abs(late) < 0.1 * tracker.period:  # (within a tenth of a frame: nothing to see to)
            continue
        echo(f"warning: camera {cid}'s capture times are {abs(late):.3f} s "
             f"{'late' if late > 0 else 'early'} against the others' (seen in the LED's "
             f"motion): its frames were placed {abs(late):.3f} s "
             f"{'earlier' if late > 0 else 'later'} than their times say", err=True)
    wander = _wandering_said(tracker)
    if wander:
        echo(f"warning: {wander}; their rows' sigma_m hold it", err=True)


def _wandering_said(tracker) -> str:
    """The cameras whose latency wanders along the run, said ("" if none): a possible cause
    of a misfit, and a warning after a run."""
    spread = sorted(tracker.wandering().items())
    if not spread:
        return ""
    return (f"camera{'s' * (len(spread) > 1)} {', '.join(c for c, _ in spread)}: capture "
            f"times wander by {', '.join(f'±{s:.3f}' for _, s in spread)} s (1 sigma) "
            "against the others' along the LED's motion (a clock running fast or slow? "
            "frames stamped late under load?)")


def _write_tracks(out, rows, utc: float = 0.0, pose_columns: bool = False,
                  figure=None) -> None:
    """The tracks file, staged and renamed (``utc``: added to each row's time;
    ``pose_columns``: the bodies' columns too; ``figure``: (png, deployment, title), drawn
    and renamed with the tracks as one set: a stop while drawing replaces neither)."""
    import csv

    from ..writing import OutputSet

    with OutputSet(*([figure[0]] if figure else []), out) as staged:
        tmp = staged[-1]
        if figure:
            from ..reports import track_figure

            track_figure(staged[0], figure[1], rows, figure[2])
        with open(tmp, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(_columns(pose_columns))
            w.writerows(_utc_row(r, utc, pose_columns) for r in rows)


def _columns(pose_columns: bool) -> tuple:
    from ..tracking import BODY_COLUMNS, TRACK_COLUMNS

    return TRACK_COLUMNS + (BODY_COLUMNS if pose_columns else ())


def _utc_row(update, utc: float, pose_columns: bool = False) -> list:
    """A track update's CSV row, its time moved by ``utc`` s (live: the host's monotonic clock
    to UTC)."""
    row = update.row(pose_columns)
    if utc:
        row[0] = f"{update.t + utc:.6f}"
    return row


def _lag_said(tracker) -> str:
    """What the summary says of a --lag past half the fit's window (the most a row can wait)."""
    if tracker.lag is None or tracker.lag <= tracker.half:
        return ""
    return (f"; --lag {tracker.lag:g} s is past half the fit's window: rows were written "
            f"{tracker.half:.3g} s after their frames")


def _summary(rows) -> str:
    ok = sum(r.status == "ok" for r in rows)
    leds = sorted({r.led for r in rows if r.pose is None},  # T2 before T10
                  key=lambda led: [int(p) if p.isdigit() else p for p in re.split(r"(\d+)", led)])
    bodies = sorted({r.led for r in rows if r.pose is not None})
    shown = ", ".join(leds[:12]) + (f" and {len(leds) - 12} more" if len(leds) > 12 else "")
    return (f"{len(rows)} rows, {ok} placed by two cameras or more, tracks {shown or '–'}"
            + (f", bodies {', '.join(bodies)}" if bodies else ""))


def _track_live(dep, deployment_path, cameras, duration, lag, spots, out, fps, quiet,
                publisher, check, hub=None) -> list:
    """``vlpcal track --camera …``: frames as they come, each at its capture time on the
    host's clock (X-Timestamp through each camera's clock estimate, else arrival), fed to
    the tracker in that order; rows in UTC seconds. ``out`` None: no file (the view alone);
    ``hub``: the live page's (:class:`~vlpcal.view.ViewHub`), given each frame, its spots
    and the rows."""
    import time

    from ..live import TimedFrames
    from ..tracking import Tracker
    from .common import _camera_sources

    sources = _camera_sources(cameras, dep, stamps=True)
    if out is not None:
        out = _output_file(out, inputs=(deployment_path,), what="the tracks")

    def say(msg):
        if not quiet:
            echo(msg, err=True)

    t_end = time.monotonic() + duration if duration else None
    frames = TimedFrames(sources, deadline=t_end, on_event=say)
    tracker = Tracker(dep, period=1.0 / (fps or 30.0), spots=spots, lag=lag)
    layouts = _Layouts(tracker)
    utc = time.time() - time.monotonic()  # the host's monotonic clock → UTC seconds
    # row by row, flushed: a reader follows
    live = _LiveTracks(out, utc, bool(dep.bodies)) if out is not None else _NoTracks()
    rows: list = []
    n = 0
    from collections import Counter

    from ..detection import detect_frame

    cams = {c.id: c for c in dep.cameras}
    unreadable: Counter = Counter()  # frames not measured, by reason (as --frames counts)

    def put(made):
        live.write(made)
        if hub is not None:
            hub.track_rows(made, utc)

    def detect(cid, frame):
        """The frame's spots as :meth:`~vlpcal.tracking.Tracker.detect` finds them, and
        why it could not be measured counted."""
        cam = cams[cid]
        uv, why = detect_frame(frame, tracker.spots, dep.detector, dep.detector_settings,
                               shape=(cam.height, cam.width))
        if why is not None:
            unreadable[why] += 1
        return uv

    try:
        for t, cid, frame in frames:
            uv = detect(cid, frame)
            made = tracker.update_spots(cid, t, uv)
            if hub is not None:  # its spots shown with the frame
                hub.frame(cid, t + utc, uv, frame if isinstance(frame, bytes) else None)
                if n % 30 == 0:
                    _camera_facts(hub, frames)
            made = _published(publisher, made, utc)
            put(made)
            rows += made
            n += 1
            check(tracker)
            layouts()
            if fps is None and n % 100 == 0:  # the cameras' own rate, once it shows
                tracker.period = frames.period()
    except KeyboardInterrupt:
        say("stopped (Ctrl-C or a signal): writing what was tracked")
    finally:
        frames.stop()
        made = _published(publisher, tracker.finish(), utc)
        put(made)
        rows += made
        live.close()
        if hub is not None:
            _camera_facts(hub, frames)
    st = frames.stats
    if not n:
        live.remove()
        why = "; ".join(f"{c}: {st.ended.get(c, 'no frames')}" for c in sources)
        raise click.ClickException(  # (exit 1, as locate's: the cameras, not the input)
            f"no frames from any camera, nothing tracked ({why})")
    for cid in sources:
        say(f"camera {cid}: {st.frames[cid]} frames"
            + (f", {frames.stamped[cid]} with X-Timestamp (host − its clock: "
               f"{frames.clocks[cid].offset(frames.last_stamp[cid]):+.4f} s"
               + (f"; {frames.clocks[cid].ignored} stamps that jumped not believed"
                  if frames.clocks[cid].ignored else "")
               + (f"; its clock started again {frames.clocks[cid].restarts}×"
                  if frames.clocks[cid].restarts else "") + ")"
               if frames.stamped[cid] else ", no X-Timestamp (arrival times used)")
            + (f"; {st.dropped[cid]} dropped" if st.dropped[cid] else "")
            + (f"; stopped: {st.ended[cid]}" if cid in st.ended else ""))
    bad = "; ".join(f"{k} frames {_UNREADABLE.get(w, w)}" for w, k in unreadable.items())
    say(f"{n} camera frames → {_summary(rows)}" + (f" → {out}" if out is not None else "")
        + _lag_said(tracker) + (f"; {bad} (not used)" if bad else ""))
    _said_latencies(tracker)
    layouts(end=True)
    if not rows and out is not None:
        live.remove()
        raise _no_rows(tracker, "the cameras", unreadable)
    return rows


def _camera_facts(hub, frames) -> None:
    """Each camera's clock offset, frames the command dropped and why it stopped, to the
    page."""
    st = frames.stats
    for cid in frames.sources:
        offset = frames.clocks[cid].offset(frames.last_stamp[cid]) \
            if frames.stamped[cid] else None
        hub.camera_status(cid, clock_offset=offset, dropped=st.dropped[cid],
                          stopped=st.ended.get(cid))


def _track_spots(dep, deployment_path, target, ca_file, duration, lag, spots, out, fps, quiet,
                 publisher, check, hub=None) -> list:
    """``vlpcal track --spots mqtt://…``: the spots cameras publish, each at its capture time
    (UTC s), fed to the tracker as they come; rows in UTC seconds. Each camera's message of a
    frame without a spot (``{"t": …}``) tells the tracker that camera saw nothing then. A spot
    captured later than now by more than a track survives without spots is no camera's of now
    (its clock is wrong) and is counted, not used."""
    import time

    from ..live import FrameIntervals
    from ..mqtt import MqttError, SpotSubscriber
    from ..tracking import Tracker

    if out is not None:
        out = _output_file(out, inputs=(deployment_path,) + ((ca_file,) if ca_file else ()),
                           what="the tracks")

    def say(msg):
        if not quiet:
            echo(msg, err=True)

    # refused at once if the file is there; no file: the view alone
    live = _LiveTracks(out, 0.0, bool(dep.bodies)) if out is not None else _NoTracks()
    try:
        sub = SpotSubscriber(target, [c.id for c in dep.cameras], ca_file,
                             sizes={c.id: (c.width, c.height) for c in dep.cameras})
    except MqttError as e:
        live.close()
        live.remove()
        raise UserError(f"--spots {e}") from None
    say(f"listening for spots on {target.shown()}/spots/+")
    tracker = Tracker(dep, period=1.0 / (fps or 30.0), spots=spots, lag=lag)
    layouts = _Layouts(tracker)
    t_end = time.monotonic() + duration if duration else None
    rows: list = []
    n, future, crowded = 0, 0, 0
    intervals = FrameIntervals()  # the cameras' own rate, when --fps does not say it
    try:
        while not (t_end and time.monotonic() > t_end):
            if (quiet_note := sub.silence()) is not None:  # a warning: -q hides none
                echo(quiet_note, err=True)
            got = sub.get(timeout=0.2)
            if got is None:
                continue
            t, cid, uv = got
            if t > time.time() + tracker.lost_after:
                future += 1
                continue
            crowded += len(uv) > tracker.spots
            made = _published(publisher, tracker.update_spots(cid, t, uv))
            live.write(made)
            if hub is not None:
                hub.frame(cid, t, uv)
                hub.track_rows(made)
            rows += made
            n += 1
            check(tracker)
            layouts()
            intervals.add(cid, t)
            if fps is None and n % 50 == 0:  # the slowest camera's, once it shows
                tracker.period = min(intervals.period(tracker.period), 10.0)
    except KeyboardInterrupt:
        say("stopped (Ctrl-C or a signal): writing what was tracked")
    finally:
        sub.close()
        made = _published(publisher, tracker.finish())
        live.write(made)
        if hub is not None:
            hub.track_rows(made)
        rows += made
        live.close()
    if not n:
        live.remove()
        raise UserError(f"no spots on {target.shown()}/spots/+ from any camera of "
                        f"{deployment_path}, nothing tracked")
    said = [f"{n} spot messages tracked"]
    if crowded:
        said.append(f"{crowded} held more spots than --leds {tracker.spots} (the first used)")
    if future:
        said.append(f"{future} captured in the future by their cameras' clocks (skipped)")
    if tracker.late:
        said.append(f"{tracker.late} came after their rows were written (skipped)")
    said += subscriber_notes(sub, "tracker", "tracked")
    if sub.disconnects:
        said.append(f"the broker went away {sub.disconnects} time(s)")
    say("; ".join(said) + f" → {_summary(rows)} → {out}" + _lag_said(tracker))
    _said_latencies(tracker)
    layouts(end=True)
    if not rows:
        live.remove()
        raise _no_rows(tracker, f"{target.shown()}/spots/+", what="spot message")
    return rows


class _NoTracks:
    """No tracks file (``vlpcal view --spots``: the page alone)."""

    def write(self, rows) -> None:
        pass

    close = remove = lambda self: None


class _LiveTracks:
    """A live run's tracks file: new, its header at once, each row flushed as it is made
    (:func:`vlpcal.locator.open_live`)."""

    def __init__(self, out, utc: float, pose_columns: bool = False):
        import csv

        from ..locator import open_live
        from ..writing import OutputError

        self.path, self.utc, self.pose_columns = out, utc, pose_columns
        try:
            self.f = open_live(out)
        except OutputError as e:
            raise UserError(str(e)) from None
        self.w = csv.writer(self.f)
        self.failed, self._whole = False, 0
        try:
            self._put([_columns(pose_columns)])
        except UserError:  # not even the header: no file of ours is left
            self.close()
            self.remove()
            raise

    def write(self, rows) -> None:
        self._put(_utc_row(r, self.utc, self.pose_columns) for r in rows)

    def _put(self, lines) -> None:
        """CSV lines, flushed; a disk that fails (full, gone) is one line naming the file, the
        rows written before it kept whole (a row cut short is cut off)."""
        import os

        if self.failed:
            return
        try:
            self.w.writerows(lines)
            self.f.flush()
            self._whole = self.f.tell()
        except OSError as e:
            self.failed = True
            try:
                os.truncate(self.path, self._whole)
            except OSError:
                pass
            raise UserError(f"{self.path}: could not write the tracks ({e.strerror or e}); "
                            "the rows written before are kept") from None

    def close(self) -> None:
        import os

        try:
            self.f.close()
        except OSError:  # what it held is written already (or the disk failed: said)
            pass
        if self.failed:  # closing tried the unwritten rest again: whole rows only
            try:
                os.truncate(self.path, self._whole)
            except OSError:
                pass

    def remove(self) -> None:
        import os

        try:
            os.unlink(self.path)
        except OSError:
            pass
