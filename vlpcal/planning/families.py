"""The grid families (linear, triangular, square with two spacings) as cameras on a ceiling, the
candidates they make and the mounting grid.

shapely is imported inside :func:`ceiling_area`: importing planning for its types (as the
viewer and the demo do) loads no GEOS library.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..geometry import NADIR, Camera, rodrigues, rotation_vector
from .reference import Evaluation
from .site import FAMILIES, Site, footprint


def grid_cameras(site: Site, family: str, nx: int, ny: int, spacing: tuple, origin: tuple,
                 rotation: float = 0.0, drop: float = 0.0, yaw: float = 0.0) -> list[Camera]:
    """Cameras of a grid family, nadir, hung ``drop`` m below the ceiling.

    ``linear``: one row of ``nx`` (``ny`` ignored); ``square``: ``nx × ny`` with spacings
    (a, b) (a = b for a square lattice); ``triangular``: rows ``b = a·√3/2`` apart, every other
    row shifted by a/2. The grid is rotated by ``rotation`` (rad) about ``origin`` (its first
    camera); each camera also turns by ``yaw`` about the vertical (0 or 90° matters for a
    160 × 120 image).
    """
    a = spacing[0]
    b = spacing[1] if len(spacing) > 1 else a
    pos = []
    if family == "linear":
        pos = [(i * a, 0.0) for i in range(nx)]
    elif family == "square":
        pos = [(i * a, j * b) for j in range(ny) for i in range(nx)]
    elif family == "triangular":
        b = a * math.sqrt(3) / 2
        pos = [(i * a + (a / 2 if j % 2 else 0.0), j * b) for j in range(ny) for i in range(nx)]
    else:
        raise ValueError(f"unknown family {family!r}; expected one of {', '.join(FAMILIES)}")
    c, s = math.cos(rotation), math.sin(rotation)
    xy = [(origin[0] + c * px - s * py, origin[1] + s * px + c * py) for px, py in pos]
    return ceiling_cameras(site, xy, [rotation + yaw] * len(xy), drop)


def ceiling_cameras(site: Site, xy, yaws, drop: float = 0.0) -> list[Camera]:
    """Cameras of the site's model, level (nadir) ``drop`` m below the ceiling at floor
    positions ``xy``, each turned by its yaw (rad) about the vertical; named C1, C2, …"""
    z = site.ceiling_height - drop
    m = site.camera
    out = []
    for k, ((x, y), yaw) in enumerate(zip(xy, yaws)):
        # the nadir camera turned by yaw about the world's vertical:
        # x_cam = R_nadir · Rz(θ)ᵀ · (X − C), so image-right points along Rz(θ)·x
        rvec = rotation_vector(rodrigues(NADIR) @ rodrigues((0.0, 0.0, float(yaw))).T)
        # to the micrometre: a position on the mounting grid reads 4.8, not 4.800000000000001
        out.append(Camera(f"C{k + 1}", m.width, m.height, m.fx, m.fy, m.cx, m.cy, m.dist,
                          (round(float(x), 6), round(float(y), 6), z), rvec))
    return out


@dataclass
class Candidate:
    """A layout of one family with its parameters and its verdict under the reference model."""

    family: str
    nx: int
    ny: int
    spacing: tuple  #: m, (a,) or (a, b)
    origin: tuple  #: m, the first camera's floor position
    yaw: float  #: rad
    cameras: list
    evaluation: Evaluation
    #: for a layout the optimiser found ("tilted"): the family of the layout it started from
    seed: str = ""

    @property
    def count(self) -> int:
        return len(self.cameras)


def rank_key(c: Candidate) -> tuple:
    """Passing layouts first (fewer cameras, then lower p95), then the closest to passing."""
    ev = c.evaluation
    return (0, c.count, ev.p95) if ev.meets else (1, -ev.coverage, ev.p95)


def ceiling_area(site: Site):
    """Where cameras may hang: the room less the site's wall clearance (a shapely polygon)."""
    from shapely.geometry import Polygon

    room = Polygon(site.room)
    clearance = site.mounting.wall_clearance if site.mounting else 0.0
    return room.buffer(-clearance, join_style="mitre") if clearance else room


#: m, the mounting grid: camera positions are multiples of it from the room's lower-left
#: corner (yaws are 0° or 90°, multiples of 5°)
MOUNT_STEP = 0.10


def mount_step(site: Site) -> float:
    """The mounting grid: :data:`MOUNT_STEP` for rooms of ordinary height; 1/10 of the
    footprint's short side when that is finer (a small scene); a multiple of it near 1/20 of
    the footprint when the footprint is over 3 m (a high ceiling), so that the search's
    resolution relative to a camera's view, and its work, stay bounded at any scale."""
    short = min(footprint(site))
    if short / 10 < MOUNT_STEP:
        return short / 10
    return MOUNT_STEP * max(1, round(short / (20 * MOUNT_STEP)))
