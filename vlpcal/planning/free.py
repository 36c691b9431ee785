"""Beyond lattices: take cameras away and move the others on the mounting grid until the
layout meets the requirements again; repeat while it works.

Lattices waste cameras where the room is not a whole number of spacings, around L-corners and
pillars. Starting from a layout that meets the requirements (the best lattice), this local
search removes a whole column or row, else the camera whose loss hurts least, then repairs
the layout by moves that shrink its deficit: single cameras stepped 1, 2 or 4 grid cells in
eight directions or given a quarter turn, whole columns and rows shifted (re-spacing a
lattice whose spacing does not fit the room). The deficit counts sample points: those missing
from the coverage plus the covered points past the error bound beyond the 5 % a p95 allows;
zero means the layout meets the requirements. It is computed from the closed-form reference
model (:mod:`.nadir`) with cached per-camera contributions, so a move costs one pass over the
sample points. Cameras stay on the mounting grid inside the room polygon (no snapping after).

shapely is imported inside the functions that use it: importing planning for its types (as the
viewer and the demo do) loads no GEOS library.
"""

from __future__ import annotations

import math

import numpy as np

from ..triangulation import trace_adjugate_det
from .families import ceiling_cameras
from .lattice import Mounting
from .nadir import YAWS, NadirModel
from .site import footprint

#: single-camera moves: grid steps in eight directions at three lengths
DIRECTIONS = [(dx, dy) for dx in (-1, 0, 1) for dy in (-1, 0, 1) if dx or dy]
LENGTHS = (1, 2, 4)
#: cameras moved to repair a removal: within this many footprint diagonals of the gap
REACH = 1.0
TURN = {YAWS[0]: YAWS[1], YAWS[1]: YAWS[0]}
#: moves judged at once (memory: 7 × sample points floats each)
MOVE_BATCH = 128


class Layout:
    """Cameras on the mounting grid and the sum of their contributions to the model."""

    def __init__(self, model: NadirModel, step: float, cells, yaws, cache=None,
                 dtype=np.float64):
        from shapely.geometry import Polygon

        self.model, self.step = model, step
        self.mount = Mounting(model.site, step)
        self.x0, self.y0 = Polygon(model.site.room).bounds[:2]
        self.cells, self.yaws = [tuple(c) for c in cells], list(yaws)
        self.cache = {} if cache is None else cache
        self.inside = {}
        self.dtype = dtype
        #: contributions kept: about 256 MB of them
        self.capacity = max(64, int(2 ** 28 / (56 * model.n_points)))
        self.total = sum(self.contribution(c, y) for c, y in zip(self.cells, self.yaws))

    def copy(self, drop=()) -> Layout:
        """The same layout without the cameras ``drop`` (sharing the cache)."""
        out = Layout.__new__(Layout)
        out.__dict__.update(self.__dict__)
        keep = [i for i in range(len(self.cells)) if i not in set(drop)]
        out.cells, out.yaws = [self.cells[i] for i in keep], [self.yaws[i] for i in keep]
        out.total = self.total - sum(self.contribution(self.cells[i], self.yaws[i])
                                     for i in drop)
        return out

    def position(self, cell):
        return self.x0 + cell[0] * self.step, self.y0 + cell[1] * self.step

    def mountable(self, cell) -> bool:
        if cell not in self.inside:
            x, y = self.position(cell)
            self.inside[cell] = bool(self.mount(np.array([x]), np.array([y]))[0])
        return self.inside[cell]

    def contribution(self, cell, yaw):
        """7 × (L·P), P the sample points in the room: the 6 Fisher entries and the count a
        camera at ``cell`` adds, level after level (cached)."""
        key = (cell, yaw)
        got = self.cache.get(key)
        if got is None:
            while len(self.cache) >= self.capacity:  # least recently made first
                self.cache.pop(next(iter(self.cache)))
            got = self.model.camera_fisher(*self.position(cell), yaw).astype(self.dtype)
            self.cache[key] = got
        return got

    def deficit(self, total) -> int:
        """Sample points short of meeting the requirements (0: it meets them): points missing
        from the coverage, plus covered points whose predicted error passes the bound beyond
        the share a 95th percentile leaves (the exact percentile is then within the bound)."""
        return int(self.deficits(total[None])[0])

    def deficits(self, totals) -> np.ndarray:
        """:meth:`deficit` of a batch of sums, B × 7 × (L·P) → B."""
        m = self.model
        *F, count = np.moveaxis(totals, 1, 0)
        ok = count >= m.k - 0.5
        n = np.count_nonzero(ok, axis=-1)
        tr, det = trace_adjugate_det(*F)
        bad = np.count_nonzero(ok & (tr > m.bound ** 2 * det), axis=-1)
        allowed = np.where(n > 0, n - 1 - np.ceil(0.95 * (n - 1) - 1e-9), 0)
        short = max(0, math.ceil(m.need * m.n_points - 1e-9)) - n
        return np.maximum(short, 0) + np.maximum(bad - allowed, 0)

    def cameras(self):
        return ceiling_cameras(self.model.site, [self.position(c) for c in self.cells],
                               self.yaws)


def _groups(cells) -> list[tuple[int, list[int]]]:
    """The columns (axis 0) and rows (axis 1) of a layout: two or more cameras sharing a grid
    x or a grid y."""
    out = []
    for axis in (0, 1):
        keys = {}
        for i, c in enumerate(cells):
            keys.setdefault(c[axis], []).append(i)
        out += [(axis, g) for g in keys.values() if len(g) > 1]
    return out


def _moves(lay: Layout, near):
    """Candidate moves (camera indices, new cells, new yaws) of the cameras ``near``: single
    cameras stepped or turned, whole columns and rows (with a camera near) shifted along
    their normal."""
    for i in near:
        cell, yaw = lay.cells[i], lay.yaws[i]
        for k in LENGTHS:
            for dx, dy in DIRECTIONS:
                yield [i], [(cell[0] + dx * k, cell[1] + dy * k)], [yaw]
        yield [i], [cell], [TURN[yaw]]
    near = set(near)
    for axis, g in _groups(lay.cells):
        if near.isdisjoint(g):
            continue
        for k in (-1, 1, -2, 2):
            d = (k, 0) if axis == 0 else (0, k)
            yield g, [(lay.cells[i][0] + d[0], lay.cells[i][1] + d[1]) for i in g], \
                [lay.yaws[i] for i in g]


def _repair(lay: Layout, focus, reach: float, iterations: int, tenure: int = 3) -> bool:
    """Tabu search by :func:`_moves` on the cameras within ``reach`` (m) of ``focus``: each
    iteration takes the best move that does not touch a camera moved in the last ``tenure``
    iterations, even when it makes the deficit worse (so the search leaves a local minimum);
    the best layout seen is kept. True as soon as the layout meets the requirements."""
    d = best_d = lay.deficit(lay.total)
    best = (list(lay.cells), list(lay.yaws), lay.total)
    moved = {}
    for it in range(iterations):
        if d == 0:
            return True
        dist = [np.hypot(*np.subtract(lay.position(c), focus)) for c in lay.cells]
        near = [i for i in np.argsort(dist) if dist[i] <= reach]
        where = {(c, y): j for j, (c, y) in enumerate(zip(lay.cells, lay.yaws))}
        moves = [(idx, cells, yaws) for idx, cells, yaws in _moves(lay, near)
                 if not any(moved.get(i, -tenure - 1) >= it - tenure for i in idx)
                 and all(where.get((c, y), idx[0]) in idx for c, y in zip(cells, yaws))
                 and all(lay.mountable(c) for c in cells)]
        if not moves:
            break
        best_move, best_total, nd = None, None, None
        size = max(1, min(MOVE_BATCH, 2 ** 24 // lay.total.size))
        for start in range(0, len(moves), size):
            batch = moves[start:start + size]
            totals = np.empty((len(batch),) + lay.total.shape, lay.dtype)
            for b, (idx, cells, yaws) in enumerate(batch):
                t = totals[b]
                np.copyto(t, lay.total)
                for c, y in zip(cells, yaws):
                    t += lay.contribution(c, y)
                for i in idx:
                    t -= lay.contribution(lay.cells[i], lay.yaws[i])
            ds = lay.deficits(totals)
            b = int(np.argmin(ds))
            if nd is None or ds[b] < nd:
                nd, best_move, best_total = int(ds[b]), batch[b], totals[b].copy()
            if nd == 0:
                break
        d, lay.total = nd, best_total
        idx, cells, yaws = best_move
        for i, c, y in zip(idx, cells, yaws):
            lay.cells[i], lay.yaws[i] = c, y
            moved[i] = it
        if d < best_d:
            best_d, best = d, (list(lay.cells), list(lay.yaws), lay.total)
    lay.cells, lay.yaws, lay.total = best
    return best_d == 0


def fewer_cameras(search: NadirModel, exact: NadirModel, step: float, xy, yaws,
                  attempts: int = 3, iterations: int = 30):
    """Starting from a layout that meets the requirements (floor positions ``xy`` on the
    ``step`` grid from the room's lower-left corner), remove cameras — a whole column or row,
    else one camera — while a tabu search of ``iterations`` moves repairs the loss; per round
    the ``attempts`` least harmful removals of each kind are tried. The search judges by the
    ``search`` model (a coarser sample grid, for speed); a repaired layout is kept only when
    it meets the ``exact`` model too (repaired there if it must be). Returns the cameras of
    the smallest layout found that meets the requirements by the exact model."""
    caches = ({}, {})
    lay = Layout(search, step, _cells(search, step, xy), yaws, caches[0], np.float32)
    reach = float(np.hypot(*footprint(search.site))) * REACH
    while len(lay.cells) > search.k:
        groups = [g for _, g in _groups(lay.cells) if len(lay.cells) - len(g) >= search.k]
        singles = [[i] for i in range(len(lay.cells))]
        done = False
        for kind in (groups, singles):
            ranked = sorted(kind, key=lambda g: lay.deficit(lay.copy(g).total) / len(g))
            for g in ranked[:attempts]:
                trial = lay.copy(g)
                focus = np.mean([lay.position(lay.cells[i]) for i in g], axis=0)
                if not _repair(trial, focus, reach, iterations):
                    continue
                check = Layout(exact, step, trial.cells, trial.yaws, caches[1])
                if check.deficit(check.total) and not _repair(check, focus, reach,
                                                              max(1, iterations // 3)):
                    continue
                lay = Layout(search, step, check.cells, check.yaws, caches[0], np.float32)
                done = True
                break
            if done:
                break
        if not done:
            break
    return lay.cameras()


def snap(model: NadirModel, step: float, xy, yaws, iterations: int = 40) -> Layout | None:
    """A layout's cameras moved to the nearest free mountable cells of the ``step`` grid, and
    repaired by the tabu search's moves if that broke it; None if it cannot be repaired."""
    lay = Layout(model, step, [], [])
    cells, taken = [], set()
    for (i, j), yaw in zip(_cells(model, step, xy), yaws):
        ring = [(i, j)] + [(i + di, j + dj) for r in (1, 2, 3) for di in range(-r, r + 1)
                           for dj in range(-r, r + 1) if max(abs(di), abs(dj)) == r]
        cell = next((c for c in ring if (c, yaw) not in taken and lay.mountable(c)), None)
        if cell is None:
            return None
        cells.append(cell)
        taken.add((cell, yaw))
    lay = Layout(model, step, cells, yaws)
    if lay.deficit(lay.total) == 0:
        return lay
    centre = np.mean([lay.position(c) for c in cells], axis=0)
    return lay if _repair(lay, centre, np.inf, iterations) else None


def _cells(model: NadirModel, step: float, xy):
    """Floor positions → grid cells (rounded)."""
    from shapely.geometry import Polygon

    x0, y0 = Polygon(model.site.room).bounds[:2]
    xy = np.asarray(xy, float)
    return [(int(i), int(j)) for i, j in np.rint((xy - (x0, y0)) / step)]
