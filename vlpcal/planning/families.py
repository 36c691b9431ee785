"""The grid families (linear, triangular, square with two spacings) as cameras on a ceiling, the
candidates they make, and the closed-form bounds that prune the search."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..geometry import NADIR, Camera, rodrigues, rotation_vector
from .reference import Evaluation
from .site import FAMILIES, Site


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
    z = site.ceiling_height - drop
    # the nadir camera turned by (rotation + yaw) about the world's vertical:
    # x_cam = R_nadir · Rz(θ)ᵀ · (X − C), so image-right points along Rz(θ)·x
    rvec = rotation_vector(rodrigues(NADIR) @ rodrigues((0.0, 0.0, rotation + yaw)).T)
    out = []
    for k, (px, py) in enumerate(pos):
        x = origin[0] + c * px - s * py
        y = origin[1] + s * px + c * py
        out.append(Camera(f"C{k + 1}", site.camera.width, site.camera.height, site.camera.fx,
                          site.camera.fy, site.camera.cx, site.camera.cy, site.camera.dist,
                          (x, y, z), rvec))
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

    @property
    def count(self) -> int:
        return len(self.cameras)


def rank_key(c: Candidate) -> tuple:
    """Passing layouts first (fewer cameras, then lower p95), then the closest to passing."""
    ev = c.evaluation
    return (0, c.count, ev.p95) if ev.meets else (1, -ev.coverage, ev.p95)


def footprint(site: Site) -> tuple[float, float]:
    """Width and depth (m) of a nadir camera's view at the highest LED height."""
    z = site.ceiling_height - max(site.requirements.heights)
    return site.camera.width / site.camera.fx * z, site.camera.height / site.camera.fy * z


def shapes(family: str, n: int) -> list[tuple[int, int]]:
    """The (nx, ny) arrangements of ``n`` cameras a family allows."""
    if family == "linear":
        return [(n, 1)]
    return [(nx, n // nx) for nx in range(1, n + 1) if n % nx == 0 and n // nx >= 2 and nx >= 2]


def arrangements(site: Site, n: int):
    """Every (family, nx, ny, yaw) of ``n`` cameras worth trying: the site's families, their
    shapes, yaw 0° and 90°, kept by :func:`promising`."""
    for family in site.families:
        for nx, ny in shapes(family, n):
            for yaw in (0.0, math.pi / 2):
                if promising(site, family, nx, ny, yaw):
                    yield family, nx, ny, yaw


def lower_bound(site: Site) -> int:
    """Fewest cameras worth trying: k footprints' worth of the covered area at the highest
    LED height."""
    from shapely.geometry import Polygon

    fw, fd = footprint(site)
    r = site.requirements
    return max(2, math.ceil(r.min_cameras * r.coverage * Polygon(site.room).area / (fw * fd)))


def promising(site: Site, family: str, nx: int, ny: int, yaw: float) -> bool:
    """Whether an arrangement can meet the coverage at all (a cheap closed-form screen,
    FIELD-NOTES): on an axis-aligned lattice a point's camera count is columns × rows seeing
    it, so covering the room once needs nx footprints across and ny along, and k cameras
    need k-fold cover along at least one axis (10 % slack for the coverage share)."""
    from shapely.geometry import Polygon

    fw, fd = footprint(site)
    if yaw:
        fw, fd = fd, fw
    x0, y0, x1, y1 = Polygon(site.room).bounds
    lx, ly = x1 - x0, y1 - y0
    rows = 1 if family == "linear" else ny
    k = site.requirements.min_cameras
    once = nx * fw >= 0.9 * lx and rows * fd >= 0.9 * ly
    k_fold = nx * fw >= 0.9 * k * lx or rows * fd >= 0.9 * k * ly
    return once and k_fold


def mountable(site: Site, cameras: list[Camera]) -> list[Camera]:
    """The cameras that can hang from the ceiling: inside the room polygon (keep-out areas are
    floor obstacles, not ceiling bans); renamed C1, C2, … in order."""
    from dataclasses import replace as _replace

    from shapely import contains_xy
    from shapely.geometry import Polygon

    room = Polygon(site.room).buffer(1e-9)
    xy = np.array([c.position[:2] for c in cameras])
    inside = contains_xy(room, xy[:, 0], xy[:, 1]) if len(xy) else np.zeros(0, bool)
    kept = [c for c, ok in zip(cameras, inside) if ok]
    return [_replace(c, id=f"C{k + 1}") for k, c in enumerate(kept)]
