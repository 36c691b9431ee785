"""The integrator's command: frames, spots or live cameras to 3D fixes (``vlpcal locate``)."""

from __future__ import annotations

from collections import Counter

import click

from .common import (
    Finite,
    FitCheck,
    Misfit,
    UserError,
    _camera_sources,
    _load_deployment,
    _output_file,
    _same_file,
    dataset_error,
    echo,
    main,
)
from .mqtt import (
    PublishingWriter,
    ZoneWriter,
    led_of,
    mqtt_options,
    open_publisher,
    parse_mqtt,
    publisher_summary,
    subscriber_notes,
)


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
@click.option("--spots", "spots_url", default=None, metavar="mqtt://…/PREFIX",
              help="Live spots the cameras publish on PREFIX/spots/<camera_id> "
                   "({\"t\": UTC s, \"u\": px, \"v\": px}).")
@click.option("--zone", default=None, metavar="ID",
              help="One zone of the deployment's zones: block: its cameras only, and only the "
                   "fixes inside its polygon (one locator process per zone).")
@click.option("--keep-going", is_flag=True,
              help="Go on when the frames do not fit the deployment (most sets two cameras "
                   "see the LED not placed: another install's deployment, cameras swapped, a "
                   "stale calibration); said once as a warning.  [default: stop, exit 2]")
@mqtt_options
@click.option("--out", "-o", default="-", show_default=True,
              help="Fixes file (.csv or .jsonl), or - for stdout.")
@click.option("--format", "fmt", type=click.Choice(["csv", "jsonl"]), default=None,
              help="Output format (default: from --out's extension; csv for stdout).")
@click.option("--batch", default=512, show_default=True, type=click.IntRange(1),
              help="Frame sets located together (folders).")
@click.option("--tolerance", default=0.05, show_default=True, type=Finite(0.001, 10.0),
              help="Live: frames arriving within this many seconds form one set.")
@click.option("--duration", type=Finite(0, 1e7, min_open=True), default=None,
              help="Live: stop after this many seconds (more than 0; none: until stopped).")
@click.option("--max-sets", type=click.IntRange(1), default=None,
              help="Live: stop after this many frame sets.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar or summary.")
@click.option("--plot", default=None, type=click.Path(dir_okay=False), metavar="PNG",
              help="Also draw the run: the fixes on the plan and their sigma_m (a PNG, "
                   "written when the fixes are).")
def locate(deployment_path, frames_dir, observations, cameras, spots_url, zone, keep_going,
           publish, qos, ca_file, out, fmt, batch, tolerance, duration, max_sets, quiet, plot):
    """Turn camera frames into 3D fixes (metres, world frame, z up).

    One row per frame set: frame_id,x,y,z,status first (the contract), then the cameras used,
    the predicted RMS error sigma_m, the worst reprojection residual and each camera's status.
    A frame set without a fix keeps its row with empty x, y, z and a status saying why.

    Example: vlpcal locate -d deployment.yaml --frames frames/ --out fixes.csv
    """
    import sys
    import time

    from ..locator import FixWriter, Locator

    sources = [name for name, given in (("--frames", frames_dir),
                                         ("--observations", observations),
                                         ("--camera", cameras), ("--spots", spots_url)) if given]
    if len(sources) != 1:
        raise click.UsageError("give exactly one input: --frames DIR, --observations CSV, "
                               "--camera ID=SOURCE … or --spots mqtt://…")
    dep = _load_deployment(deployment_path)
    if zone is not None:
        if zone not in dep.zones:
            raise click.BadParameter(f"{deployment_path} has no zone {zone!r} (its zones: "
                                     f"{', '.join(dep.zones) or 'none: add a zones: block'})",
                                     param_hint="--zone")
        site_led, dep = led_of(dep), dep.zone(zone)
    loc = Locator(dep)
    spots_target = parse_mqtt(spots_url, "--spots") if spots_url else None
    if out != "-":  # never over the deployment or the frames it reads
        out = str(_output_file(out, inputs=[p for p in (deployment_path, frames_dir,
                                                         observations, ca_file) if p],
                               what="the fixes"))
    if plot is not None:
        if not str(plot).lower().endswith(".png"):
            raise UserError(f"--plot {plot}: the figure is a PNG picture (.png)")
        plot = _output_file(plot, inputs=[p for p in (deployment_path, frames_dir,
                                                      observations, ca_file) if p],
                            what="the figure")
        if out != "-" and _same_file(plot, out):
            raise UserError(f"--plot {plot}: the same file as --out")
    say = (lambda msg: None) if quiet else (lambda msg: echo(msg, err=True))
    live = bool(cameras) or bool(spots_url)
    publisher = open_publisher(publish, qos, ca_file, loc.deployment, deployment_path, zone)
    from ..writing import OutputError

    t0 = time.perf_counter()
    sent = live or out == "-" or publisher  # what a stop cannot take back
    statuses = _Tally(loc.deployment.name, FitCheck(
        keep_going, "the fixes so far are kept" if sent else "nothing was written"))
    notes = []
    try:
        writer = FixWriter(out, fmt, extra_columns=("t_s",) if live else (), live=live)
    except (OSError, OutputError) as e:
        if publisher:
            publisher.close()
        raise UserError(str(e) if isinstance(e, OutputError) else
                        f"{out}: cannot write the fixes there ({e.strerror})") from None
    try:  # (a stop while the writer is wrapped leaves no staged file either)
        if plot is not None:
            writer = _PlottingWriter(writer, plot, dep, led_of(dep), live, say)
        if publisher:
            writer = PublishingWriter(writer, publisher, site_led if zone else led_of(dep),
                                      utc="t_s" if live else None)
        if zone is not None:  # written and published: the fixes inside the zone's polygon
            writer = ZoneWriter(writer, _load_deployment(deployment_path).zones, zone)
    except BaseException:
        writer.abort()
        raise
    # from here on every way out either closes the writer (the fixes so far are kept) or
    # aborts it (nothing replaced)
    try:
        if frames_dir:
            n = _locate_folder(loc, frames_dir, writer, batch, statuses, notes, quiet)
        elif observations:
            n = _locate_observations(loc, observations, writer, statuses, notes)
        elif spots_target:
            n = _locate_spots(loc, spots_target, ca_file, writer, tolerance, duration, max_sets,
                              statuses, notes, say)
        else:
            n = _locate_live(loc, cameras, writer, tolerance, duration, max_sets, statuses,
                             notes, say)
    except KeyboardInterrupt:
        if not sent:  # an offline run into a file: the previous file stays, as it was
            writer.abort()
            echo(f"interrupted (Ctrl-C or a signal): nothing was written; {out} is as "
                 "it was", err=True)
            raise SystemExit(1) from None
        notes.append("interrupted: the fixes so far are kept")
        n = sum(statuses.values())
    except Misfit:  # stopped: an offline run writes nothing, a live one keeps its rows
        if live:
            writer.close()
        else:
            writer.abort()
        raise
    except BrokenPipeError:  # the reader of stdout has what it wanted (| head): stop quietly
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return
    except OSError as e:  # the output's disk is full or went away
        writer.abort()
        raise UserError(f"{out}: could not write the fixes ({e.strerror}); nothing was "
                        "replaced") from None
    except BaseException:
        writer.abort()
        raise
    finally:
        if publisher:
            publisher.close()
            notes.append(publisher_summary(publisher))
        if zone is not None and writer.outside:
            notes.append(f"zone {zone}: {writer.outside} fixes outside its polygon left to the "
                         "zones around it")
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


class _PlottingWriter:
    """The fixes written, kept as numbers, and drawn (:func:`~vlpcal.reports.run_figure`)
    into ``plot`` when the fixes are closed; an aborted run draws nothing."""

    def __init__(self, writer, plot, dep, led: str, live: bool, say):
        self.writer, self.plot, self.dep, self.led, self.live, self.say = (writer, plot, dep,
                                                                           led, live, say)
        self.parts: list = []  # per batch: (t, X, sigma, status)

    def write(self, fixes, extra: dict | None = None) -> None:
        import numpy as np

        fixes = list(fixes)
        self.writer.write(fixes, extra)
        n = sum(len(p[0]) for p in self.parts)
        t = np.full(len(fixes), float(extra["t_s"])) if extra and "t_s" in extra \
            else np.arange(n, n + len(fixes), dtype=float)
        self.parts.append((t, np.array([(f.x, f.y, f.z) for f in fixes], float).reshape(-1, 3),
                           np.array([f.sigma for f in fixes], float),
                           np.array([f.status for f in fixes], dtype=object)))

    def close(self) -> None:
        import numpy as np

        from ..reports import run_figure
        from ..writing import OutputSet

        if not self.parts:
            self.writer.close()
            return
        # drawn first, then renamed with the fixes as one set: a stop while drawing (or
        # before the renames) leaves the previous fixes and figure as they were
        t, X, sigma, status = (np.concatenate(k) for k in zip(*self.parts))
        figure = OutputSet(self.plot)
        (png,) = figure.stage()
        try:
            run_figure(png, self.dep, t - t.min() if self.live else t, [self.led] * len(t), X,
                       sigma, status, None, f"{self.dep.name}: vlpcal locate",
                       "time from the first fix (s)" if self.live else "frame set (in order)")
        except BaseException:
            figure.discard()
            self.writer.abort()
            raise
        fixes = getattr(self.writer, "_set", None)  # staged fixes (a live run's are written)
        if fixes is not None:
            fixes.join(figure)
        self.writer.close()
        if fixes is None:
            figure.commit()
        self.say(f"figure → {self.plot}")

    def abort(self) -> None:
        self.writer.abort()


class _Tally(Counter):
    """The fix statuses counted (:meth:`add`), and whether the frames fit the deployment
    judged as they come (:class:`~vlpcal.fit_watch.FitWatch`, by ``check``)."""

    def __init__(self, deployment: str, check: FitCheck):
        from ..fit_watch import FitWatch

        super().__init__()
        self.watch = FitWatch(deployment, "sets two cameras or more saw")
        self.check = check

    def add(self, fixes) -> None:
        """A batch of fixes (:class:`~vlpcal.locator.FixBatch`): counted and judged."""
        self.update(fixes.counts())
        if not self.check.said:
            self.watch.add_statuses(fixes.status.tolist(),
                                    (fixes.camera_status == "dropped").any(axis=0).tolist())
            self.check(self.watch)


def _check_the_deployment_fits(loc, source, camera_ids, notes, folder=None) -> None:
    """The likely mistake of a wrong deployment for the frames (or spots), caught before
    any work: refused (exit 2) when most of its cameras have nothing here, or when most
    cameras' frames are not the size the deployment says; a note when a few are absent."""
    from ..detection import spread, usual_size

    dep, ids = loc.deployment, loc.camera_ids
    present = [c for c in ids if c in camera_ids]
    absent = [c for c in ids if c not in camera_ids]
    hint = "is this the right deployment for them?"
    if folder is not None and (folder.root / "times.csv").is_file():  # a robot's streams
        hint = ("it holds times.csv and <camera_id>/<frame_no>.jpg: an asynchronous folder, "
                "which vlpcal track --frames follows")
    if len(present) < 2 or len(absent) > len(ids) / 2:
        other = [c for c in camera_ids if c not in ids]
        others = ", ".join(other[:8]) + (f" and {len(other) - 8} more" if len(other) > 8
                                          else "") or "none"
        raise UserError(f"{source}: has {'frames' if folder else 'spots'} of only "
                        f"{len(present)} of {dep.name}'s {len(ids)} cameras "
                        f"({', '.join(present) or 'none'}; other ids there: {others}): {hint}")
    if absent:
        notes.append(f"{source}: nothing at all from camera(s) {', '.join(absent)} of "
                     f"{dep.name}: {hint}")
    if folder is None:
        return
    wrong = []
    for cid in present:  # the size most of a spread of its frames' headers say
        fids = [f for f in folder.frame_ids if (f, cid) in folder.files]
        size = usual_size(folder.frame(f, cid) for f in spread(fids))
        cam = dep.camera(cid)
        if size is not None and size != (cam.height, cam.width):
            wrong.append(f"{cid} {size[1]}×{size[0]} (the deployment says "
                         f"{cam.width}×{cam.height})")
    if len(wrong) > len(present) / 2:
        raise UserError(f"{source}: frames of another size than {dep.name}'s cameras: "
                        f"{'; '.join(wrong)}: {hint}")


def _locate_folder(loc, frames_dir, writer, batch, statuses, notes, quiet) -> int:
    import sys

    from ..datasets import DatasetError, read_frames_folder

    try:
        folder = read_frames_folder(frames_dir)
    except DatasetError as e:
        raise dataset_error(e) from None
    _check_the_deployment_fits(loc, frames_dir, folder.camera_ids, notes, folder)
    unknown = sorted(set(folder.camera_ids) - set(loc.camera_ids))
    if unknown:
        files = sum(1 for (_, c) in folder.files if c in unknown)
        notes.append(f"ignored {files} frames of camera(s) {', '.join(unknown)} that "
                     f"{loc.deployment.name} does not have")
    ids = folder.frame_ids
    # progress to stderr (stdout may be the fixes), and only where a person watches
    with click.progressbar(length=len(ids), label="locating", file=sys.stderr,
                           hidden=quiet, show_pos=True) as bar:
        for s in range(0, len(ids), batch):
            chunk = ids[s:s + batch]
            # unreadable: b"", a corrupt frame
            sets = [{cid: folder.frame(fid, cid) for cid in loc.camera_ids
                     if (fid, cid) in folder.files} for fid in chunk]
            fixes = loc.locate_batch(sets, chunk)
            statuses.add(fixes)
            writer.write(fixes)
            bar.update(len(chunk))
    return len(ids)


#: frame sets located at once from an observations file: the spots array and the fusion's
#: work stay this many sets wide, however long the file
OBSERVATION_CHUNK = 20_000


def _locate_observations(loc, path, writer, statuses, notes) -> int:
    import numpy as np

    from ..datasets import DatasetError, read_observations

    try:
        obs, ids = read_observations(path, "frame_id")
    except DatasetError as e:
        raise UserError(str(e)) from None
    index = {c: k for k, c in enumerate(loc.camera_ids)}
    frame_index = {f: n for n, f in enumerate(ids)}
    cams = sorted({c for (_, c) in obs})
    _check_the_deployment_fits(loc, path, cams, notes)
    unknown = [c for c in cams if c not in index]
    if unknown:
        notes.append(f"ignored spots of camera(s) {', '.join(unknown)} that "
                     f"{loc.deployment.name} does not have")
    # the spots as flat arrays in frame order, each chunk of frames filled from its slice
    n = len(obs)
    frame = np.fromiter((frame_index[f] for f, _ in obs), np.intp, n)
    camera = np.fromiter((index.get(c, -1) for _, c in obs), np.intp, n)
    spot = np.fromiter((x for p in obs.values() for x in p), float, 2 * n).reshape(n, 2)
    del obs, frame_index
    order = np.argsort(frame, kind="stable")
    order = order[camera[order] >= 0]  # a camera the deployment lacks: its spots ignored
    frame, camera, spot = frame[order], camera[order], spot[order]
    for s in range(0, len(ids), OBSERVATION_CHUNK):
        e = min(s + OBSERVATION_CHUNK, len(ids))
        lo, hi = np.searchsorted(frame, (s, e))
        uv = np.full((len(index), e - s, 2), np.nan)
        uv[camera[lo:hi], frame[lo:hi] - s] = spot[lo:hi]
        fixes = loc.locate_pixels(uv, frame_ids=ids[s:e])
        statuses.add(fixes)
        writer.write(fixes)
    return len(ids)


def _locate_live(loc, cameras, writer, tolerance, duration, max_sets, statuses, notes,
                 say) -> int:
    import time

    from ..live import LiveGrouper

    sources = _camera_sources(cameras, loc.deployment)
    t_end = time.monotonic() + duration if duration else None
    grouper = LiveGrouper(sources, tolerance, on_event=say, deadline=t_end)
    utc = time.time() - time.monotonic()  # a set's time, UTC s: when its first frame came
    n = 0
    try:
        for fs in grouper:
            fixes = loc.locate_batch([fs.frames], [f"{fs.index:06d}"])
            statuses.add(fixes)
            writer.write(fixes, {"t_s": round(grouper.t0 + fs.t + utc, 3)})
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


def _locate_spots(loc, target, ca_file, writer, tolerance, duration, max_sets, statuses, notes,
                  say) -> int:
    """``--spots mqtt://…``: the spots cameras publish, grouped by their capture times (those
    within ``tolerance`` s of a set's first form the set; a set is complete when every camera,
    or every camera that saw the LED in the set before, has sent) and located as they come."""
    import time

    import numpy as np

    from ..mqtt import MqttError, SpotSubscriber

    try:
        sub = SpotSubscriber(target, loc.camera_ids, ca_file,
                             sizes={c.id: (c.width, c.height) for c in loc.deployment.cameras})
    except MqttError as e:
        raise UserError(f"--spots {e}") from None
    say(f"listening for spots on {target.shown()}/spots/+")
    index = {c: k for k, c in enumerate(loc.camera_ids)}
    t_end = time.monotonic() + duration if duration else None
    pending: dict = {}
    first = None
    n = 0
    seeing: set = set()  # the cameras that saw the LED in the last set
    times: dict = {}  # camera id → its spots' capture time, in the set being gathered

    def close():
        nonlocal pending, first, n, seeing
        seeing = {cid for cid, spots in pending.items() if spots} or seeing
        uv = np.full((len(index), 1, 2), np.nan)
        for cid, spots in pending.items():
            if spots:
                uv[index[cid], 0] = spots[0]
        fixes = loc.locate_pixels(uv, frame_ids=[f"{n:06d}"])
        statuses.add(fixes)
        # the set's time: its spots' mean capture time, where a fix of spots taken at
        # different moments stands (a camera that saw nothing tells no time)
        seen_at = [times[c] for c, spots in pending.items() if spots]
        when = sum(seen_at) / len(seen_at) if seen_at else first
        writer.write(fixes, {"t_s": round(when, 6)})
        n += 1
        pending, first = {}, None
        times.clear()

    try:
        while not (t_end and time.monotonic() > t_end) and not (max_sets and n >= max_sets):
            if (quiet_note := sub.silence()) is not None:  # a warning: -q hides none
                echo(quiet_note, err=True)
            got = sub.get(timeout=tolerance)
            if got is None:
                if pending and time.time() - first > 2 * tolerance:
                    close()
                continue
            t, cid, spots = got
            if pending and (cid in pending or abs(t - first) > tolerance):
                close()
            if first is None:
                first = t
            pending[cid] = spots
            times[cid] = t
            # complete when every camera has sent, or every camera that saw the LED last time
            # has (the others' frames say nothing of it: waiting for them is only latency)
            if len(pending) == len(index) or (seeing and seeing <= pending.keys()
                                              and any(pending.values())):
                close()
        if pending:
            close()
    finally:
        sub.close()
    notes.append(", ".join([f"spots: {sub.received} messages",
                            *subscriber_notes(sub, "locator", "located")])
                 + (f"; the broker went away {sub.disconnects} time(s)" if sub.disconnects
                    else ""))
    return n
