"""The ``vlpcal`` command. Thin: parses options and calls the layers below.

Heavy modules (cv2, scipy, casadi, matplotlib) are imported inside commands, so ``vlpcal
--help`` starts fast.
"""

from __future__ import annotations

import math

import click

from . import __version__


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="vlpcal")
def main():
    """vlpcal: centimetre-level 3D positioning of an LED from a few cheap ceiling cameras.

    Units are metres and radians; the world frame has z up and the floor at z = 0.
    """


class UserError(click.ClickException):
    """A user's mistake (a wrong path, a malformed file): one line, exit code 2."""

    exit_code = 2


def _load_deployment(path):
    from .deployment import DeploymentError, load

    try:
        return load(path)
    except DeploymentError as e:
        raise UserError(str(e)) from None


def _floats(text: str) -> list[float]:
    try:
        return [float(t) for t in text.split(",") if t.strip()]
    except ValueError:
        raise click.BadParameter(f"expected numbers separated by commas, got {text!r}") from None


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
    evaluation), OUT/survey/ (DESIGN.md survey bundle, tape-measure noise on points.csv),
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
    heights = _floats(survey_heights)
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
@click.option("--seed", default=0, show_default=True, help="Seed of the simulated frames.")
@click.option("--step", default=0.15, show_default=True, type=click.FloatRange(0.03, 1.0),
              help="Spacing of the LED test grid, m.")
def demo(seed: int, step: float):
    """Run the built-in demo: a simulated install of the paper's three-camera rig, the paper's
    pipeline beside vlpcal's on the same frames.

    Example: vlpcal demo --seed 1
    """
    from .demo import format_table, run_demo

    rows, n = run_demo(seed=seed, step=step)
    click.echo(f"A simulated install of the paper's rig (profile paper-2024, seed {seed}): 3 "
               f"cameras at 2.3 m, 160 × 120 px,\nhung a little off the plan; {n} LED "
               "positions at h = 0 and 0.35 m seen by ≥ 2 cameras; JPEG frames.")
    click.echo("3D error in cm over the same frames, with the cameras as planned (nominal):\n")
    click.echo(format_table(rows))
    click.echo("\nfixed: share of positions with a fix (the paper's pair method is undefined "
               "within 3° of\nthe cameras' line in top view). Calibrated: from a simulated "
               "survey of other points\n(vlpcal survey calibrate --intrinsics); the last row "
               "is the floor it aims for.")


@main.command()
@click.option("--deployment", "-d", "deployment_path", required=True,
              type=click.Path(dir_okay=False), help="Deployment YAML (DESIGN.md).")
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

    One row per frame set: frame_id,x,y,z,status first (DESIGN.md), then the cameras used,
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
    except UserError:
        writer.abort()
        raise
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


def _locate_live(loc, cameras, writer, tolerance, duration, max_sets, statuses, notes,
                 say) -> int:
    import time

    from .live import LiveGrouper, open_source

    sources = {}
    for spec in cameras:
        cid, sep, src = spec.partition("=")
        if not sep or not cid or not src:
            raise UserError(f"--camera {spec!r}: expected ID=SOURCE, e.g. "
                            "C1=http://10.0.0.21:81/stream")
        if cid not in loc.camera_ids:
            raise UserError(f"--camera {spec!r}: {loc.deployment.name} has no camera {cid!r} "
                            f"(it has {', '.join(loc.camera_ids)})")
        sources[cid] = open_source(src)
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
    """Survey calibration: cameras (and region maps) from LED measurements at known points."""


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
              help="Points each camera must see (12 lets --intrinsics fit the lens).")
def survey_plan(deployment_path, out, step, heights, min_per_camera):
    """Plan the survey: where to put the LED, with ids, and a map to print.

    Example: vlpcal survey plan -d nominal.yaml --out survey/points.csv
    """
    from pathlib import Path

    from .datasets import POINTS_COLUMNS, write_truth_csv
    from .survey import SurveyError, plan_survey

    dep = _load_deployment(deployment_path)
    hs = _floats(heights)
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
    _plan_figure(out.with_suffix(".png"), dep, plan)
    click.echo(f"{len(plan.ids)} points at h = {', '.join(f'{h:g}' for h in sorted(set(hs)))} m "
               f"→ {out}, map {out.with_suffix('.png')}")
    ids = plan.camera_ids
    for k, cid in enumerate(ids):
        shared = [(ids[j], int((plan.seen[k] & plan.seen[j]).sum())) for j in range(len(ids))
                  if j != k]
        pairs = ", ".join(f"{cj} {n}" for cj, n in shared if n)
        click.echo(f"  {cid}: sees {int(plan.seen[k].sum())} points; shared with {pairs or '–'}")


def _plan_figure(path, dep, plan) -> None:
    """One panel per height: room, keep-out areas, cameras, points with their ids."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    heights = sorted(set(plan.xyz[:, 2].round(6)))
    room = np.array(dep.room + dep.room[:1])
    fig, axes = plt.subplots(1, len(heights), figsize=(5.5 * len(heights), 5.0),
                             squeeze=False, constrained_layout=True)
    for ax, h in zip(axes[0], heights):
        ax.plot(room[:, 0], room[:, 1], "k-", lw=1)
        for poly in dep.keep_out:
            ax.fill(*np.array(poly).T, color="0.85", hatch="//", ec="0.5")
        for c in dep.cameras:
            ax.plot(*c.position[:2], "rs", ms=7)
            ax.annotate(c.id, c.position[:2], color="r", fontsize=8, xytext=(4, 4),
                        textcoords="offset points")
        sel = np.flatnonzero(np.isclose(plan.xyz[:, 2], h))
        ax.plot(plan.xyz[sel, 0], plan.xyz[sel, 1], "-", color="0.8", lw=0.6)  # walking order
        ax.plot(plan.xyz[sel, 0], plan.xyz[sel, 1], "o", color="#2a7ab0", ms=4)
        for i in sel:
            ax.annotate(plan.ids[i][1:].lstrip("0"), plan.xyz[i, :2], fontsize=5,
                        xytext=(2, 2), textcoords="offset points")
        ax.set_title(f"LED at h = {h:g} m: {len(sel)} points (S{plan.ids[sel[0]][1:]}…)",
                     fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
    axes[0][0].set_ylabel("y (m)")
    fig.suptitle(f"Survey plan for {dep.name}: place the LED at each point, measure, record",
                 fontsize=10)
    _save_figure(fig, path, dpi=130)


@survey.command("calibrate")
@click.option("--deployment", "-d", "deployment_path", required=True,
              type=click.Path(dir_okay=False), help="The nominal deployment (as installed).")
@click.option("--survey", "survey_path", required=True, type=click.Path(file_okay=False),
              help="Survey bundle: points.csv and frames/ (or observations.csv).")
@click.option("--out", "-o", required=True, type=click.Path(dir_okay=False),
              help="Calibrated deployment to write; a report (.report.json, .png) goes beside.")
@click.option("--intrinsics", is_flag=True,
              help="Also fit focal lengths, principal point and distortion (needs points at "
                   "two or more heights).")
@click.option("--folds", default=5, show_default=True, type=click.IntRange(2, 20),
              help="Held-out accuracy: k-fold by survey point.")
@click.option("--point-sigma", default=0.003, show_default=True, type=click.FloatRange(0.0001),
              help="Measurement uncertainty of a surveyed position, m per axis.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
def survey_calibrate(deployment_path, survey_path, out, intrinsics, folds, point_sigma, quiet):
    """Calibrate the cameras from a survey and report held-out accuracy.

    Each camera's pose (and with --intrinsics its lens) is fitted to the survey points it saw,
    robustly (wrong spots and mis-measured points are reported by id), then all cameras and
    all surveyed positions are refined together, each position within --point-sigma. The
    accuracy printed is measured on survey points left out of the fit (k-fold), never on the
    fitted ones.

    Example: vlpcal survey calibrate -d nominal.yaml --survey survey/ --out calibrated.yaml
    """
    from pathlib import Path

    import numpy as np

    from .datasets import DatasetError, read_survey_bundle
    from .deployment import Deployment, save
    from .geometry import rodrigues
    from .survey import (
        SurveyError,
        calibrate,
        held_out,
        learn_region_map,
        survey_spots,
    )

    dep = _load_deployment(deployment_path)
    try:
        bundle = read_survey_bundle(survey_path)
    except DatasetError as e:
        raise UserError(str(e)) from None
    out = Path(out)
    if out.is_dir() or not out.parent.is_dir():
        raise UserError(f"{out}: cannot write there (expected a file in an existing folder)")
    uv, notes = survey_spots(dep, bundle)
    for note in notes:
        click.echo(note, err=True)
    X, ids, cams = bundle.xyz, bundle.point_ids, dep.cameras
    _check_survey_positions(survey_path, dep, X, ids)
    try:
        with click.progressbar(length=folds + 1, label="calibrating (all, then k-fold)",
                               file=None if not quiet else open("/dev/null", "w")) as bar:
            cal = calibrate(cams, X, uv, ids, intrinsics, point_sigma)
            bar.update(1)
            per_point: dict = {}
            stats = held_out(cams, X, uv, ids, dep.room, intrinsics, folds, point_sigma,
                             progress=lambda i, n: bar.update(1), per_point=per_point,
                             pair_method=dep.pair_method, max_residual=dep.max_residual)
    except SurveyError as e:
        raise UserError(f"{survey_path}: {e}") from None
    rmap = learn_region_map(cal.cameras, uv, cal.adjusted, dep.room, pair_method=dep.pair_method)
    choice = {"calibrated, (a) mean of pairs": "mean", "calibrated, (b) nearest pair": "nearest",
              "calibrated, (c) region map": "region", "calibrated, all-camera LS": "robust"}
    best = min(choice, key=lambda k: stats[k]["mean"] if stats[k]["mean"] is not None
               else np.inf)
    extra = {k: v for k, v in dep.extra.items() if k != "provenance"}
    extra["fusion"] = {**extra.get("fusion", {}), "method": choice[best],
                       "region_map": rmap.to_dict()}
    from datetime import datetime, timezone

    from . import __version__

    extra["provenance"] = {
        "command": "vlpcal survey calibrate", "vlpcal": __version__,
        "written": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "from": {"deployment": str(deployment_path), "survey": str(survey_path),
                 "points": len(ids)},
        "intrinsics": intrinsics,
        "held_out_mean_m": {k: v["mean"] for k, v in stats.items()},
    }
    calibrated = Deployment(dep.name, dep.ceiling_height, dep.room, cal.cameras, dep.keep_out,
                            extra)
    # the report: per camera and held out
    cam_rows = []
    for nom, fit in zip(cams, cal.fits):
        c = fit.camera
        dR = rodrigues(c.rotation) @ rodrigues(nom.rotation).T
        angle = float(np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1, 1))))
        cam_rows.append({"camera": c.id, "rms_px": fit.rms_px, "points": fit.used,
                         "outliers": fit.outliers,
                         "moved_cm": float(np.linalg.norm(np.subtract(c.position,
                                                                      nom.position)) * 100),
                         "turned_deg": angle,
                         "fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy, "dist": list(c.dist)})
    click.echo(f"\nheld-out 3D error ({folds}-fold by survey point, {len(ids)} points), cm; the "
               f"reference is the measured position itself (±{point_sigma * 1000:g} mm per "
               f"axis ≈ {point_sigma * 173:.2f} cm in 3D):")
    click.echo(f"{'':32s} {'mean':>7s} {'median':>7s} {'p90':>7s} {'max':>7s} {'fixed':>6s}")
    for label, st in stats.items():
        if st["mean"] is None:
            click.echo(f"{label:32s} {'–':>7s}")
            continue
        click.echo(f"{label:32s} {st['mean'] * 100:7.2f} {st['median'] * 100:7.2f} "
                   f"{st['p90'] * 100:7.2f} {st['max'] * 100:7.2f} {st['fixed']:6.0%}")
    click.echo(f"\n{'camera':8s} {'RMS px':>7s} {'points':>7s} {'moved cm':>9s} "
               f"{'turned °':>9s}  rejected spots")
    for r in cam_rows:
        click.echo(f"{r['camera']:8s} {r['rms_px']:7.3f} {r['points']:7d} {r['moved_cm']:9.2f} "
                   f"{r['turned_deg']:9.2f}  {', '.join(r['outliers']) or '–'}")
    if cal.mismeasured:
        click.echo("\nmis-measured survey points (rejected by the cameras that saw them; how far "
                   "from its record the calibrated cameras put the LED):")
        for pid, off in cal.mismeasured:
            click.echo(f"  {pid}: {off * 100:.1f} cm" if np.isfinite(off) else f"  {pid}: –")
    save(calibrated, out, header=f"Calibrated by vlpcal survey calibrate from {survey_path}.")
    report = {"held_out_m": stats, "cameras": cam_rows, "fusion": choice[best],
              "mismeasured": [{"point_id": p, "moved_m": m} for p, m in cal.mismeasured],
              "notes": notes}
    import json

    from .deployment import atomic_write_text

    atomic_write_text(out.with_suffix(".report.json"), json.dumps(report, indent=2))
    _survey_figure(out.with_suffix(".png"), stats, per_point, X, cal.cameras)
    click.echo(f"\nwrote {out} (fusion: {choice[best]}), {out.with_suffix('.report.json')}, "
               f"{out.with_suffix('.png')}")


def _save_figure(fig, path, dpi: int = 110) -> None:
    """Write a matplotlib figure as PNG atomically (a temporary file, then rename), close it."""
    import matplotlib.pyplot as plt

    tmp = path.with_name(f".{path.name}.tmp.png")
    try:
        fig.savefig(tmp, dpi=dpi)
        tmp.replace(path)
    finally:
        plt.close(fig)
        tmp.unlink(missing_ok=True)


def _check_survey_positions(survey_path, dep, X, ids) -> None:
    """Refuse positions that cannot be in this room (millimetres read as metres, a typo)."""
    import numpy as np
    from shapely import contains_xy
    from shapely.geometry import Polygon

    room = Polygon(dep.room).buffer(0.5)
    inside = contains_xy(room, X[:, 0], X[:, 1]) & (X[:, 2] > -0.1) \
        & (X[:, 2] < dep.ceiling_height)
    if not inside.all():
        i = int(np.flatnonzero(~inside)[0])
        raise UserError(f"{survey_path}: point {ids[i]} at ({X[i, 0]:g}, {X[i, 1]:g}, "
                        f"{X[i, 2]:g}) m is not in the room of {dep.name} (0.5 m margin) or "
                        f"under its {dep.ceiling_height:g} m ceiling: metres expected")


def _survey_figure(path, stats, per_point, X, cameras) -> None:
    """Held-out errors: map over the floor (nominal vs calibrated, all-camera LS) and CDF."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    nom = per_point["nominal, all-camera LS"] * 100
    cal = per_point["calibrated, all-camera LS"] * 100
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2), constrained_layout=True)
    vmax = np.nanpercentile(nom, 95) if np.isfinite(nom).any() else 1.0
    for ax, err, title in ((axes[0], nom, "nominal cameras"), (axes[1], cal, "calibrated")):
        ok = np.isfinite(err)
        sc = ax.scatter(X[ok, 0], X[ok, 1], c=err[ok], cmap="viridis", vmin=0, vmax=vmax, s=18)
        for c in cameras:
            ax.plot(*c.position[:2], "rs", ms=6)
        ax.set_title(f"held-out error, {title}: mean {np.nanmean(err):.2f} cm", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
    fig.colorbar(sc, ax=axes[:2].tolist(), label="3D error (cm)", shrink=0.8)
    for label, err in per_point.items():
        e = np.sort(err[np.isfinite(err)] * 100)
        if len(e):
            axes[2].plot(e, np.arange(1, len(e) + 1) / len(e), label=label,
                         ls="--" if label.startswith("nominal") else "-")
    axes[2].set_xscale("log")
    axes[2].set_xlabel("held-out 3D error (cm)")
    axes[2].set_ylabel("CDF")
    axes[2].grid(alpha=0.3)
    axes[2].legend(fontsize=6)
    _save_figure(fig, path, dpi=110)


@main.command()
@click.option("--site", "site_path", required=True, type=click.Path(dir_okay=False),
              help="Site file (DESIGN.md format vlpcal-site).")
@click.option("--out", "-o", required=True, type=click.Path(dir_okay=False),
              help="Deployment to write; maps per LED height (.png) go beside it.")
@click.option("--candidate", default=1, show_default=True, type=click.IntRange(1),
              help="Which ranked candidate to export.")
@click.option("--max-cameras", default=120, show_default=True, type=click.IntRange(2),
              help="Give up above this many cameras.")
@click.option("--quiet", "-q", is_flag=True, help="No progress lines.")
def plan(site_path, out, candidate, max_cameras, quiet):
    """Plan a camera grid: the fewest cameras that meet the site's requirements.

    Searches linear, triangular and square (two spacings) grids by camera count; for each
    arrangement and yaw a CasADi/IPOPT optimiser sets spacing and offset on smooth
    surrogates, and every result is judged by the reference model of DESIGN.md (coverage and
    predicted 95th-percentile error). Prints the ranked candidates, writes the chosen one.

    Example: vlpcal plan --site layouts/paper-linear.site.yaml --out deployment.yaml
    """
    from datetime import datetime, timezone
    from pathlib import Path

    from . import __version__
    from .deployment import Deployment, save
    from .planning import SiteError, load_site, plan_site

    try:
        site = load_site(site_path)
    except SiteError as e:
        raise UserError(str(e)) from None
    out = Path(out)
    if out.is_dir() or not out.parent.is_dir():
        raise UserError(f"{out}: cannot write there (expected a file in an existing folder)")
    say = (lambda m: None) if quiet else (lambda m: click.echo(m, err=True))
    result = plan_site(site, max_cameras, progress=lambda n: say(f"  tried {n} cameras"))
    r = site.requirements
    if not result.candidates:
        c = result.closest
        best = (f"the best found: {c.count} cameras ({c.family}) cover "
                f"{c.evaluation.coverage:.1%} with p95 {c.evaluation.p95 * 100:.2f} cm"
                if c else "no layout could be evaluated")
        raise click.ClickException(
            f"{site_path}: no grid of up to {max_cameras} cameras meets coverage "
            f"{r.coverage:.0%} with p95 ≤ {r.max_error_p95 * 100:g} cm ({best}); relax the "
            "requirements, lower the LED heights or use a camera with more pixels")
    click.echo(f"{site.name}: {len(result.candidates)} layouts of "
               f"{result.candidates[0].count} cameras meet the requirements "
               f"({result.tried} arrangements optimised, {result.seconds:.1f} s)\n")
    click.echo(f"{'#':>2s} {'family':10s} {'cams':>4s} {'grid':>6s} {'spacing m':>12s} "
               f"{'yaw':>4s} {'coverage':>8s} {'mean cm':>8s} {'p95 cm':>7s}")
    for k, c in enumerate(result.candidates, start=1):
        sp = "×".join(f"{v:.2f}" for v in c.spacing)
        click.echo(f"{k:2d} {c.family:10s} {c.count:4d} {c.nx:>3d}×{c.ny:<2d} {sp:>12s} "
                   f"{round(math.degrees(c.yaw)):4d} {c.evaluation.coverage:8.1%} "
                   f"{c.evaluation.mean * 100:8.2f} {c.evaluation.p95 * 100:7.2f}")
    if candidate > len(result.candidates):
        raise UserError(f"--candidate {candidate}: only {len(result.candidates)} candidates")
    chosen = result.candidates[candidate - 1]
    ev = chosen.evaluation
    provenance = {
        "command": "vlpcal plan", "vlpcal": __version__,
        "written": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "from": {"site": str(site_path)},
        "plan": {"family": chosen.family, "grid": [chosen.nx, chosen.ny],
                 "spacing_m": [float(v) for v in chosen.spacing],
                 "origin_m": [float(v) for v in chosen.origin],
                 "yaw_rad": float(chosen.yaw), "rank": candidate},
        "predicted": {"coverage": ev.coverage, "mean_error_m": ev.mean, "p95_error_m": ev.p95,
                      "model": "DESIGN.md reference model", "pixel_noise_px": r.pixel_noise},
    }
    dep = Deployment(site.name, site.ceiling_height, site.room, chosen.cameras, site.keep_out,
                     {"uncertainty": {"pixel_noise": r.pixel_noise}, "provenance": provenance})
    save(dep, out, header=f"Planned by vlpcal plan from {site_path}: candidate {candidate}.")
    _plan_maps(out.with_suffix(".png"), site, chosen)
    click.echo(f"\nwrote {out} (candidate {candidate}) and {out.with_suffix('.png')}")


def _plan_maps(path, site, cand) -> None:
    """Per LED height: cameras, how many see each point, and the predicted error."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    ev = cand.evaluation
    levels = sorted(set(ev.points[:, 2].round(6)))
    fig, axes = plt.subplots(2, len(levels), figsize=(4.6 * len(levels), 7.2), squeeze=False,
                             constrained_layout=True)
    room = np.array(list(site.room) + [site.room[0]])
    vmax = np.nanpercentile(ev.error, 99) * 100 if np.isfinite(ev.error).any() else 1
    for col, h in enumerate(levels):
        sel = np.isclose(ev.points[:, 2], h)
        for row, (values, cmap, label) in enumerate((
                (ev.views[sel], "viridis", "cameras seeing the point"),
                (ev.error[sel] * 100, "magma_r", "predicted RMS error (cm)"))):
            ax = axes[row][col]
            sc = ax.scatter(ev.points[sel, 0], ev.points[sel, 1], c=values, cmap=cmap, s=6,
                            marker="s", vmin=0, vmax=None if row == 0 else vmax)
            ax.plot(room[:, 0], room[:, 1], "k-", lw=1)
            for poly in site.keep_out:
                ax.fill(*np.array(poly).T, color="0.85", ec="0.5")
            for c in cand.cameras:
                ax.plot(*c.position[:2], "c^", ms=6, mec="k")
            ax.set_aspect("equal")
            ax.set_title(f"h = {h:g} m: {label}", fontsize=8)
            fig.colorbar(sc, ax=ax, shrink=0.7)
    fig.suptitle(f"{site.name}: {cand.count} cameras, {cand.family} — coverage "
                 f"{ev.coverage:.1%}, predicted p95 {ev.p95 * 100:.2f} cm", fontsize=10)
    _save_figure(fig, path, dpi=110)
