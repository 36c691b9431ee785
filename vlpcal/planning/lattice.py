"""Exhaustive search over a family's lattices, clipped to the room: every spacing and offset on
a grid of ``step``, both camera yaws, judged by the closed-form reference model
(:mod:`.nadir`) in batches.

A lattice is one or two rectangular sublattices (periods A × B, a shift each): ``square`` is
the rectangular lattice (a × b, a ≠ b allowed), ``triangular`` rows a·√3/2 apart with every
other row shifted by a/2 (rows along x or along y), ``linear`` a single row (along x or y).
A lattice's cameras are its points inside the room polygon (cameras hang from the ceiling;
keep-out areas are floor obstacles). Layouts are visited by ascending camera count; once one
meets the requirements, only layouts with as few cameras are judged further.

shapely is imported inside the functions that use it: importing planning for its types (as the
viewer and the demo do) loads no GEOS library.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from .families import Candidate, ceiling_area, ceiling_cameras
from .nadir import YAWS, NadirModel
from .reference import evaluate
from .site import Site, footprint

#: spacings searched, as shares of the footprint at the highest LED height along that axis
SPACING_RANGE = (0.25, 1.1)
#: share of the coverage a screened layout may miss on the coarse grid and still be judged
SCREEN_SLACK = 0.02
#: lattices judged at once, at most (memory: 6 × levels × batch × sample points floats)
BATCH = 96
#: values per batch array (6 × levels × batch × sample points: 64 MB of floats): a large room
#: judges fewer lattices at once, so that its memory does not grow with the room
BATCH_VALUES = 2 ** 23


@dataclass
class Lattice:
    """One spacing of one family: its sublattices and the offsets to try."""

    family: str
    spacing: tuple  #: m, (a,) or (a, b)
    yaw: float
    periods: tuple  #: (A, B) m, of every sublattice
    shifts: tuple  #: ((sx, sy), …) m
    offsets: np.ndarray  #: K × 2, m, from the room's lower-left corner


@dataclass
class SearchResult:
    """The best layout a search found (None if none meets) and what it cost."""

    best: Candidate | None
    judged: int  #: layouts whose coverage was computed
    layouts: int  #: layouts enumerated
    seconds: float


def _grid(lo: float, hi: float, step: float) -> np.ndarray:
    """Multiples of ``step`` in [lo, hi] (so positions stay on the mounting grid)."""
    return step * np.arange(math.ceil(lo / step - 1e-9), math.floor(hi / step + 1e-9) + 1)


def lattices(site: Site, family: str, step: float, yaws=YAWS):
    """Every spacing (multiples of ``step`` within :data:`SPACING_RANGE` of the footprint) and
    yaw of a family, with its offsets on the ``step`` grid within one period."""
    from shapely.geometry import Polygon

    fw0, fd0 = footprint(site)
    x0, y0, x1, y1 = Polygon(site.room).bounds
    lo, hi = SPACING_RANGE
    for yaw in yaws:
        fw, fd = (fw0, fd0) if not yaw else (fd0, fw0)
        # a spacing longer than the room holds one column (or row): no need to try more
        A = _grid(min(lo * fw, x1 - x0), min(hi * fw, x1 - x0 + step), step)
        B = _grid(min(lo * fd, y1 - y0), min(hi * fd, y1 - y0 + step), step)
        if family == "square":
            specs = [((a, b), (a, b), ((0.0, 0.0),)) for a in A for b in B]
        elif family == "triangular":
            tri = [(a, a * math.sqrt(3) / 2) for a in A]
            specs = [((a,), (a, 2 * h), ((0.0, 0.0), (a / 2, h))) for a, h in tri
                     if lo * fd <= h <= hi * fd]
            tri = [(b, b * math.sqrt(3) / 2) for b in B]
            specs += [((b,), (2 * h, b), ((0.0, 0.0), (h, b / 2))) for b, h in tri
                      if lo * fw <= h <= hi * fw]
        elif family == "linear":
            specs = [((a,), (a, y1 - y0 + step), ((0.0, 0.0),)) for a in A]
            specs += [((b,), (x1 - x0 + step, b), ((0.0, 0.0),)) for b in B]
        else:
            raise ValueError(f"unknown family {family!r}")
        for spacing, (pa, pb), shifts in specs:
            ox, oy = np.meshgrid(_grid(0, pa - step / 2, step), _grid(0, pb - step / 2, step))
            yield Lattice(family, spacing, yaw, (pa, pb), shifts,
                          np.c_[ox.ravel(), oy.ravel()] + (x0, y0))


class Mounting:
    """Whether floor positions can carry a camera: inside the room polygon less the site's
    wall clearance, its edges included (a camera body a few centimetres across hangs against
    the wall; the model's sample grid does not resolve the difference). A raster lookup for
    positions on the ``step`` grid from the room's lower-left corner, the polygon itself for
    the others."""

    def __init__(self, site: Site, step: float):
        from shapely import contains_xy
        from shapely.geometry import Polygon

        room = ceiling_area(site)
        self.x0, self.y0, self.x1, self.y1 = Polygon(site.room).bounds
        self.room = room.buffer(1e-9 * max(1.0, self.x1 - self.x0, self.y1 - self.y0))
        self.step = step
        self.rectangle = room.envelope.equals(room) and room.bounds == Polygon(site.room).bounds
        gx, gy = np.meshgrid(np.arange(math.floor((self.x1 - self.x0) / step + 1e-9) + 1),
                             np.arange(math.floor((self.y1 - self.y0) / step + 1e-9) + 1),
                             indexing="ij")
        self.raster = contains_xy(self.room, self.x0 + gx * step, self.y0 + gy * step)

    def __call__(self, X, Y) -> np.ndarray:
        from shapely import contains_xy

        eps = 1e-9 * max(1.0, self.x1 - self.x0, self.y1 - self.y0)
        box = (X >= self.x0 - eps) & (X <= self.x1 + eps) & (Y >= self.y0 - eps) \
            & (Y <= self.y1 + eps)
        if self.rectangle:
            return box
        out = np.zeros(X.shape, bool)
        i, j = (X[box] - self.x0) / self.step, (Y[box] - self.y0) / self.step
        ri, rj = np.rint(i), np.rint(j)
        on = (np.abs(i - ri) < 1e-6) & (np.abs(j - rj) < 1e-6)
        inside = np.empty(len(i), bool)
        inside[on] = self.raster[ri[on].astype(int), rj[on].astype(int)]
        inside[~on] = contains_xy(self.room, X[box][~on], Y[box][~on])
        out[box] = inside
        return out


def _points(mount: Mounting, lat: Lattice, offsets: np.ndarray):
    """Per sublattice: columns (K × I), rows (K × J) and the mounted mask (K × I × J)."""
    (pa, pb) = lat.periods
    ni = int((mount.x1 - mount.x0) / pa) + 3
    nj = int((mount.y1 - mount.y0) / pb) + 3
    out = []
    for sx, sy in lat.shifts:
        cols = offsets[:, :1] + sx + pa * np.arange(-1, ni - 1)
        rows = offsets[:, 1:] + sy + pb * np.arange(-1, nj - 1)
        X = np.broadcast_to(cols[:, :, None], (len(offsets), ni, nj))
        Y = np.broadcast_to(rows[:, None, :], (len(offsets), ni, nj))
        out.append((cols, rows, mount(X, Y)))
    return out


def _covering(model: NadirModel, lat: Lattice, subs, slack: float = 0.0) -> np.ndarray:
    """Which layouts of a batch reach the coverage (less ``slack``): the highest LED height
    first (it binds first); a layout leaves as soon as the levels left cannot make up its
    deficit."""
    need = (model.need - slack) * model.n_points - 1e-9
    per_level = int(model.inside.sum())
    alive = np.arange(len(subs[0][0]))
    got = np.zeros(len(alive))
    for done, level in enumerate(reversed(range(len(model.levels)))):
        part = [(c[alive], r[alive], m[alive]) for c, r, m in subs]
        n = sum(model.lattice_sums(c, r, m, lat.yaw, level, ((0, 0),))[0] for c, r, m in part)
        got = got + model.covered(n)
        left = len(model.levels) - done - 1
        keep = got + left * per_level >= need
        alive, got = alive[keep], got[keep]
        if not len(alive):
            break
    return alive


def _verdict(model: NadirModel, lat: Lattice, subs):
    """The reference model's verdict on a batch of layouts of one lattice."""
    counts, Fs = [], []
    for level in range(len(model.levels)):
        S = [sum(t) for t in zip(*(model.lattice_sums(c, r, m, lat.yaw, level)
                                   for c, r, m in subs))]
        F, n = model.fisher({lat.yaw: S}, level)
        Fs.append(F)
        counts.append(n)
    return model.judge(np.stack(Fs), np.stack(counts))


def _cameras(site: Site, lat: Lattice, subs, b: int):
    """The cameras of layout ``b`` of a judged batch, row by row."""
    xy = np.concatenate([np.c_[np.broadcast_to(c[b][:, None], m[b].shape)[m[b] > 0],
                               np.broadcast_to(r[b][None, :], m[b].shape)[m[b] > 0]]
                         for c, r, m in subs])
    xy = xy[np.lexsort((xy[:, 0], xy[:, 1]))]
    return ceiling_cameras(site, xy, [lat.yaw] * len(xy))


def lattice_search(site: Site, families=("square",), step: float = 0.05,
                   model: NadirModel | None = None, fewest: int | None = None,
                   screen: NadirModel | None = None, progress=None) -> SearchResult:
    """The fewest cameras of any lattice of ``families`` (spacings and offsets on a ``step``
    grid, both yaws) that meets the site's requirements, the lowest predicted p95 among them;
    the winner is judged again by :func:`evaluate`. ``fewest``: ignore layouts with more
    cameras than this (a known answer to beat or match). ``screen``: a model on a coarser
    sample grid that drops layouts more than :data:`SCREEN_SLACK` short of the coverage
    first (a heuristic: the exhaustive baseline runs without it)."""
    t0 = time.perf_counter()
    model = model or NadirModel(site)
    mount = Mounting(site, step)
    specs = []
    for family in families:
        for lat in lattices(site, family, step):
            subs = _points(mount, lat, lat.offsets)
            counts = sum(m.sum(axis=(1, 2)) for _, _, m in subs)
            specs.append((int(counts.min()), lat, counts, subs))
    specs.sort(key=lambda s: s[0])
    best = None  # (count, p95, lattice, subs, b)
    limit = fewest if fewest is not None else 10 ** 9
    judged = layouts = 0
    for i, (low, lat, counts, every) in enumerate(specs):
        layouts += len(counts)
        if low > limit:
            continue
        idx = np.flatnonzero(counts <= limit)
        batch = max(1, min(BATCH, BATCH_VALUES // (6 * len(model.levels)
                                                    * model.inside.size)))
        for start in range(0, len(idx), batch):
            chunk = idx[start:start + batch]
            subs = [(c[chunk], r[chunk], m[chunk].astype(float)) for c, r, m in every]
            judged += len(chunk)
            if screen is not None:
                keep = _covering(screen, lat, subs, SCREEN_SLACK)
                subs = [(c[keep], r[keep], m[keep]) for c, r, m in subs]
                chunk = chunk[keep]
                if not len(chunk):
                    continue
            keep = _covering(model, lat, subs)
            if not len(keep):
                continue
            subs = [(c[keep], r[keep], m[keep]) for c, r, m in subs]
            v = _verdict(model, lat, subs)
            for k in np.flatnonzero(v.meets):
                n = int(counts[chunk[keep[k]]])
                if best is None or (n, v.p95[k]) < best[:2]:
                    best = (n, float(v.p95[k]), lat, subs, k)
                    limit = n
        if progress:
            progress(i + 1, len(specs), best[0] if best else None)
    if best is None:
        return SearchResult(None, judged, layouts, time.perf_counter() - t0)
    n, _, lat, subs, k = best
    cams = _cameras(site, lat, subs, k)
    xs = sorted({round(c.position[0], 9) for c in cams})
    ys = sorted({round(c.position[1], 9) for c in cams})
    cand = Candidate(lat.family, len(xs), len(ys), lat.spacing, tuple(cams[0].position[:2]),
                     lat.yaw, cams, evaluate(site, cams))
    return SearchResult(cand, judged, layouts, time.perf_counter() - t0)
