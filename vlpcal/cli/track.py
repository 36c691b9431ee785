"""The robot integrator's command: an LED's track from cameras that are not synchronised
(``vlpcal track``, issue 16)."""

from __future__ import annotations

import click

from .common import Finite, UserError, _load_deployment, _output_file, main

#: camera frames read and detected at once, at most — and at most this many bytes of them
BLOCK, BLOCK_BYTES = 2048, 64 << 20


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
    # the folder, and what it holds through links (times.csv, each camera's folder)
    from pathlib import Path

    held = [Path(frames_dir) / "times.csv", *(Path(frames_dir) / c for c in folder.camera_ids)]
    out = _output_file(out, inputs=(deployment_path, frames_dir, *held), what="the tracks")
    from ..detection import detect_spots

    tracker = Tracker(dep, period=1.0 / fps)
    cams = {c.id: c for c in dep.cameras}
    rows = []
    missing = 0

    def track_block(block):
        """Each camera's frames of the block detected as one batch (a tenth of the cost of
        one by one), then fed to the tracker in time order."""
        spots: dict = {}
        for cid in {c for _, c, _, _ in block}:
            mine = [(no, f) for _, c, no, f in block if c == cid]
            found = detect_spots([f for _, f in mine], dep.detector, dep.detector_settings,
                                 shape=(cams[cid].height, cams[cid].width))
            for (no, _), u, v in zip(mine, found.u, found.v):
                spots[(cid, no)] = (u, v) if np.isfinite(u) and np.isfinite(v) else None
        for t, cid, no, _ in block:
            rows.extend(tracker.update_spot(cid, t, spots[(cid, no)]))

    with click.progressbar(length=len(folder.events), label="tracking", hidden=quiet,
                           file=sys.stderr) as bar:
        block, held_bytes = [], 0  # frames held at once: bounded in count and in bytes
        for t, cid, no in folder.events:
            frame = folder.frame(cid, no)
            missing += frame is None
            block.append((t, cid, no, frame))
            held_bytes += len(frame or b"")
            if len(block) >= BLOCK or held_bytes >= BLOCK_BYTES:
                track_block(block)
                bar.update(len(block))
                block, held_bytes = [], 0
        if block:
            track_block(block)
            bar.update(len(block))
    if missing == len(folder.events):
        raise UserError(f"{frames_dir}: none of the {missing} frames times.csv lists is there "
                        "(expected <camera_id>/<frame_no>.jpg); nothing was written")
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
                   f"placed by two cameras or more, tracks {', '.join(leds) or '–'} → {out}"
                   + (f"; {missing} listed frames missing" if missing else ""), err=True)
