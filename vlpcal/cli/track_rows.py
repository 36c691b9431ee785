"""What `vlpcal track` says and writes, whatever its source: the tracks file, a run's
summary, why it gave no rows, its cameras' capture times, a body's layout."""

from __future__ import annotations

import csv
import re

from ..writing import OutputSet
from .common import UserError, echo


class Layouts:
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
UNREADABLE = {"wrong_size": "of another size than their camera's", "corrupt_frame": "not whole "
               "JPEGs"}


def no_rows(tracker, source, unreadable=None, what: str = "frame") -> UserError:
    """Why a run gave no row at all (``unreadable``: frames not measured, by reason;
    ``what`` a frame is: a camera frame, or a spot message)."""
    fit = tracker.fit
    if unreadable and not tracker.frames_with_spot:
        why = "; ".join(f"{n} frames {UNREADABLE.get(w, w)}" for w, n in unreadable.items()) \
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


def published_rows(publisher, rows, utc: float = 0.0):
    """``rows`` (track updates) published as they are made, when --publish asks; returned."""
    if publisher:
        from ..mqtt import track_message

        for r in rows:
            publisher.publish(r.led, track_message(r.t + utc, r),
                              "bodies" if r.pose is not None else "fixes")
    return rows


def say_latencies(tracker) -> None:
    """Cameras whose capture times the run found to run late or early, said (a warning: a
    camera's clock or link to see to)."""
    for cid, late in sorted(tracker.latencies().items()):
        if abs(late) < 0.1 * tracker.period:  # (within a tenth of a frame: nothing to see to)
            continue
        echo(f"warning: camera {cid}'s capture times are {abs(late):.3f} s "
             f"{'late' if late > 0 else 'early'} against the others' (seen in the LED's "
             f"motion): its frames were placed {abs(late):.3f} s "
             f"{'earlier' if late > 0 else 'later'} than their times say", err=True)
    wander = wandering_said(tracker)
    if wander:
        echo(f"warning: {wander}; their rows' sigma_m hold it", err=True)


def wandering_said(tracker) -> str:
    """The cameras whose latency wanders along the run, said ("" if none): a possible cause
    of a misfit, and a warning after a run."""
    spread = sorted(tracker.wandering().items())
    if not spread:
        return ""
    return (f"camera{'s' * (len(spread) > 1)} {', '.join(c for c, _ in spread)}: capture "
            f"times wander by {', '.join(f'±{s:.3f}' for _, s in spread)} s (1 sigma) "
            "against the others' along the LED's motion (a clock running fast or slow? "
            "frames stamped late under load?)")


def write_tracks(out, rows, utc: float = 0.0, pose_columns: bool = False,
                  figure=None) -> None:
    """The tracks file, staged and renamed (``utc``: added to each row's time;
    ``pose_columns``: the bodies' columns too; ``figure``: (png, deployment, title), drawn
    and renamed with the tracks as one set: a stop while drawing replaces neither)."""

    with OutputSet(*([figure[0]] if figure else []), out) as staged:
        tmp = staged[-1]
        if figure:
            from ..reports import track_figure

            track_figure(staged[0], figure[1], rows, figure[2])
        with open(tmp, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(track_columns(pose_columns))
            w.writerows(utc_row(r, utc, pose_columns) for r in rows)


def track_columns(pose_columns: bool) -> tuple:
    from ..tracking import BODY_COLUMNS, TRACK_COLUMNS

    return TRACK_COLUMNS + (BODY_COLUMNS if pose_columns else ())


def utc_row(update, utc: float, pose_columns: bool = False) -> list:
    """A track update's CSV row, its time moved by ``utc`` s (live: the host's monotonic clock
    to UTC)."""
    row = update.row(pose_columns)
    if utc:
        row[0] = f"{update.t + utc:.6f}"
    return row


def lag_said(tracker) -> str:
    """What the summary says of a --lag past half the fit's window (the most a row can wait)."""
    if tracker.lag is None or tracker.lag <= tracker.half:
        return ""
    return (f"; --lag {tracker.lag:g} s is past half the fit's window: rows were written "
            f"{tracker.half:.3g} s after their frames")


def run_summary(rows) -> str:
    ok = sum(r.status == "ok" for r in rows)
    leds = sorted({r.led for r in rows if r.pose is None},  # T2 before T10
                  key=lambda led: [int(p) if p.isdigit() else p for p in re.split(r"(\d+)", led)])
    bodies = sorted({r.led for r in rows if r.pose is not None})
    shown = ", ".join(leds[:12]) + (f" and {len(leds) - 12} more" if len(leds) > 12 else "")
    return (f"{len(rows)} rows, {ok} placed by two cameras or more, tracks {shown or '–'}"
            + (f", bodies {', '.join(bodies)}" if bodies else ""))
