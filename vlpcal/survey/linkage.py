"""Whether a free survey can link every camera, judged from the geometry before anyone
measures.

A free calibration ties two cameras together only when they saw the free LED at
:data:`MIN_SHARED` moments or more; cameras no chain of such pairs joins are refused,
after the measuring. So the plan asks first, for every camera pair: where in the space the LED
can reach (the room minus its keep-out areas, from the sweep's foot to its top, and not behind
an obstacle) do both cameras see it, and would a stop there give the pair enough sightings?

A stop is one sweep of the LED from the foot up and back (:data:`SWEEP_SETS` moments), at a
place found by eye (within :data:`PLACING_SHARE` of a camera's floor footprint, so a pair whose
views meet in a strip narrower than that gets a share of the sweep only): the pair's expected
sightings there are the sweep's moments times the share of the sweep, over the places the LED
may land, that both cameras see. A pair is *linked* when its best stop, with the sweep kept as
low as the overlap reaches there, gives :data:`MIN_SHARED`; *thin* when only such a low
sweep does. Every size here is relative to the scene: the grid and the placing to the cameras'
footprint, the heights to the sweep.

One module, about 500 lines: the reach, the pairs' verdicts and the remedies all walk the same
sampled space (:class:`Reach`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import shapely
from shapely import MultiPoint, contains_xy, union_all
from shapely.geometry import Point, Polygon

from ..geometry import Camera
from .errors import SurveyError
from .free_checks import MIN_SHARED

#: moments one sweep records: from the foot to the top and back in about four seconds at the
#: capture's ten moments a second
SWEEP_SETS = 40
#: seconds one sweep takes (:data:`SWEEP_SETS` at ten a second)
SWEEP_SECONDS = 4.0
#: m/s: walking between stops with the LED held steady
WALK_SPEED = 0.5
#: a stop is found by eye, no tape, to within this share of a camera's floor footprint (the
#: footprint's shorter side): the LED lands anywhere in a square this far either side
PLACING_SHARE = 0.05
#: the floor grid has this many cells across a camera's footprint (its shorter side): a strip
#: of overlap a tenth of the footprint wide is six cells
CELLS_PER_FOOTPRINT = 60
#: at most this many floor cells (a large hall: a coarser grid)
MAX_CELLS = 40_000
#: heights one sweep is sampled at, foot and top included
SWEEP_LEVELS = 10
#: px: the LED is seen where it projects this far inside the image (the reference model's margin)
MARGIN_PX = 2.0
#: the LED reaches at most this share of the lowest camera's height (as survey plans allow)
REACH_SHARE = 0.9


def obstacles_of(deployment) -> list:
    """The deployment's obstacles that hide what is behind them: keep-out items given as
    ``{polygon: …, height: H}`` (docs/formats.md, the site file), as ``(polygon, H)``; a plain
    polygon is a floor area to leave out and hides nothing."""
    out = []
    for item in deployment.keep_out:
        if isinstance(item, dict) and "height" in item:
            out.append((item["polygon"], float(item["height"])))
    return out


def keep_out_polygons(deployment) -> list:
    """Every keep-out item's floor polygon (plain, or an obstacle's)."""
    return [item["polygon"] if isinstance(item, dict) else item for item in deployment.keep_out]


def footprint(cameras, height: float) -> float:
    """m: the median camera's floor footprint at ``height``, its shorter side — the yardstick
    of the grid and of a stop's placing."""
    return float(np.median([min(c.width / c.fx, c.height / c.fy) * (c.position[2] - height)
                            for c in cameras]))


@dataclass
class PairScore:
    """What one stop can give a camera pair: per sweep top (a level index ``m``), the best
    share of the sweep both see (``best[m]``, foot to level ``m``) and where (``where[m]``, a
    floor cell ``(iy, ix)``); ``air``: the cells of reachable space, up to the verdict's top,
    that both see."""

    best: np.ndarray
    where: np.ndarray
    air: int


@dataclass
class Reach:
    """The space a free LED can reach, sampled: a floor grid (cell centres ``xs``, ``ys``; the
    ``inside`` mask, room minus keep-out, ``Y×X``) at ``levels`` from the sweep's foot; the
    verdict's sweep ends at ``levels[top_index]``, the levels above are for what a taller sweep
    would do. ``seen``: ``C×L×Y×X``, each camera sees the LED there (in the image by
    :data:`MARGIN_PX`, not behind an obstacle). ``reach``: cells either side a stop's LED may
    land."""

    cameras: list
    xs: np.ndarray
    ys: np.ndarray
    inside: np.ndarray
    levels: np.ndarray
    top_index: int
    seen: np.ndarray
    reach: int
    step: float
    room: object = field(repr=False)
    margin_px: float = MARGIN_PX
    obstacles: list = field(default_factory=list, repr=False)
    outline: object = field(default=None, repr=False)  #: the room, keep-outs included
    _scores: dict = field(default_factory=dict, repr=False)  #: (k, j) → PairScore
    _spans: dict = field(default_factory=dict, repr=False)  #: k → its sightings' span

    @property
    def low(self) -> float:
        return float(self.levels[0])

    @property
    def top(self) -> float:
        return float(self.levels[self.top_index])

    def place(self, cell) -> np.ndarray:
        """The floor position (m) of a cell ``(iy, ix)``."""
        return np.array([self.xs[cell[1]], self.ys[cell[0]]])

    def cell(self, xy) -> tuple[int, int]:
        """The cell nearest a floor position."""
        return (int(np.clip(np.round((xy[1] - self.ys[0]) / self.step), 0, len(self.ys) - 1)),
                int(np.clip(np.round((xy[0] - self.xs[0]) / self.step), 0, len(self.xs) - 1)))

    def seen_by(self, camera) -> np.ndarray:
        """``L×Y×X``: where ``camera`` (any, e.g. one proposed) sees the LED — projected only
        within its view's bounding box (a large hall: a small share of the grid)."""
        out = np.zeros((len(self.levels),) + self.inside.shape, bool)
        (r0, r1), (c0, c1) = self._view_box(camera)
        inside = self.inside[r0:r1, c0:c1]
        gx, gy = np.meshgrid(self.xs[c0:c1], self.ys[r0:r1])
        xy = np.c_[gx[inside], gy[inside]]
        if not len(xy):
            return out
        for li, h in enumerate(self.levels):
            pts = np.c_[xy, np.full(len(xy), h)]
            ok = camera.project(pts, margin=self.margin_px)[2]
            if self.obstacles:
                ok &= ~_hidden(camera.center, pts, self.obstacles)
            out[li, r0:r1, c0:c1][inside] = ok
        return out

    def _view_box(self, camera):
        """Rows and columns (half-open) of the cells ``camera`` can see at any level: its
        image's border rays met at the lowest and highest level, padded by a cell; the whole
        grid when a ray misses a level (a view reaching the horizon)."""
        t = np.linspace(0.0, 1.0, 9)
        w, h = camera.width - 1.0, camera.height - 1.0
        uv = np.r_[np.c_[t * w, 0 * t], np.c_[t * w, 0 * t + h], np.c_[0 * t, t * h],
                   np.c_[0 * t + w, t * h]]
        xy = np.concatenate([camera.ground(uv, z) for z in (self.levels[0], self.levels[-1])])
        if not np.isfinite(xy).all():
            return (0, len(self.ys)), (0, len(self.xs))
        (x0, y0), (x1, y1) = xy.min(axis=0), xy.max(axis=0)
        cols = np.searchsorted(self.xs, [x0 - self.step, x1 + self.step])
        rows = np.searchsorted(self.ys, [y0 - self.step, y1 + self.step])
        return (int(rows[0]), int(rows[1])), (int(cols[0]), int(cols[1]))

    def score(self, a, b) -> PairScore:
        """:class:`PairScore` of cameras ``a``, ``b`` (indices into :attr:`cameras`, or ``L×Y×X``
        sightings of cameras not in it, bare or with their span); kept for indices."""
        key = ((min(a, b), max(a, b)) if all(isinstance(x, (int, np.integer)) for x in (a, b))
               else None)
        if key is not None and key in self._scores:
            return self._scores[key]
        (sa, (ra, ca)), (sb, (rb, cb)) = self._sighting(a), self._sighting(b)
        L = len(self.levels)
        s = PairScore(np.zeros(L), np.zeros((L, 2), int), 0)
        v0, v1, u0, u1 = max(ra[0], rb[0]), min(ra[1], rb[1]), max(ca[0], cb[0]), min(ca[1], cb[1])
        if v0 < v1 and u0 < u1:  # their views' boxes meet: the work in that window only
            w = self.reach
            v0, u0 = max(v0 - w, 0), max(u0 - w, 0)
            v1, u1 = v1 + w, u1 + w
            both = sa[:, v0:v1, u0:u1] & sb[:, v0:v1, u0:u1]
            if both.any():
                share = _box(both.astype(np.float32), w)  # L×y×x: a stop's landings both see
                mean = np.cumsum(share, axis=0) / np.arange(1, L + 1)[:, None, None]
                mean[:, ~self.inside[v0:v1, u0:u1]] = -1  # a stop stands on the floor
                flat = mean.reshape(L, -1)
                at = np.argmax(flat, axis=1)
                iy, ix = np.unravel_index(at, share.shape[1:])
                s = PairScore(flat[np.arange(L), at].clip(0), np.c_[iy + v0, ix + u0],
                              int(both[: self.top_index + 1].sum()))
        if key is not None:
            self._scores[key] = s
        return s

    def _sighting(self, x):
        """``(L×Y×X sightings, their span)`` of a camera index (span kept), a camera's
        sightings, or a pair ``(sightings, span)`` already spanned."""
        if isinstance(x, (int, np.integer)):
            if x not in self._spans:
                self._spans[x] = _span(self.seen[x])
            return self.seen[x], self._spans[x]
        if isinstance(x, tuple):
            return x
        return x, _span(x)

    @cached_property
    def views(self) -> tuple[list, list]:
        """Each camera's floor centre and convex hull of where it sees the LED at the sweep's
        foot (computed once: every group's remedy asks)."""
        return [_view_centre(self, s) for s in self.seen], [_view_hull(self, s) for s in self.seen]

    def stop_sets(self, cell, m: int, pairs) -> np.ndarray:
        """Expected moments each of ``pairs`` (index pairs) shares at a stop at ``cell`` whose
        sweep ends at level ``m``."""
        w = self.reach
        iy, ix = cell
        win = self.seen[:, : m + 1, max(iy - w, 0): iy + w + 1, max(ix - w, 0): ix + w + 1]
        if not len(pairs):
            return np.zeros(0)
        k, j = np.asarray(pairs).T
        both = (win[k] & win[j]).reshape(len(pairs), -1).sum(axis=1)
        return SWEEP_SETS * both / ((2 * w + 1) ** 2 * (m + 1))


def reach(deployment, low: float = 0.0, top: float | None = None, margin_px: float = MARGIN_PX,
          obstacles=None) -> Reach:
    """Sample the space a free LED can reach under ``deployment``'s cameras: from ``low`` to
    ``top`` (default 40 % of the ceiling's height) and on, at the same spacing, up to
    :data:`REACH_SHARE` of the lowest camera's height (what a taller sweep could do)."""

    cams = list(deployment.cameras)
    if not cams:
        raise SurveyError("the deployment has no cameras")
    top = 0.4 * deployment.ceiling_height if top is None else float(top)
    room = outline = Polygon(deployment.room)
    polys = keep_out_polygons(deployment)
    if polys:
        room = room.difference(union_all([Polygon(p).buffer(0) for p in polys]))
    if room.is_empty:
        raise SurveyError("the keep-out areas leave no floor to survey")
    ceiling = REACH_SHARE * min(c.position[2] for c in cams)
    size = footprint(cams, low)
    if not size > 0 or not top < min(c.position[2] for c in cams):
        raise SurveyError("the cameras are not above the free LED's heights")
    x0, y0, x1, y1 = room.bounds
    step = max(size / CELLS_PER_FOOTPRINT, np.sqrt((x1 - x0) * (y1 - y0) / MAX_CELLS))
    xs, ys = np.arange(x0 + step / 2, x1, step), np.arange(y0 + step / 2, y1, step)
    if not len(xs) or not len(ys):
        xs, ys = np.array([(x0 + x1) / 2]), np.array([(y0 + y1) / 2])
    gx, gy = np.meshgrid(xs, ys)
    inside = contains_xy(room, gx, gy)
    if top > low:
        d = (top - low) / (SWEEP_LEVELS - 1)
        levels = list(np.linspace(low, top, SWEEP_LEVELS))
    else:  # an LED at one height (a robot): above it, what a pole's sweep would do
        d = max(ceiling - low, 0.0) / (2 * (SWEEP_LEVELS - 1))
        levels = [low]
    top_index = len(levels) - 1
    d = max(d, (ceiling - low) / (2 * (SWEEP_LEVELS - 1)))  # above: at most twenty levels
    while d > 0 and levels[-1] + d <= ceiling + 1e-9 * d:
        levels.append(levels[-1] + d)
    obstacles = obstacles_of(deployment) if obstacles is None else list(obstacles)
    r = Reach(cams, xs, ys, inside, np.array(levels), top_index,
              np.zeros((len(cams), len(levels)) + inside.shape, bool),
              max(0, int(round(PLACING_SHARE * size / step))), float(step), room, margin_px,
              obstacles, outline)
    r.seen = np.stack([r.seen_by(c) for c in cams])
    return r


def _span(seen: np.ndarray):
    """The rows and columns (half-open ranges) of the floor cells where ``seen`` (L×Y×X) holds
    at any level; empty ranges when nowhere."""
    rows, cols = seen.any(axis=(0, 2)), seen.any(axis=(0, 1))
    if not rows.any():
        return (0, 0), (0, 0)
    r, c = np.flatnonzero(rows), np.flatnonzero(cols)
    return (int(r[0]), int(r[-1]) + 1), (int(c[0]), int(c[-1]) + 1)


def _box(a: np.ndarray, w: int) -> np.ndarray:
    """The mean over a square of ``2w+1`` cells about each cell, over the last two axes (cells
    beyond the grid count as nothing: the LED cannot land there)."""
    if w == 0:
        return a
    pad = np.pad(a, [(0, 0)] * (a.ndim - 2) + [(w + 1, w), (w + 1, w)])
    c = pad.cumsum(axis=-1).cumsum(axis=-2)
    n = 2 * w + 1
    s = c[..., n:, n:] - c[..., :-n, n:] - c[..., n:, :-n] + c[..., :-n, :-n]
    return s / n ** 2


def _hidden(centre, pts: np.ndarray, obstacles) -> np.ndarray:
    """``N``: the segment from a camera's ``centre`` to each point passes through an obstacle
    (a polygon ``H`` m tall, standing on the floor)."""

    pts = np.asarray(pts, float)
    out = np.zeros(len(pts), bool)
    cz = float(centre[2])
    for poly, height in obstacles:
        shape = Polygon(poly)
        below = pts[:, 2] < height
        if cz <= height:  # a camera inside the obstacle's height: the whole segment is low
            t0 = np.zeros(len(pts))
        else:
            with np.errstate(divide="ignore", invalid="ignore"):
                t0 = np.clip((cz - height) / (cz - pts[:, 2]), 0.0, 1.0)
        start = centre[:2] + t0[:, None] * (pts[:, :2] - centre[:2])  # where it dips below H
        bx0, by0, bx1, by1 = shape.bounds
        lo, hi = np.minimum(start, pts[:, :2]), np.maximum(start, pts[:, :2])
        near = below & (hi[:, 0] >= bx0) & (lo[:, 0] <= bx1) & (hi[:, 1] >= by0) & \
            (lo[:, 1] <= by1)
        idx = np.flatnonzero(near)
        if len(idx):
            lines = shapely.linestrings(np.stack([start[idx], pts[idx, :2]], axis=1))
            out[idx] |= shapely.intersects(lines, shape)
    return out


@dataclass(frozen=True)
class Remedy:
    """What would link a group of cameras to the others: a sweep up to ``sweep_top`` m (NaN:
    none within reach), or one more camera like theirs at ``camera_at`` (floor position, m; None:
    one is not enough)."""

    cameras: tuple
    low: float  #: m: the sweep's foot
    below: float  #: m: the verdict's top, below which nothing links them
    sweep_top: float
    camera_at: tuple | None
    gap: float  #: m: between their view and the others', at the sweep's foot (0: a sliver)

    def words(self) -> str:
        who = ", ".join(self.cameras)
        one = len(self.cameras) == 1
        where = (f"at {self.low:g} m" if self.below <= self.low else
                 f"below {self.below:.2f} m")
        said = (f"{who}: no other camera shares {'its' if one else 'their'} view enough for a "
                f"free LED {where} to link {'it' if one else 'them'}")
        fixes = []
        if np.isfinite(self.sweep_top):
            fixes.append(f"sweep up to {self.sweep_top:.2f} m")
        if self.camera_at is not None:
            fixes.append(f"add a camera near ({self.camera_at[0]:.2f}, "
                         f"{self.camera_at[1]:.2f}) m")
        if not fixes:
            apart = (f"their views are {self.gap:.2f} m apart" if self.gap > 0 else
                     "their views meet in a sliver")
            fixes.append(f"cameras between them and the others would ({apart} at "
                         f"{self.low:g} m)")
        return f"{said}; {' or '.join(fixes)}"


@dataclass
class Linkage:
    """The verdict: which cameras a free LED swept from ``low`` to ``top`` m can link.
    ``sets``: ``C×C``, the moments each pair shares at its best stop (the sweep kept as low as
    its overlap reaches there); ``full``: the same with the sweep to ``top``. ``groups``:
    camera ids of each linked group, the largest first; ``remedies`` for every other group."""

    camera_ids: list
    low: float
    top: float
    sets: np.ndarray
    full: np.ndarray
    groups: list
    remedies: list
    reach: Reach = field(repr=False)

    @property
    def linked(self) -> np.ndarray:
        """``C×C``: the pair's best stop gives it :data:`MIN_SHARED` moments or more."""
        return self.sets >= MIN_SHARED

    @property
    def all_linked(self) -> bool:
        return len(self.groups) <= 1

    @property
    def unlinked(self) -> list:
        """Ids of the cameras outside the largest linked group."""
        return [c for g in self.groups[1:] for c in g]

    @property
    def thin(self) -> list:
        """Linked pairs whose overlap a full sweep crosses too briefly: their stop's sweep stays
        low (``(id, id)``)."""
        ids = self.camera_ids
        k, j = np.nonzero(np.triu(self.linked & (self.full < MIN_SHARED), 1))
        return [(ids[a], ids[b]) for a, b in zip(k, j)]

    def sentences(self) -> list:
        """The verdict in a surveyor's words: one line when every camera is linked."""
        n = len(self.camera_ids)
        sweep = (f"a free LED swept from {self.low:g} to {self.top:.2f} m" if self.top > self.low
                 else f"a free LED at {self.low:g} m")
        thin = self.thin
        note = (f" ({len(thin)} thin overlap{'s' if len(thin) != 1 else ''}: "
                f"{', '.join(f'{a}+{b}' for a, b in thin[:6])}{' …' if len(thin) > 6 else ''}; "
                "the route sweeps low there)") if thin else ""
        if self.all_linked:
            return [f"{sweep} links all {n} cameras{note}"]
        out = [f"{sweep} cannot link all {n} cameras: {len(self.groups)} groups "
               f"({'; '.join(', '.join(g) for g in self.groups)}){note}"]
        return out + [r.words() for r in self.remedies]


def link_cameras(deployment, low: float = 0.0, top: float | None = None,
                 margin_px: float = MARGIN_PX, obstacles=None, at: Reach | None = None) -> Linkage:
    """Judge, from the geometry, which of ``deployment``'s cameras a free LED swept from ``low``
    to ``top`` m (default 40 % of the ceiling) can link (see the module), name the groups and
    what would link each group outside the largest: a taller sweep, another camera. ``at``: a
    :class:`Reach` already sampled."""
    r = at if at is not None else reach(deployment, low, top, margin_px, obstacles)
    cams, T = r.cameras, r.top_index
    C = len(cams)
    sets, full = np.zeros((C, C)), np.zeros((C, C))
    for k in range(C):
        for j in range(k + 1, C):
            s = r.score(k, j)
            sets[k, j] = sets[j, k] = SWEEP_SETS * s.best[: T + 1].max()
            full[k, j] = full[j, k] = SWEEP_SETS * s.best[T]
    groups = _components(sets >= MIN_SHARED)
    ids = [c.id for c in cams]
    remedies = [_remedy(r, g, [k for k in range(C) if k not in g]) for g in groups[1:]]
    return Linkage(ids, r.low, r.top, sets, full, [[ids[k] for k in g] for g in groups],
                   remedies, r)


def _components(linked: np.ndarray) -> list:
    """Connected groups of camera indices, the largest first (ties: in camera order)."""
    C = len(linked)
    label = -np.ones(C, int)
    groups = []
    for s in range(C):
        if label[s] >= 0:
            continue
        label[s] = len(groups)
        todo, g = [s], [s]
        while todo:
            k = todo.pop()
            for j in np.flatnonzero(linked[k]):
                if label[j] < 0:
                    label[j] = label[s]
                    todo.append(int(j))
                    g.append(int(j))
        groups.append(sorted(g))
    return sorted(groups, key=lambda g: (-len(g), g[0]))


def _view_centre(r: Reach, seen: np.ndarray) -> np.ndarray:
    """The floor centre of where a camera sees the LED at the sweep's foot (NaN: nowhere)."""
    iy, ix = np.nonzero(seen[0])
    if not len(iy):
        return np.full(2, np.nan)
    return np.array([r.xs[ix].mean(), r.ys[iy].mean()])


def _view_hull(r: Reach, seen: np.ndarray):
    """Where a camera sees the LED at the sweep's foot, as a convex floor polygon."""
    iy, ix = np.nonzero(seen[0])
    return MultiPoint(np.c_[r.xs[ix], r.ys[iy]]).convex_hull


def _remedy(r: Reach, group, main) -> Remedy:
    """What would link ``group`` (camera indices) to the cameras ``main`` (the others): the
    lowest sweep top, above the verdict's, at which a pair of one of each is linked; a camera
    like theirs between the nearest views that both a camera of the group and one of the
    others would share enough with."""
    T, cams = r.top_index, r.cameras
    need = MIN_SHARED / SWEEP_SETS
    tops = [int(np.argmax(np.maximum.accumulate(r.score(g, h).best) >= need))
            for g in group for h in main
            if (np.maximum.accumulate(r.score(g, h).best) >= need).any()]
    sweep_top = float(r.levels[min(tops)]) if tops else float("nan")
    centres, hulls = r.views
    near = sorted(((np.linalg.norm(centres[g] - centres[h]), g, h) for g in group for h in main
                   if np.isfinite(centres[g]).all() and np.isfinite(centres[h]).all()),
                  key=lambda t: t[0])
    gaps = [hulls[g].distance(hulls[h]) for g in group for h in main
            if not hulls[g].is_empty and not hulls[h].is_empty]
    gap = float(min(gaps)) if gaps else float("nan")
    at = None
    for _, g, h in near[:4]:
        model = cams[g]
        z = (cams[g].position[2] + cams[h].position[2]) / 2
        for f in (0.5, 0.35, 0.65):
            xy = centres[g] + f * (centres[h] - centres[g])
            ceiling = r.outline if r.outline is not None else r.room  # hung over anything
            if not ceiling.buffer(r.step).contains(Point(*xy)):
                continue
            axis = model.ground(np.array([[model.cx, model.cy]]), r.low)[0]
            offset = model.center[:2] - axis if np.isfinite(axis).all() else np.zeros(2)
            new = Camera("new", model.width, model.height, model.fx, model.fy, model.cx,
                         model.cy, model.dist, (*(xy + offset), z), model.rotation)
            seen = r.seen_by(new)
            spanned = (seen, _span(seen))
            links = [r.score(spanned, k).best[: T + 1].max() >= need for k in (*group, *main)]
            if any(links[: len(group)]) and any(links[len(group):]):
                at = (round(float(xy[0] + offset[0]), 2), round(float(xy[1] + offset[1]), 2))
                break
        if at is not None:
            break
    return Remedy(tuple(cams[k].id for k in group), r.low, r.top, sweep_top, at, gap)
