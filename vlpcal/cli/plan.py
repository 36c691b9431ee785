"""The installer's commands: plan a layout for a site, judge any layout against it
(``vlpcal plan``, ``vlpcal check``). The reports they print are
:mod:`vlpcal.planning.report`'s.
"""

from __future__ import annotations

from dataclasses import replace

import click

from ..deployment import MAX_ZONES, dumps, save
from ..planning import Candidate, SiteError, load_site, plan_site, planned_deployment
from ..planning.check import check_layout
from ..planning.report import (
    check_lines,
    mounting_lines,
    no_plan_message,
    plan_lines,
    verdict_line,
    zones_lines,
)
from ..planning.zones import ZoningError, cut_zones
from ..reports import plan_maps
from ..survey import SurveyError
from ..survey.linkage import link_cameras
from ..writing import OutputSet
from .common import UserError, _load_deployment, _output_file, _stop_asked, echo, main


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

    try:
        site = load_site(site_path)
    except SiteError as e:
        raise UserError(str(e)) from None
    if not str(out).lower().endswith((".yaml", ".yml")):
        raise UserError(f"{out}: the planned deployment is a YAML file (.yaml); its maps (.png) "
                        "go beside it")
    out = _output_file(out, inputs=(site_path,), beside=(".png",))
    say = (lambda m: None) if quiet else (lambda m: echo(m, err=True))

    def progress(line):  # between solves: a stop CasADi swallowed (a solve that "failed")
        _stop_asked()
        say(line)

    result = plan_site(site, max_cameras, progress=progress)
    if not result.candidates:
        raise click.ClickException(f"{site_path}: " + no_plan_message(
            site, result, max_cameras, max_cameras_name="--max-cameras"))
    for line in plan_lines(site, result):
        echo(line)
    if candidate > len(result.candidates):
        k = len(result.candidates)
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
    for line in mounting_lines(chosen.cameras):
        echo(line)
    _echo_linkage(dep)


def _echo_linkage(dep) -> None:
    """Whether a free survey can calibrate the layout: the cameras a free LED swept from the
    floor to 40 % of the ceiling can link, judged from the geometry (one line when all are);
    those it cannot, named with what would link them — told now, while cameras can still be
    moved, not after a survey's measuring."""
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

    try:
        site = load_site(site_path)
    except SiteError as e:
        raise UserError(str(e)) from None
    dep = _load_deployment(deployment_path)
    if maps is not None:
        if not str(maps).lower().endswith(".png"):
            raise UserError(f"{maps}: the maps are a PNG picture (.png)")
        maps = _output_file(maps, inputs=(site_path, deployment_path))
    checked = check_layout(site, dep)
    if not len(checked.evaluation.points):
        raise UserError(f"{site_path}: no point of the reference model's sample grid falls on "
                        "the floor (a room narrower than one grid cell?)")
    for line in check_lines(checked, site, site_path, deployment_path):
        echo(line)
    if maps is not None:
        cand = Candidate(f"as in {deployment_path}", 0, 0, (), (), 0.0, list(dep.cameras),
                         checked.evaluation)
        with OutputSet(maps) as (png,):
            plan_maps(png, site, cand)
        echo(f"  maps: {maps}")
    echo(verdict_line(checked, site))
    if not checked.meets:
        raise SystemExit(1)


@main.command()
@click.option("--deployment", "-d", "deployment_path", required=True,
              type=click.Path(dir_okay=False), help="Deployment YAML (docs/formats.md).")
@click.option("--processes", "-n", required=True, type=click.IntRange(1, MAX_ZONES),
              help="Locator processes to share the site among: one zone each.")
@click.option("--out", "-o", required=True, type=click.Path(dir_okay=False),
              help="The deployment with its zones: block (the input is never written over).")
def zones(deployment_path, processes, out):
    """Cut a site into zones for several locator processes, of balanced camera load.

    Each zone is a rectangle of the floor; its cameras are those whose view of the floor
    reaches it, so a camera near a border is in both zones and each zone's locator places
    every fix in its floor as the whole site's would. The cuts — strips along the room's
    longer side, or a grid of them — are chosen so that the most loaded zone has as few
    cameras as can be. Writes the deployment with the zones: block (an existing one is
    replaced) and prints each process's command.

    Example: vlpcal zones -d deployment.yaml --processes 4 --out deployment-zoned.yaml
    """
    dep = _load_deployment(deployment_path)
    out = _output_file(out, inputs=(deployment_path,), what="the zoned deployment")
    if not str(out).lower().endswith((".yaml", ".yml")):
        raise UserError(f"{out}: the zoned deployment is a YAML file (.yaml)")
    try:
        zoning = cut_zones(dep, processes)
    except ZoningError as e:
        raise UserError(str(e)) from None
    for line in zones_lines(zoning, replaced="zones" in dep.extra):
        echo(line)
    save(replace(dep, extra={**dep.extra, "zones": zoning.block()}), out)
    echo(f"wrote {out}; each process: vlpcal locate -d {out} --zone ZONE --spots mqtt://…")
