"""`vlpcal track` live: cameras' MJPEG streams (or devices), or the spots cameras publish
over MQTT, tracked as they come."""

from __future__ import annotations

import csv
import os
import time
from collections import Counter

import click

from ..writing import OutputError
from .common import UserError, _camera_sources, _output_file, echo
from .mqtt import subscriber_notes
from .track_rows import (
    UNREADABLE,
    Layouts,
    lag_said,
    no_rows,
    published_rows,
    run_summary,
    say_latencies,
    track_columns,
    utc_row,
)


def _track_live(dep, deployment_path, cameras, duration, lag, spots, out, fps, quiet,
                publisher, check, hub=None) -> list:
    """``vlpcal track --camera …``: frames as they come, each at its capture time on the
    host's clock (X-Timestamp through each camera's clock estimate, else arrival), fed to
    the tracker in that order; rows in UTC seconds. ``out`` None: no file (the view alone);
    ``hub``: the live page's (:class:`~vlpcal.view.ViewHub`), given each frame, its spots
    and the rows."""
    from ..live import TimedFrames
    from ..tracking import Tracker

    sources = _camera_sources(cameras, dep, stamps=True)
    if out is not None:
        out = _output_file(out, inputs=(deployment_path,), what="the tracks")

    def say(msg):
        if not quiet:
            echo(msg, err=True)

    t_end = time.monotonic() + duration if duration else None
    frames = TimedFrames(sources, deadline=t_end, on_event=say)
    tracker = Tracker(dep, period=1.0 / (fps or 30.0), spots=spots, lag=lag)
    layouts = Layouts(tracker)
    utc = time.time() - time.monotonic()  # the host's monotonic clock → UTC seconds
    # row by row, flushed: a reader follows
    live = _LiveTracks(out, utc, bool(dep.bodies)) if out is not None else _NoTracks()
    rows: list = []
    n = 0

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
            made = published_rows(publisher, made, utc)
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
        made = published_rows(publisher, tracker.finish(), utc)
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
    bad = "; ".join(f"{k} frames {UNREADABLE.get(w, w)}" for w, k in unreadable.items())
    say(f"{n} camera frames → {run_summary(rows)}" + (f" → {out}" if out is not None else "")
        + lag_said(tracker) + (f"; {bad} (not used)" if bad else ""))
    say_latencies(tracker)
    layouts(end=True)
    if not rows and out is not None:
        live.remove()
        raise no_rows(tracker, "the cameras", unreadable)
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
    layouts = Layouts(tracker)
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
            made = published_rows(publisher, tracker.update_spots(cid, t, uv))
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
        made = published_rows(publisher, tracker.finish())
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
        late = ", ".join(f"{c} {n}" for c, n in tracker.late_by_camera().items())
        said.append(f"{tracker.late} came after their rows were written (skipped: {late})")
    said += subscriber_notes(sub, "tracker", "tracked")
    if sub.disconnects:
        said.append(f"the broker went away {sub.disconnects} time(s)")
    say("; ".join(said) + f" → {run_summary(rows)} → {out}" + lag_said(tracker))
    say_latencies(tracker)
    layouts(end=True)
    if not rows:
        live.remove()
        raise no_rows(tracker, f"{target.shown()}/spots/+", what="spot message")
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
        from ..locator import open_live

        self.path, self.utc, self.pose_columns = out, utc, pose_columns
        try:
            self.f = open_live(out)
        except OutputError as e:
            raise UserError(str(e)) from None
        self.w = csv.writer(self.f)
        self.failed, self._whole = False, 0
        try:
            self._put([track_columns(pose_columns)])
        except UserError:  # not even the header: no file of ours is left
            self.close()
            self.remove()
            raise

    def write(self, rows) -> None:
        self._put(utc_row(r, self.utc, self.pose_columns) for r in rows)

    def _put(self, lines) -> None:
        """CSV lines, flushed; a disk that fails (full, gone) is one line naming the file, the
        rows written before it kept whole (a row cut short is cut off)."""
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
        try:
            os.unlink(self.path)
        except OSError:
            pass
