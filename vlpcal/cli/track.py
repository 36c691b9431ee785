"""The robot integrator's command: an LED's track from cameras that are not synchronised
(``vlpcal track``)."""

from __future__ import annotations

import sys
from pathlib import Path

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
from .mqtt import mqtt_options, open_publisher, parse_mqtt, publisher_summary
from .track_live import _track_live, _track_spots
from .track_rows import (
    UNREADABLE,
    Layouts,
    lag_said,
    no_rows,
    published_rows,
    run_summary,
    say_latencies,
    wandering_said,
    write_tracks,
)
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


def _track(dep, deployment_path, frames_dir, duration, lag, spots, out, fps, quiet,
           publisher, check, plot=None) -> list:

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
    check.also = lambda watch: drifted or wandering_said(watch)  # (said with the fit
    # watch's verdict, which names a wrong deployment first: a clock's drift looks alike)
    for t, cid, uv in tracker.in_order(spotted):
        rows.extend(published_rows(publisher, tracker.update_spots(cid, t, uv)))
        check(tracker)  # (a deployment that does not fit is said first: its skews wander too)
    if drifts and not check.said:  # times that place no frame right
        if not check.keep_going:
            raise UserError(f"{drifted} (nothing was written)")
        echo(f"warning: {drifted} (going on: --keep-going)", err=True)
    rows += published_rows(publisher, tracker.finish())
    if tracker.latencies() and publisher is None:  # rows from the first frame at the
        tracker, rows = tracked_again(tracker, spotted, check)  # times the run found
    say_latencies(tracker)
    Layouts(tracker)(end=True)
    wrong = {m.body for m in tracker.layout_misfits()}
    if wrong:  # its rows before the verdict were skewed by the layout too: none written
        kept = [r for r in rows if not (r.pose is not None and r.led in wrong)]
        if len(kept) < len(rows):
            echo(f"warning: {len(rows) - len(kept)} rows of {', '.join(sorted(wrong))} "
                 "given before its layout was judged are left out of the file", err=True)
        rows = kept
    if not rows:
        raise no_rows(tracker, frames_dir, unreadable)
    write_tracks(out, rows, pose_columns=bool(tracker.bodies),
                  figure=(plot, dep, f"{dep.name}: vlpcal track → {out}") if plot else None)
    if not quiet:
        bad = "; ".join(f"{n} frames {UNREADABLE.get(w, w)}" for w, n in unreadable.items())
        echo(f"{len(folder.events)} camera frames ({fps:g} fps) → {run_summary(rows)} → {out}"
             + lag_said(tracker)
             + (f"; {missing} listed frames missing" if missing else "")
             + (f"; {bad} (not used)" if bad else ""), err=True)
    return rows
