"""A site cut into zones for several locator processes: each zone a rectangle of the floor,
its cameras those that see any of it, so that a camera near a border serves both zones and a
zone's locator places every fix in its floor as the whole site's would.

The load of a process is its cameras (their frames or spots are what it decodes and fits):
the cuts are chosen so that the most loaded zone carries as few cameras as can be, over
strips along the room's longer side and grids of strips cut across, whichever balances best.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np

from ..deployment import Deployment

#: the floor is sampled at this share of the narrowest camera view's side (so no view is
#: missed between samples, nor its border misplaced by more than this share)
SAMPLE_SHARE = 1 / 10
#: px: a sample this far inside an image is seen (a spot at the very edge is not measured)
EDGE_PX = 2.0


@dataclass(frozen=True)
class Zone:
    """One locator process's share of a site: ``id``; ``polygon``, its floor (m, a rectangle
    clipped to the room's bounds); ``cameras``, the ids of the cameras that see any of it."""

    id: str
    polygon: tuple
    cameras: tuple


@dataclass(frozen=True)
class Zoning:
    """A site cut into zones: ``zones``; ``grid``, the cut (strips along the room's longer
    side × pieces across each); ``cameras``, the site's count."""

    zones: tuple
    grid: tuple
    cameras: int

    @property
    def loads(self) -> np.ndarray:
        """Each zone's cameras."""
        return np.array([len(z.cameras) for z in self.zones])

    @property
    def imbalance(self) -> float:
        """The most loaded zone's cameras over the mean zone's, less one (0: even)."""
        return float(self.loads.max() / self.loads.mean() - 1.0)

    @property
    def shared(self) -> int:
        """Cameras in more than one zone (on a border)."""
        counts = Counter(c for z in self.zones for c in z.cameras)
        return sum(n > 1 for n in counts.values())

    def block(self) -> list:
        """The deployment's ``zones:`` block."""
        return [{"id": z.id, "polygon": [list(map(float, p)) for p in z.polygon],
                 "cameras": list(z.cameras)} for z in self.zones]


class ZoningError(ValueError):
    """The site cannot be cut so: a zone would hold fewer than two cameras."""


def cut_zones(deployment: Deployment, processes: int, heights=(0.0,)) -> Zoning:
    """``deployment``'s floor cut into ``processes`` zones of balanced camera load; a zone's
    cameras are those whose view of the floor at LED ``heights`` (m) reaches it (the view's
    bounding rectangle: a camera that might see the zone is in it). Raises
    :class:`ZoningError` when no cut gives every zone two cameras."""
    views, grid_u, grid_v, bounds, along = _views(deployment, heights)
    best = None
    for a in range(1, processes + 1):
        if processes % a:
            continue
        grid = (a, processes // a)
        cells = _cut(views, grid_u, grid_v, grid, bounds, along)
        if cells is None:
            continue
        loads = [int(_reach(views, box).sum()) for box, _ in cells]
        key = (max(loads), max(loads) - min(loads), sum(loads))
        if best is None or key < best[0]:
            best = (key, grid, cells)
    if best is None:
        raise ZoningError(f"{deployment.name}: its floor cannot be cut into {processes} zones "
                          "that each at least two cameras see")
    _, grid, cells = best
    ids = [c.id for c in deployment.cameras]
    zones = [Zone(f"Z{k + 1}", rect, tuple(ids[i] for i in np.flatnonzero(_reach(views, box))))
             for k, (box, rect) in enumerate(cells)]
    return Zoning(tuple(zones), grid, len(ids))


def _views(deployment: Deployment, heights):
    """Each camera's view of the floor at any of ``heights``, as a rectangle in the cut's
    coordinates (C×4: along's low, high, across's low, high; NaN: it sees none of the
    floor); the floor's sample coordinates along and across; the room's bounds (x0, y0, x1,
    y1); and ``along``, the axis of the room's longer side (0: x)."""
    room = np.array(deployment.room, float)
    lo, hi = room.min(axis=0), room.max(axis=0)
    along = 0 if hi[0] - lo[0] >= hi[1] - lo[1] else 1
    depth = min(c.center[2] for c in deployment.cameras) - max(heights)
    view = min(min(c.width / c.fx, c.height / c.fy) for c in deployment.cameras)
    step = SAMPLE_SHARE * view * depth if depth > 0 else float((hi - lo).max()) / 100
    gx = np.arange(lo[0] + step / 2, hi[0], step)
    gy = np.arange(lo[1] + step / 2, hi[1], step)
    xy = np.stack(np.meshgrid(gx, gy, indexing="ij"), -1).reshape(-1, 2)
    xy = xy[~deployment.outside(np.c_[xy, np.zeros(len(xy))], np.zeros(len(xy)))]
    u, v = xy[:, along], xy[:, 1 - along]
    views = np.full((len(deployment.cameras), 4), np.nan)
    for i, cam in enumerate(deployment.cameras):
        seen = np.zeros(len(xy), bool)
        for h in heights:
            seen |= cam.project(np.c_[xy, np.full(len(xy), float(h))], margin=EDGE_PX)[2]
        if seen.any():  # (its view's edge lies within a step past its outermost samples)
            views[i] = (u[seen].min() - step, u[seen].max() + step, v[seen].min() - step,
                        v[seen].max() + step)
    return views, np.unique(u), np.unique(v), (*lo, *hi), along


def _reach(views, box):
    """Which cameras' views reach the rectangle ``box`` (along's low, high, across's)."""
    with np.errstate(invalid="ignore"):
        return (views[:, 0] <= box[1]) & (views[:, 1] >= box[0]) & (views[:, 2] <= box[3]) \
            & (views[:, 3] >= box[2])


def _cut(views, grid_u, grid_v, grid, bounds, along):
    """The cells of a ``grid`` (strips along ``along``, pieces across each) whose most loaded
    cell carries the fewest cameras — the least load every cell can keep to, found by
    bisection: [(its box in the cut's coordinates, its rectangle)], strip by strip, a cell's
    cameras those whose views reach its box; the borders midway between neighbouring
    samples, the outer ones on the room's ``bounds``. None when some cell would see fewer
    than two cameras."""
    strips, pieces = grid
    x0, y0, x1, y1 = bounds
    u_range, v_range = ((x0, x1), (y0, y1)) if along == 0 else ((y0, y1), (x0, x1))

    def cuts(values, n, fits, outer):
        """``n`` runs of ``values`` (sorted sample coordinates) whose rectangles each
        ``fits`` (given its lower and upper border, monotone in either), their borders
        midway between the latest and the earliest that allow it (runs as long as they may
        from either end): the loads even out instead of the last run taking what is left.
        [(lower border, upper border)], or None."""
        m = len(values)

        def border(i):  # between sample i − 1 and sample i; the room's bounds outside
            return outer[0] if i == 0 else outer[1] if i == m else 0.5 * (values[i - 1]
                                                                           + values[i])

        def ahead():  # each run's start, each run as long as it may from the start
            starts, start = [], 0
            for k in range(n - 1):
                lo, hi = start + 1, m - (n - 1 - k)  # (a value left for each run after)
                if lo > hi or not fits(border(start), border(lo)):
                    return None
                while lo < hi:
                    mid = (lo + hi + 1) // 2
                    lo, hi = (mid, hi) if fits(border(start), border(mid)) else (lo, mid - 1)
                starts.append(start)
                start = lo
            return starts + [start] if fits(border(start), border(m)) else None

        def back():  # each run's start, each run as long as it may from the end
            starts, end = [], m
            for k in range(n - 1):
                lo, hi = n - 1 - k, end - 1  # (a value left for each run before)
                if lo > hi or not fits(border(hi), border(end)):
                    return None
                while lo < hi:
                    mid = (lo + hi) // 2
                    lo, hi = (lo, mid) if fits(border(mid), border(end)) else (mid + 1, hi)
                starts.append(lo)
                end = lo
            return [0] + starts[::-1] if fits(border(0), border(end)) else None

        first, last = ahead(), back()
        if first is None:
            return None
        starts = first
        if last is not None:
            middle = [0] + [(p + q) // 2 for p, q in zip(first[1:], last[1:])]
            if all(fits(border(s), border(e)) for s, e in zip(middle, middle[1:] + [m])) \
                    and all(e > s for s, e in zip(middle, middle[1:] + [m])):
                starts = middle
        return [(border(s), border(e)) for s, e in zip(starts, starts[1:] + [m])]

    def layout(limit):
        def pieces_of(u_lo, u_hi):
            return cuts(grid_v, pieces,
                        lambda v_lo, v_hi: _reach(views, (u_lo, u_hi, v_lo, v_hi)).sum()
                        <= limit, v_range)

        bands = cuts(grid_u, strips, lambda a, b: pieces_of(a, b) is not None, u_range)
        if bands is None:
            return None
        cells = []
        for u_lo, u_hi in bands:
            for v_lo, v_hi in pieces_of(u_lo, u_hi):
                corners = [(u_lo, v_lo), (u_hi, v_lo), (u_hi, v_hi), (u_lo, v_hi)]
                if along == 1:
                    corners = [(b, a) for a, b in corners]
                rect = tuple((round(float(a), 6), round(float(b), 6)) for a, b in corners)
                cells.append(((u_lo, u_hi, v_lo, v_hi), rect))
        return cells

    lo, hi = 2, len(views)
    if layout(hi) is None:
        return None
    while lo < hi:
        mid = (lo + hi) // 2
        if layout(mid) is not None:
            hi = mid
        else:
            lo = mid + 1
    cells = layout(lo)
    if any(_reach(views, box).sum() < 2 for box, _ in cells):
        return None
    return cells
