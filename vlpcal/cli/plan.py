"""The installer's commands: plan a layout for a site, judge any layout against it
(``vlpcal plan``, ``vlpcal check``)."""

from __future__ import annotations

import math

import click

from .common import UserError, _load_deployment, _output_file, echo, main


@main.command()
@click.option("--site", "site_path", required=True, type=click.Path(dir_okay=False),
              help="Site file (format vlpcal-site, docs/formats.md).")
@click.option("--out", "-o", required=True, type=click.Path(dir_okay=False),
              help="Deployment to write; maps per LED height (.png) go beside it.")
@click.option("--candidate", default=1, show_default=True, type=click.IntRange(1),
              help="Which ranked candidate to export.")
@click.option("--max-cameras", default=120, show_default=True, type=click.IntRange(2, 250),
              help="Give up above this many cameras.")
@click.option("--quiet", "-q", is_flag=True, help="No progress lines.")
def plan(site_path, out, candidate, max_cameras, quiet):
    """Plan a camera layout: the fewest cameras that meet the site's requirements.

    Every lattice of the site's grid families (square with two spacings, triangular, linear)
    on the 10 cm mounting grid, both camera yaws, cameras clipped to the room; then, when the
    site allows "free" layouts (the default), a local search from the best lattice removes
    cameras and moves the others while the layout still meets the requirements. When the
    site's mounting: block allows tilt, the CasADi optimiser then moves, turns and tilts the
    cameras of the best layout while fewer still meet (without it, the plan says what tilting
    would save). Every candidate is judged by the reference model of docs/formats.md
    (coverage and predicted 95th-percentile error, obstacles' shadows counted). Prints the
    ranked candidates, writes the chosen one and, for tilted cameras, how to hang each.

    Example: vlpcal plan --site layouts/paper-linear.site.yaml --out deployment.yaml
    """

    from ..deployment import dumps
    from ..planning import SiteError, load_site, plan_site, planned_deployment
    from ..planning.site import unit_doubt
    from ..reports import plan_maps
    from ..writing import OutputSet

    try:
        site = load_site(site_path)
    except SiteError as e:
        raise UserError(str(e)) from None
    if not str(out).lower().endswith((".yaml", ".yml")):
        raise UserError(f"{out}: the planned deployment is a YAML file (.yaml); its maps (.png) "
                        "go beside it")
    out = _output_file(out, inputs=(site_path,), beside=(".png",))
    say = (lambda m: None) if quiet else (lambda m: echo(m, err=True))
    from .common import _stop_asked

    def progress(line):  # between solves: a stop CasADi swallowed (a solve that "failed")
        _stop_asked()
        say(line)

    result = plan_site(site, max_cameras, progress=progress)
    r = site.requirements
    if not result.candidates and "all" in result.missing:
        raise click.ClickException(f"{site_path}: no layout of up to {max_cameras} cameras "
                                   f"can meet the requirements: {result.missing['all']}; "
                                   "raise --max-cameras, relax the requirements or use a "
                                   "camera with a wider view" + unit_doubt(site))
    if not result.candidates:
        m = result.mended
        kind = "tilted" if site.mounting and site.mounting.max_tilt > 0 else "level"
        tried = "" if m is None else (
            f"; the CasADi optimiser's {kind} cameras found {m.best.count}, more than "
            f"{max_cameras} ({_solves(m)})" if m.best is not None else
            f"; the CasADi optimiser's {kind} cameras found none either ({_solves(m)})"
            if m.complete else
            f"; the CasADi optimiser's {kind} cameras found none in its time ({_solves(m)})")
        c = result.closest
        best = (f"for comparison, a dense lattice of {c.count} camera"
                f"{'s' if c.count != 1 else ''} covers {c.evaluation.coverage:.1%}"
                + (f" with p95 {c.evaluation.p95 * 100:.2f} cm"
                   if math.isfinite(c.evaluation.p95) else "")
                if c else "no layout could be evaluated")
        raise click.ClickException(
            f"{site_path}: no layout of up to {max_cameras} cameras meets coverage "
            f"{r.coverage:.0%} with p95 ≤ {r.max_error_p95 * 100:g} cm ({best}{tried}); relax the "
            "requirements, lower the LED heights or use a camera with more pixels"
            + unit_doubt(site))
    k = len(result.candidates)
    echo(f"{site.name}: {result.candidates[0].count} cameras meet the requirements "
         f"({k} candidate{'s' if k > 1 else ''}; {result.tried} layouts judged, "
         f"{result.seconds:.1f} s)\n")
    echo(f"{'#':>2s} {'layout':10s} {'cams':>4s} {'x×y':>6s} {'spacing m':>12s} "
         f"{'yaw':>5s} {'coverage':>8s} {'mean cm':>8s} {'p95 cm':>7s}")
    for k, c in enumerate(result.candidates, start=1):
        xs = {round(cam.position[0], 6) for cam in c.cameras}
        ys = {round(cam.position[1], 6) for cam in c.cameras}
        grid = f"{len(xs)}×{len(ys)}"
        sp = "×".join(f"{v:.2f}" for v in c.spacing) if c.spacing else "–"
        yaw = "/".join(str(a) for a in sorted({round(math.degrees(cam.yaw)) % 180
                                               for cam in c.cameras}))
        if c.family in ("tilted", "free") and len(xs) * len(ys) > c.count:
            grid = "–"  # not a grid: the positions are in the deployment
        yaw = yaw if len(yaw) <= 5 else "mixed"
        echo(f"{k:2d} {c.family:10s} {c.count:4d} {grid:>6s} {sp:>12s} {yaw:>5s} "
             f"{c.evaluation.coverage:8.1%} {c.evaluation.mean * 100:8.2f} "
             f"{c.evaluation.p95 * 100:7.2f}")
    for family, why in result.missing.items():
        echo(f"   {family:10s} {why}")
    echo(f"x×y: distinct camera positions along x and y (cameras on a {_mount(site)} "
         "grid from the room's lower-left corner); yaw: "
         f"degrees from the room's x axis to each image's {site.camera.width} px side "
         "(the maps draw it)")
    _echo_tilted(site, result)
    if candidate > len(result.candidates):
        raise UserError(f"--candidate {candidate}: the plan has {k} candidate"
                        f"{'s' if k > 1 else ''}, numbered from 1")
    chosen = result.candidates[candidate - 1]
    dep = planned_deployment(site, chosen, candidate, site_path)
    say("  drawing the maps…")
    _stop_asked()  # (the last solve's)
    with OutputSet(out.with_suffix(".png"), out) as (png, yaml_file):  # both, or neither
        plan_maps(png, site, chosen)
        yaml_file.write_text(dumps(dep, f"Planned by vlpcal plan from {site_path}: candidate "
                                        f"{candidate}."), encoding="utf-8")
    echo(f"\nwrote {out} (candidate {candidate}) and {out.with_suffix('.png')}")
    _echo_mounting(chosen.cameras)
    _echo_linkage(dep)


def _solves(t) -> str:
    return (f"CasADi optimiser: {len(t.solves)} solve{'s' * (len(t.solves) != 1)}, "
            f"{sum(s.iterations for s in t.solves)} iterations, {t.seconds:.1f} s")


def _echo_tilted(site, result) -> None:
    """What the CasADi optimiser did beyond the lattices: the layout it mended when no
    lattice met, its tilted candidate and its cost when the site allows tilt, else what
    tilting would save."""
    deg = f"{math.degrees(result.tilt):.3g}°"
    m = result.mended
    if m is not None:
        tilted = site.mounting is not None and site.mounting.max_tilt > 0
        echo(f"{m.best.family}: no lattice meets the exact reference model "
             f"(see above); from one of {m.start} cameras the optimiser mended a "
             f"layout of {m.best.count}" + (" tilted" if tilted else " level")
             + f" cameras ({_solves(m)})")
    t = result.tilted
    if t is None:
        if site.mounting is None and m is None and result.candidates:
            echo(f"what tilting would save is not estimated for a layout this large "
                 f"({result.candidates[0].count} cameras); a mounting: block in the "
                 "site plans tilted cameras")
        return
    if site.mounting is None and t.best is not None:
        fewer = "" if t.complete else " or fewer (the what-if ran out of its time)"
        echo(f"with tilt up to {deg}: {t.best.count} cameras{fewer} instead of "
             f"{t.start} — needs tilting brackets (a mounting: block in the site "
             f"would allow it; {_solves(t)})")
    elif site.mounting is None and t.complete:
        echo(f"tilting up to {deg} would not save a camera ({_solves(t)})")
    elif site.mounting is None:
        echo(f"what tilting up to {deg} would save was not found in the what-if's time "
             f"({_solves(t)}); a mounting: block in the site plans tilted cameras")
    elif t.best is not None:
        from ..planning.poses import pose_of, tilts

        most = math.degrees(max(tilts([pose_of(c) for c in t.best.cameras])))
        echo(f"tilted: {t.best.count} cameras, tilted up to {most:.0f}° (of {deg} "
             f"allowed), from the best {t.best.seed} layout ({_solves(t)})")
    else:
        echo(f"tilted: none below {t.start} cameras with tilts up to {deg} "
             f"({_solves(t)})")


def _echo_mounting(cameras) -> None:
    """How to hang a layout whose cameras are not all level: per camera where, the bracket's
    turn about the vertical, and which way and how far it tilts (what the maps draw)."""
    from ..planning.poses import pose_of

    poses = [pose_of(c) for c in cameras]
    if all(math.hypot(p[3], p[4]) < math.radians(0.5) for p in poses):
        return
    echo("how to hang it (turn: the level camera's image x axis from the room's x "
         "axis, set first; then tilt the optical axis toward the direction given, "
         "degrees from the room's x axis):")
    for c, p in zip(cameras, poses):
        tilt = math.degrees(math.hypot(p[3], p[4]))
        toward = round(math.degrees(math.atan2(p[3], -p[4]))) % 360  # leans along (−wy, wx)
        echo(f"  {c.id:>4s} at ({p[0]:.2f}, {p[1]:.2f}) m: turn "
             f"{round(math.degrees(p[2])) % 360:3d}°, tilt {tilt:2.0f}°"
             + (f" toward {toward:3d}°" if tilt >= 0.5 else ""))


def _echo_linkage(dep) -> None:
    """Whether a free survey can calibrate the layout: the cameras a free LED swept from the
    floor to 40 % of the ceiling can link, judged from the geometry (one line when all are);
    those it cannot, named with what would link them — told now, while cameras can still be
    moved, not after a survey's measuring."""
    from ..survey import SurveyError
    from ..survey.linkage import link_cameras

    try:
        lines = link_cameras(dep).sentences()
    except SurveyError as e:
        lines = [f"cannot be judged: {e}"]
    echo(f"free survey (vlpcal survey plan --free): {lines[0]}")
    for line in lines[1:]:
        echo(f"  {line}")


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

    from ..planning import Candidate, SiteError, evaluate, load_site
    from ..reports import plan_maps

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
    if not len(ev.points):
        raise UserError(f"{site_path}: no point of the reference model's sample grid falls on "
                        "the floor (a room narrower than one grid cell?)")
    r = site.requirements
    levels = sorted(set(ev.points[:, 2].round(6)))
    hs = ", ".join(f"{h:g}" for h in levels)
    n = len(dep.cameras)
    echo(f"{deployment_path}: {n} camera{'' if n == 1 else 's'} judged against "
         f"{site_path} ({site.name}; LED at {hs} m, {r.min_cameras} cameras per point, "
         f"spot noise {r.pixel_noise:g} px):")
    model = site.camera
    other = sorted({c.id for c in dep.cameras if (c.width, c.height) != (model.width,
                                                                         model.height)})
    if other:
        echo(f"  note: {', '.join(other[:5])}{' …' if len(other) > 5 else ''} have another "
             "image size than the site's camera model; each camera is judged as it is")
    from shapely import contains_xy, distance, points
    from shapely.geometry import Polygon

    xy = np.array([c.position[:2] for c in dep.cameras]).reshape(-1, 2)
    room = Polygon(site.room)
    walls = room.buffer(1e-9 * max(1.0, *np.ptp(np.array(site.room), axis=0)))
    inside = contains_xy(walls, xy[:, 0], xy[:, 1])  # walls count as inside
    outside = [c.id for c, ok in zip(dep.cameras, inside) if not ok]
    if site.mounting is not None:  # what the site's mounting allows, named (not judged)
        lean = [math.degrees(c.tilt) for c in dep.cameras]
        steep = [f"{c.id} ({t:.1f}°)" for c, t in zip(dep.cameras, lean)
                 if t > math.degrees(site.mounting.max_tilt) + 0.05]
        near = distance(room.exterior, points(xy)) if len(xy) else np.zeros(0)
        close = [f"{c.id} ({d:.2f} m)" for c, d, ok in zip(dep.cameras, near, inside)
                 if ok and d < site.mounting.wall_clearance - 1e-6]
        if steep:
            echo(f"  note: {', '.join(steep[:5])}{' …' if len(steep) > 5 else ''} tilt "
                 f"past the site's max_tilt "
                 f"({math.degrees(site.mounting.max_tilt):g}°); judged as they are")
        if close:
            echo(f"  note: {', '.join(close[:5])}{' …' if len(close) > 5 else ''} hang "
                 f"closer to a wall than the site's wall_clearance "
                 f"({site.mounting.wall_clearance:g} m); judged as they are")
    high = [c.id for c in dep.cameras if not 0 < c.position[2] <= site.ceiling_height]
    if outside or high:
        echo(f"  note: camera(s) {', '.join((outside + high)[:5])} hang outside the "
             "room or above its ceiling; judged as they are")
    p95 = f"{ev.p95 * 100:.2f} cm" if math.isfinite(ev.p95) else "–"
    mean = f"{ev.mean * 100:.2f} cm" if math.isfinite(ev.mean) else "–"
    echo(f"  coverage {ev.coverage:.1%} (required {r.coverage:.1%}): the share of the "
         f"floor's sample points seen by {r.min_cameras} or more cameras")
    echo(f"  predicted error over those points: p95 {p95} (required ≤ "
         f"{r.max_error_p95 * 100:.3g} cm), mean {mean}")
    why = []
    if ev.coverage < r.coverage:
        why.append(f"coverage {ev.coverage:.1%} < {r.coverage:.1%}")
    if not ev.p95 <= r.max_error_p95:
        why.append(f"p95 {ev.p95 * 100:.3f} cm > {r.max_error_p95 * 100:.3f} cm"
                   if math.isfinite(ev.p95) else "p95 unbounded: some points are seen by "
                   "cameras at one place only, which cannot triangulate them")
    if dep.room != site.room:
        echo("  note: the deployment's room differs from the site's; the site's is used")
    if maps is not None:
        cand = Candidate(f"as in {deployment_path}", 0, 0, (), (), 0.0, list(dep.cameras), ev)
        from ..writing import OutputSet

        with OutputSet(maps) as (png,):
            plan_maps(png, site, cand)
        echo(f"  maps: {maps}")
    if why:
        echo(f"verdict: does not meet the site ({'; '.join(why)})")
        raise SystemExit(1)
    echo("verdict: meets the site")


def _mount(site) -> str:
    """The site's mounting grid, said in the unit a person would use."""
    from ..planning import mount_step

    step = mount_step(site)
    return f"{step * 100:.3g} cm" if step >= 0.01 else f"{step * 1000:.3g} mm"
