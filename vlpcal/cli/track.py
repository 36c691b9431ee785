"""The robot integrator's command: an LED's track from cameras that are not synchronised
(``vlpcal track``, issue 16)."""

from __future__ import annotations

import click

from .common import Finite, UserError, _load_deployment, _output_file, main


@main.command()
@click.option("--deployment", "-d", "deployment_path", required=True,
              type=click.Path(dir_okay=False), help="Deployment YAML (docs/formats.md).")
@click.option("--frames", "frames_dir", required=True, type=click.Path(file_okay=False),
              help="Asynchronous frames: <camera_id>/<frame_no>.jpg and times.csv "
                   "(camera_id,frame_no,t: capture time, s, on one clock).")
@click.option("--out", "-o", required=True, type=click.Path(dir_okay=False),
              help="Tracks file to write (.csv).")
@click.option("--fps", default=None, type=Finite(0.1, 10000.0),
              help="The cameras' frame rate.  [default: from times.csv, the slowest camera's]")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar or summary.")
def track(deployment_path, frames_dir, out, fps, quiet):
    """Track a moving LED from cameras that are not synchronised.

    Each camera frame is a ray at its own capture time; the LED's path over a short window is
    fitted to every ray in it, so no two views need to be simultaneous. One row per camera
    frame that saw the LED: t,led,x,y,z,vx,vy,vz,sigma_m,cameras,status (m, m/s; status ok
    where two cameras or more placed it, one_camera where its motion carried it).

    Example: vlpcal track -d deployment.yaml --frames streams/ --out tracks.csv
    """
    import csv
    import sys

    import numpy as np

    from ..datasets import DatasetError, read_async_frames
    from ..tracking import TRACK_COLUMNS, Tracker
    from ..writing import OutputSet

    dep = _load_deployment(deployment_path)
    try:
        folder = read_async_frames(frames_dir)
    except DatasetError as e:
        raise UserError(str(e)) from None
    unknown = sorted(set(folder.camera_ids) - {c.id for c in dep.cameras})
    if unknown:
        raise UserError(f"{frames_dir}: cameras {', '.join(unknown)} are not in "
                        f"{deployment_path} (expected its camera ids)")
    if fps is None:  # the slowest camera's median frame interval
        gaps = []
        for cid in folder.camera_ids:
            t = np.array([e[0] for e in folder.events if e[1] == cid])
            if len(t) > 1:
                gaps.append(float(np.median(np.diff(t))))
        fps = 1.0 / max(gaps) if gaps and max(gaps) > 0 else 30.0
    out = _output_file(out, inputs=(deployment_path, frames_dir), what="the tracks")
    tracker = Tracker(dep, period=1.0 / fps)
    rows = []
    with click.progressbar(folder.events, label="tracking", hidden=quiet,
                           file=sys.stderr) as events:
        for t, cid, no in events:
            frame = folder.frame(cid, no)
            if frame is not None:
                rows += tracker.update(cid, t, frame)
    rows += tracker.finish()
    with OutputSet(out) as (tmp,):
        with open(tmp, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(TRACK_COLUMNS)
            w.writerows(r.row() for r in rows)
    if not quiet:
        ok = sum(r.status == "ok" for r in rows)
        leds = sorted({r.led for r in rows})
        click.echo(f"{len(folder.events)} camera frames ({fps:g} fps) → {len(rows)} rows, {ok} "
                   f"placed by two cameras or more, tracks {', '.join(leds) or '–'} → {out}",
                   err=True)
