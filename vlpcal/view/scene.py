"""A deployment or site as the page draws it: the floor to scale, obstacles, each camera with
its id and its image's footprint at the lowest and highest LED height, and the reference
model's maps (docs/conventions.md#reference-model) at each height — how many cameras see a
point, which, and its predicted error — so a person can hover a point and read them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..deployment import Deployment
from ..planning.reference import sample_grid, sample_step, seen_by
from ..planning.site import Requirements, Site
from ..triangulation import predicted_rms_error

#: a map has at most this many cells a side (the page hovers cells; a big hall's are coarser)
MAP_CELLS = 200
#: LED heights of a deployment, which names none: the floor and this share of the ceiling
#: height (a robot's or a hand-held LED's reach)
DEFAULT_TOP = 0.25


@dataclass(frozen=True)
class Scene:
    """What the page draws of a room, as JSON-ready values (metres, radians)."""

    doc: dict


def site_of(dep: Deployment, heights=None, requirements: Requirements | None = None) -> Site:
    """A deployment as a site to judge it against: its room and cameras, and the
    ``requirements`` of the site it was planned for when known; else LED ``heights``
    (default: the floor and :data:`DEFAULT_TOP` of the ceiling height), two cameras per
    point, its spot noise."""
    if requirements is not None:
        return Site(dep.name, dep.ceiling_height, dep.room, dep.cameras[0], requirements,
                    list(dep.keep_out))
    if heights is None:
        heights = (0.0, DEFAULT_TOP * dep.ceiling_height)
    reqs = Requirements(tuple(sorted(float(h) for h in heights)), pixel_noise=dep.pixel_noise)
    return Site(dep.name, dep.ceiling_height, dep.room, dep.cameras[0], reqs,
                list(dep.keep_out))


def scene(site: Site, cameras: list, calibration: dict | None = None,
          stated: bool = True) -> Scene:
    """The page's scene of ``cameras`` in ``site``; ``calibration``: a survey's report block,
    passed on as it is; ``stated``: whether the site's requirements are a site file's (else
    assumed: the page then judges the error maps by their own spread)."""
    heights = list(site.requirements.heights)
    lo, hi = min(heights), max(heights)
    cams = []
    for c in cameras:
        cams.append({"id": c.id, "xyz": [float(v) for v in c.position], "yaw": float(c.yaw),
                     "tilt": float(c.tilt), "size": [c.width, c.height],
                     "footprints": [_points(c.footprint(lo)), _points(c.footprint(hi))]})
    room = np.asarray(site.room, float)
    extent = float(np.ptp(room, axis=0).max()) if len(room) else 1.0
    # the reference model's step, coarser for a big hall: at most MAP_CELLS a side (the grid
    # is made at that step, never at the fine one first)
    step = max(sample_step(site), extent / MAP_CELLS)
    xs, ys, inside = sample_grid(site, step)
    gx, gy = np.meshgrid(xs, ys)
    maps = []
    for h in sorted({lo, hi}):
        pts = np.column_stack([gx[inside], gy[inside], np.full(int(inside.sum()), h)])
        seen = seen_by(site, cameras, pts) if len(pts) else np.zeros((len(cameras), 0), bool)
        err = predicted_rms_error(cameras, pts, seen, site.requirements.pixel_noise) \
            if len(pts) and cameras else np.full(len(pts), np.nan)
        views = np.full(inside.shape, -1, int)  # -1: not floor
        views[inside] = seen.sum(axis=0)
        error = np.full(inside.shape, np.nan)
        error[inside] = err
        which = [[] for _ in range(inside.size)]
        flat = np.flatnonzero(inside.ravel())
        for k in range(len(cameras)):
            for i in flat[seen[k]]:
                which[i].append(k)
        maps.append({"height": float(h), "views": views.ravel().tolist(),
                     "error": [None if not np.isfinite(e) else round(float(e), 6)
                               for e in error.ravel()],
                     "cameras": which})
    r = site.requirements
    doc = {"name": site.name, "ceiling": float(site.ceiling_height),
           "room": _points(site.room), "keep_out": [_points(p) for p in site.keep_out],
           "obstacles": [{"polygon": _points(o.polygon), "height": float(o.height)}
                         for o in site.obstacles],
           "heights": [float(lo), float(hi)], "cameras": cams,
           "grid": {"x0": float(xs[0]) if len(xs) else 0.0,
                    "y0": float(ys[0]) if len(ys) else 0.0,
                    "step": step, "nx": len(xs), "ny": len(ys)},
           "maps": maps, "requirements": {"min_cameras": r.min_cameras,
                                          "max_error_p95": r.max_error_p95,
                                          "pixel_noise": r.pixel_noise,
                                          "stated": stated},
           "calibration": calibration}
    return Scene(doc)


def _points(p) -> list:
    """N×2 (or N×3) → a list of [x, y] pairs, a point that is not a number left out."""
    a = np.asarray(p, float)[:, :2]
    return [[round(float(x), 4), round(float(y), 4)] for x, y in a[np.isfinite(a).all(1)]]
