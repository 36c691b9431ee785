"""The live page (``vlpcal view``, and ``--view`` on ``track``): a deployment's plan, its
cameras' frames and the tracks, in a browser (docs/view.md)."""

from __future__ import annotations

import click

from .common import Finite, UserError, echo, main

#: the page's address unless told otherwise
DEFAULT_BIND = "127.0.0.1:8765"


def open_view(dep, bind: str, source: str = "", live: bool = True, site=None, path=None):
    """Serve the page of deployment ``dep`` (or of ``site``, a planner's site file, with no
    cameras) on ``bind``; returns (its hub — None when not ``live`` —, its server). A
    calibrated deployment's report (``<path>.report.json`` and its figure ``<path>.png``,
    as ``survey calibrate`` writes them beside it) is shown too. Says where it is on stderr
    (with the token, when bound off loopback)."""
    from ..view.scene import scene, site_of
    from ..view.server import ViewError, ViewServer, parse_bind

    try:
        host, port = parse_bind(bind)
    except ViewError as e:
        raise UserError(f"--view/--bind {e}") from None
    figure = None
    if site is None:
        calibration, figure = _calibration(path) if path else (None, None)
        planned = _planned_for(dep, path)  # the site it was planned for: its LED heights
        drawn = scene(site_of(dep, requirements=planned.requirements if planned else None),
                      list(dep.cameras), calibration=calibration, stated=planned is not None)
        cameras = {c.id: (c.width, c.height) for c in dep.cameras}
    else:
        drawn, cameras = scene(site, []), {}
    hub = None
    if live:
        from ..view import ViewHub

        hub = ViewHub(cameras, source)
    try:
        server = ViewServer(drawn, hub, host, port, figure=figure)
    except ViewError as e:
        raise UserError(f"view: {e}") from None
    line = f"view: {server.url}"
    if server.token:
        line += ("  (bound beyond this machine: the page asks for this token; anyone on the "
                 "network who has the address has the view)")
    echo(line, err=True)
    return hub, server


def _planned_for(dep, path):
    """The site a deployment was planned for (``vlpcal plan`` names it in the provenance:
    ``from: {site: …}``, relative to the deployment's folder or the working one), or None
    when it names none or it cannot be read."""
    from pathlib import Path

    from ..planning import SiteError, load_site

    prov = dep.extra.get("provenance")
    named = prov.get("from", {}).get("site") if isinstance(prov, dict) and isinstance(
        prov.get("from"), dict) else None
    if not isinstance(named, str) or not named:
        return None
    for where in ([Path(path).parent / named] if path else []) + [Path(named)]:
        try:
            if where.is_file():
                return load_site(where)
        except (SiteError, OSError):
            return None
    return None


#: a calibration report beside a deployment is read up to this size (it is a few kB)
REPORT_BYTES = 4 << 20


def _calibration(path) -> tuple[dict | None, bytes | None]:
    """The survey report beside a calibrated deployment (``<path>.report.json``), as the page
    shows it — per camera how far it moved and turned, its lens model; per comparison the
    held-out error —, and its figure (``<path>.png``); (None, None) when there is none or it
    cannot be read (said in a note; the plan is shown without it)."""
    import json
    import math
    from pathlib import Path

    report, png = Path(path).with_suffix(".report.json"), Path(path).with_suffix(".png")
    def number(v):  # a finite number, or None
        v = float(v)
        return v if math.isfinite(v) else None

    try:
        if not report.is_file() or report.stat().st_size > REPORT_BYTES:
            return None, None
        doc = json.loads(report.read_text(encoding="utf-8"))
        cameras = [{"id": str(c["camera"]), "moved_mm": 1000 * number(c["moved_m"]),
                    "turned_deg": number(c["turned_deg"]), "lens": str(c.get("lens_model", ""))}
                   for c in doc["cameras"]]
        held = {str(k): {"mean_m": number(v["mean"]) if v.get("mean") is not None else None,
                         "p95_m": number(v["p95"]) if v.get("p95") is not None else None,
                         "fixed": number(v["fixed"]) if v.get("fixed") is not None else None}
                for k, v in (doc.get("held_out_m") or {}).items() if isinstance(v, dict)}
        figure = png.read_bytes() if png.is_file() and png.stat().st_size <= REPORT_BYTES \
            else None
    except (OSError, ValueError, KeyError, TypeError, AttributeError, OverflowError):
        echo(f"note: {report}: not a calibration report that can be read; the plan is "
             "shown without it", err=True)
        return None, None
    return {"report": report.name, "cameras": cameras, "held_out": held,
            "figure": figure is not None}, figure


@main.command()
@click.argument("path", type=click.Path(dir_okay=False))
@click.option("--bind", default=DEFAULT_BIND, show_default=True, metavar="HOST:PORT",
              help="Where the page is served; another interface than loopback asks for the "
                   "token printed at start.")
@click.option("--camera", "cameras", multiple=True, metavar="ID=SOURCE",
              help="A live camera (as vlpcal track --camera): its frames, spots and the "
                   "tracks drawn live.")
@click.option("--spots", "spots_url", default=None, metavar="mqtt://…/PREFIX",
              help="Spots the cameras publish on PREFIX/spots/<camera> (as vlpcal track "
                   "--spots): shown on the tiles and tracked on the plan, nothing written.")
@click.option("--follow", "follow_url", default=None, metavar="mqtt://…/PREFIX",
              help="Follow a running locate or track that publishes on PREFIX (--publish): "
                   "its fixes, tracks and bodies, and the spots cameras publish there.")
@click.option("--ca-file", type=click.Path(dir_okay=False, exists=True), default=None,
              help="The broker's CA certificate (mqtts:// with a private CA).")
@click.option("--duration", type=Finite(0, 1e7, min_open=True), default=None,
              help="Stop after this many seconds (default: until Ctrl-C).")
def view(path, bind, cameras, spots_url, follow_url, ca_file, duration):
    """A deployment (or a planner's site) in the browser: the floor plan to scale, the
    cameras and their footprints at the lowest and highest LED height, the maps of how many
    cameras see each point and its predicted error (hover a point to read them); with
    --camera, each camera's latest frame and spots and the tracks on the plan, live.

    Example: vlpcal view layouts/paper-linear.deployment.yaml
    """
    import time

    dep, site = _deployment_or_site(path)
    if (cameras or follow_url or spots_url) and dep is None:
        raise UserError(f"{path}: a site has no cameras to show live; give a deployment")
    if sum(map(bool, (cameras, follow_url, spots_url))) > 1:
        raise UserError("give one of --camera …, --spots or --follow")
    target = spots = None
    from .mqtt import parse_mqtt

    if follow_url:
        target = parse_mqtt(follow_url, "--follow")
    if spots_url:
        spots = parse_mqtt(spots_url, "--spots")
    source = (f"{path}, {len(cameras)} live camera(s)" if cameras else
              f"{path}, following {target.shown()}" if target else
              f"{path}, spots on {spots.shown()}" if spots else path)
    hub, server = open_view(dep, bind, source=source, live=bool(cameras or target or spots),
                            site=site, path=path)
    t_end = time.monotonic() + duration if duration else None
    try:
        if target is not None:
            _follow(target, ca_file, hub, t_end)
        elif spots is not None:
            from .track_live import _track_spots

            _track_spots(dep, path, spots, ca_file, duration, None, None, None, None, True,
                         None, lambda watch: None, hub)
        elif cameras:
            from .track_live import _track_live

            _track_live(dep, path, cameras, duration, None, None, None, None, True, None,
                        lambda watch: None, hub)
        else:
            echo("Ctrl-C to stop", err=True)
            while t_end is None or time.monotonic() < t_end:
                time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    finally:
        server.close()


def _follow(target, ca_file, hub, t_end) -> None:
    """What a running command publishes on ``target``'s prefix, to the page, until
    ``t_end`` (monotonic s) or Ctrl-C."""
    import time

    from ..mqtt import MqttError, RowSubscriber

    try:
        sub = RowSubscriber(target, ca_file)
    except MqttError as e:
        raise UserError(f"--follow {e}") from None
    echo(f"following {target.shown()}/{{fixes,bodies,spots}}/+ (Ctrl-C to stop)",
         err=True)
    try:
        while t_end is None or time.monotonic() < t_end:
            item = sub.get(timeout=0.2)
            if item is None:
                continue
            if item[0] == "spots":
                t, uv = item[2]
                hub.frame(item[1], t, uv)
            else:
                hub.message_rows([item[2]])
    finally:
        sub.close()
        if sub.bad:
            one = sub.bad == 1
            echo(f"{sub.bad} message{'' if one else 's'} on {target.shown()} "
                 f"{'was not a fix' if one else 'were not fixes'}, track update, body "
                 "pose or spots (not shown)", err=True)


def _deployment_or_site(path):
    """A deployment file → (deployment, None); a planner's site file → (None, site)."""
    from ..deployment import DeploymentError, load
    from ..planning import SiteError, load_site
    from ..reading import ReadError, load_yaml

    try:
        doc = load_yaml(path, "a deployment or a site file (docs/formats.md)")
    except ReadError as e:
        raise UserError(str(e)) from None
    if isinstance(doc, dict) and doc.get("format") == "vlpcal-site":
        try:
            return None, load_site(path)
        except SiteError as e:
            raise UserError(str(e)) from None
    try:
        return load(path), None
    except DeploymentError as e:
        raise UserError(str(e)) from None
