"""What a deployment holds, for a person (``vlpcal show``)."""

from __future__ import annotations

import math

import click
import numpy as np
from shapely.geometry import Polygon

from ..reading import shown
from .common import _load_deployment, echo, main


@main.command("show")
@click.argument("deployment_path", metavar="DEPLOYMENT", type=click.Path(dir_okay=False),
                required=False)
@click.option("--deployment", "-d", "deployment_option", type=click.Path(dir_okay=False),
              help="The deployment (as the other commands take it; or give it as the argument).")
def show(deployment_path, deployment_option):
    """Print what a deployment holds: the room, every camera (image, lens, where it hangs and
    how it points), the detector and fusion the locator will use (region map, residual limit),
    pixel corrections, the spot noise behind predicted errors, and where the file came from
    (planned, calibrated: the predicted or held-out accuracy).

    Example: vlpcal show layouts/paper-linear.planned.yaml
    """
    if (deployment_path is None) == (deployment_option is None):
        raise click.UsageError("give one deployment: vlpcal show D (or -d D)")
    dep = _load_deployment(deployment_path or deployment_option)
    room = np.asarray(dep.room, float)
    span = _extent(room)
    area = 0.5 * abs(np.dot(room[:, 0], np.roll(room[:, 1], 1))
                     - np.dot(room[:, 1], np.roll(room[:, 0], 1)))
    _say(f"{dep.name}: {len(dep.cameras)} camera{'s' if len(dep.cameras) != 1 else ''};"
               f" room {span[0]:.4g} × {span[1]:.4g} m ({area:.2f} m², {len(room)} corners), "
               f"ceiling {dep.ceiling_height:g} m"
               + (f", {len(dep.keep_out)} keep-out area(s)" if dep.keep_out else ""))
    _say(f"\n{'camera':8s} {'image':>9s} {'fx':>7s} {'fy':>7s} {'cx':>6s} {'cy':>6s} "
               f"{'lens k1':>8s} {'x m':>7s} {'y m':>7s} {'z m':>6s} {'tilt°':>6s} {'yaw°':>5s}")
    for c in dep.cameras:
        tilt = math.degrees(c.tilt)
        yaw = round(math.degrees(c.yaw)) % 360  # as printed: 359.7 shows as 0, not 360
        x, y, z = c.position
        _say(f"{c.id[:8]:8s} {f'{c.width}×{c.height}':>9s} {c.fx:7.1f} {c.fy:7.1f} "
                   f"{c.cx:6.1f} {c.cy:6.1f} {c.dist[0]:8.3f} {x:7.3f} {y:7.3f} {z:6.3f} "
                   f"{tilt:6.1f} {yaw:5.0f}")
    _say("(tilt: the optical axis from straight down; yaw: the image's x axis from the "
               "room's x axis)")
    fusion = dep.extra.get("fusion", {})
    line = f"\nlocator: detector {dep.detector}, fusion {dep.fusion}"
    if "max_residual" in fusion:
        line += f", residual limit {float(fusion['max_residual']):.2f} px"
    if fusion.get("region_map"):
        line += f", region map of {len(fusion['region_map'])} regions"
    _say(line)
    corrections = dep.extra.get("corrections", {})
    if corrections:
        _say(f"pixel corrections for {len(corrections)} camera(s): "
                   + ", ".join(f"{cid} ({', '.join(f'{v:+.2f}' for v in c['pixel_offset'])} px)"
                               for cid, c in list(corrections.items())[:6] if 'pixel_offset' in c))
    noise = dep.extra.get("uncertainty", {}).get("pixel_noise")
    if noise is not None:
        _say(f"predicted errors assume {float(noise):g} px of spot noise")
    prov = dep.extra.get("provenance") or {}
    try:
        _provenance(dep, prov)
    except (TypeError, ValueError, AttributeError, KeyError, OverflowError):
        _say(f"  (the rest of provenance: is not as vlpcal writes it: {shown(prov)})")


def _provenance(dep, prov) -> None:
    """What made the deployment, from its ``provenance:`` block (a block another tool wrote
    may hold anything: the caller catches what does not read)."""
    if prov:
        _say(f"\nmade by {prov.get('command', 'an unknown tool')}"
                   + (f" (vlpcal {prov['vlpcal']})" if prov.get("vlpcal") else "")
                   + (f" on {prov['written']}" if prov.get("written") else ""))
        for key, value in (prov.get("from") or {}).items():
            _say(f"  from {key}: {value}")
        plan = prov.get("plan") or {}
        if plan:
            _say(f"  plan: a {plan.get('family', '?')} layout of "
                       f"{plan.get('cameras', len(dep.cameras))} cameras")
        predicted = prov.get("predicted") or {}
        if predicted.get("p95_error_m") is not None:
            _say(f"  predicted: coverage {float(predicted.get('coverage', 0)):.1%}, p95 "
                       f"{float(predicted['p95_error_m']) * 100:.2f} cm at "
                       f"{predicted.get('pixel_noise_px', '?')} px")
        if isinstance(prov.get("lens"), dict):
            _say("  lens models: " + ", ".join(f"{k} {v}" for k, v in prov["lens"].items()))
        if prov.get("point_sigma_m") is not None:
            how = "estimated" if prov.get("point_sigma_estimated") else \
                "assumed" if prov.get("point_sigma_assumed") else "as stated"
            _say(f"  survey points' position error: {float(prov['point_sigma_m']) * 1000:.1f}"
                       f" mm ({how})")
        wand = prov.get("wand_error_m")
        if isinstance(wand, dict) and wand.get("mean") is not None and prov.get("wand_m"):
            _say(f"  wand: {float(prov['wand_m']) * 1000:.0f} mm long, missed by "
                       f"{float(wand['mean']) * 1000:.2f} mm on average (p95 "
                       f"{float(wand.get('p95') or math.nan) * 1000:.2f} mm) over "
                       f"{wand.get('held_out_sets', '?')} held-out sets")
        if prov.get("datum_floor_m") is not None:
            _say(f"  frame fixed to about {float(prov['datum_floor_m']) * 1000:.1f} mm by "
                       "its references or marks (the datum floor: no calibration in that frame "
                       "does better on average)")
        if prov.get("predicted_error_m") is not None:
            _say(f"  predicted mean 3D error of fixes: "
                 f"{float(prov['predicted_error_m']) * 1000:.1f} mm (from the fit's own "
                 "uncertainty" + ("" if prov.get("held_out_mean_m")
                                  else "; no test points held out") + ")")
        held = prov.get("held_out_mean_m")
        if isinstance(held, dict) and held:
            best = min(held, key=lambda k: held[k] if held[k] is not None else math.inf)
            if held[best] is not None:
                _say(f"  held-out mean 3D error: {float(held[best]) * 100:.2f} cm "
                           f"({best}; the report has every pipeline)")


def _say(text: str = "") -> None:
    """A line of the report (names and strings from the file printed safely: :func:`echo`)."""
    echo(text)


def _extent(room):
    """The room's length and width: the sides of the smallest rectangle around it at any
    angle (a room carried into a frame that marks define is turned, and its box would not
    be its size)."""
    box = np.asarray(Polygon(room).minimum_rotated_rectangle.exterior.coords)[:3]
    return np.sort(np.linalg.norm(np.diff(box, axis=0), axis=1))[::-1]
