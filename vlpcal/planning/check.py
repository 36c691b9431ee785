"""A given layout — planned, installed, edited by hand — judged against a site: the reference
model's verdict, and what the site would not allow (another image size, a tilt past
``max_tilt``, a camera near a wall or outside the room), named but not judged: the layout is
judged as it hangs.

shapely is imported inside :func:`check_layout`: importing planning for its types (as the
viewer and the demo do) loads no GEOS library.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..deployment import Deployment
from .reference import Evaluation, evaluate
from .site import Site


@dataclass(frozen=True)
class LayoutCheck:
    """A layout judged by the reference model, with what the site would not allow."""

    evaluation: Evaluation
    levels: tuple[float, ...]  #: m, the LED heights sampled
    cameras: int
    #: ids of cameras whose image size differs from the site's camera model
    other_size: tuple[str, ...] = ()
    #: (id, degrees) of cameras tilted past the site's ``max_tilt``
    too_tilted: tuple[tuple[str, float], ...] = ()
    #: (id, m) of cameras in the room nearer a wall than the site's ``wall_clearance``
    near_wall: tuple[tuple[str, float], ...] = ()
    outside: tuple[str, ...] = ()  #: ids of cameras outside the room polygon
    above: tuple[str, ...] = ()  #: ids of cameras not between the floor and the ceiling
    room_differs: bool = False  #: the deployment's room is not the site's (the site's is used)

    @property
    def meets(self) -> bool:
        return self.evaluation.meets


def check_layout(site: Site, deployment: Deployment) -> LayoutCheck:
    """Judge ``deployment``'s cameras against ``site`` by the reference model, and name what
    the site would not allow (only with a ``mounting`` block: tilt and wall clearance)."""
    from shapely import contains_xy, distance, points
    from shapely.geometry import Polygon

    cameras = list(deployment.cameras)
    ev = evaluate(site, cameras)
    levels = tuple(sorted(set(ev.points[:, 2].round(6))))
    model = site.camera
    other = tuple(sorted({c.id for c in cameras
                          if (c.width, c.height) != (model.width, model.height)}))
    xy = np.array([c.position[:2] for c in cameras]).reshape(-1, 2)
    room = Polygon(site.room)
    walls = room.buffer(1e-9 * max(1.0, *np.ptp(np.array(site.room), axis=0)))
    inside = contains_xy(walls, xy[:, 0], xy[:, 1])  # walls count as inside
    outside = tuple(c.id for c, ok in zip(cameras, inside) if not ok)
    steep, close = (), ()
    if site.mounting is not None:
        lean = [math.degrees(c.tilt) for c in cameras]
        steep = tuple((c.id, t) for c, t in zip(cameras, lean)
                      if t > math.degrees(site.mounting.max_tilt) + 0.05)
        near = distance(room.exterior, points(xy)) if len(xy) else np.zeros(0)
        close = tuple((c.id, float(d)) for c, d, ok in zip(cameras, near, inside)
                      if ok and d < site.mounting.wall_clearance - 1e-6)
    above = tuple(c.id for c in cameras if not 0 < c.position[2] <= site.ceiling_height)
    return LayoutCheck(ev, levels, len(cameras), other, steep, close, outside, above,
                       deployment.room != site.room)
