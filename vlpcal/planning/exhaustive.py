"""The exhaustive search over each family's spacing, offset and yaw: the baseline the optimiser
must match."""

from __future__ import annotations

import math

import numpy as np

from .families import Candidate, arrangements, footprint, grid_cameras, mountable
from .reference import evaluate
from .site import Site


def exhaustive_search(site: Site, n: int, steps: int = 8, offsets: int = 5,
                      screen_step: float = 0.2) -> list[Candidate]:
    """Every layout of ``n`` cameras over a grid of spacings (``steps`` values from 0.3 to 1.0
    footprint) and offsets (``offsets`` × ``offsets`` shifts within a spacing), both yaws
    (0°, 90°), for each of the site's families; screened on a coarse sample grid, the
    promising ones judged by :func:`evaluate`. Returns the candidates that meet the
    requirements, best predicted p95 first."""
    from itertools import product

    from shapely.geometry import Polygon

    x0, y0, x1, y1 = Polygon(site.room).bounds
    grid = np.linspace(0.3, 1.0, steps)
    found = []
    for family, nx, ny, yaw in arrangements(site, n):
        fw, fd = footprint(site)
        if yaw:
            fw, fd = fd, fw
        for fa, fb in product(grid, grid if family == "square" else [None]):
            a = fa * fw
            b = fb * fd if fb is not None else (a * math.sqrt(3) / 2
                                                 if family == "triangular" else 0.0)
            span_x = (nx - 1) * a + (a / 2 if family == "triangular" and ny > 1 else 0.0)
            cx0 = (x0 + x1 - span_x) / 2
            cy0 = (y0 + y1 - (ny - 1) * b) / 2
            spacing = (a, b) if family == "square" else (a,)
            shifts_x = np.linspace(-a / 2, a / 2, offsets) if nx > 1 else [0.0]
            shifts_y = np.linspace(-b / 2, b / 2, offsets) if ny > 1 and b else [0.0]
            for dx, dy in product(shifts_x, shifts_y):
                origin = (cx0 + dx, cy0 + dy)
                cams = mountable(site, grid_cameras(site, family, nx, ny, spacing, origin,
                                                    yaw=yaw))
                if not evaluate(site, cams, screen_step).meets:
                    continue
                ev = evaluate(site, cams)
                if ev.meets:
                    found.append(Candidate(family, nx, ny, spacing, origin, yaw, cams, ev))
    return sorted(found, key=lambda c: c.evaluation.p95)
