"""Fewer cameras by tilting them: from a layout that meets the requirements, take one camera
away and let the CasADi optimiser (:mod:`.optimiser`) move, turn and tilt the others until the
smooth model meets again; snap the answer to what an installer can set and judge it by the
exact reference model; repeat while it meets.

Each count is tried from several starts: the last layout that met less its least useful
camera (by the exact model), and grids of that many cameras over the ceiling whose outer
cameras lean inward (the grid families as seeds). The first start whose snapped answer meets
wins the count.

shapely is imported inside the functions that use it: importing planning for its types (as the
viewer and the demo do) loads no GEOS library.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from ..triangulation import trace_adjugate_det
from .families import Candidate, ceiling_area
from .nadir import PAIRS
from .optimiser import PoseProblem, Solve, optimiser_step
from .poses import pose_of, posed_cameras, snapped
from .reference import evaluate, sample_points, seen_by
from .site import Site

#: the grid seeds tried per count, best aspect first
GRID_SEEDS = 2
#: share of max_tilt the grid seeds' outer cameras start with
SEED_LEAN = 0.7
#: a mend tries at most this many times the cameras it started from
MEND_GROWTH = 2


@dataclass
class TiltedPlan:
    """What the tilted search found: the fewest cameras that met (None if no count below the
    start did), every solve, and the time."""

    best: Candidate | None
    solves: list[Solve] = field(default_factory=list)
    seconds: float = 0.0
    complete: bool = True  #: False when the time allowed ran out before the search ended
    start: int = 0  #: cameras of the layout it started from
    repaired: bool = False  #: the start did not meet the requirements; the search mended it


def tilted_plan(site: Site, start: Candidate, step: float, max_tilt: float,
                progress=None, seconds: float = math.inf, most: int = 0,
                least: int = 0) -> TiltedPlan:
    """The fewest cameras below ``start.count`` that meet the requirements with tilts up to
    ``max_tilt`` (rad; 0: level cameras moved and turned freely), positions on the ``step``
    mounting grid; stops after ``seconds``; never tries fewer than ``least`` (a lower bound).

    A start that does not meet (a lattice whose obstacles' shadows or lens distortion the
    lattice search left out) is repaired first: the same count, then one camera more at a
    time up to ``most``, until a layout meets. Then the counts tried gallop down (1, 2, 4, …
    fewer while each meets) and bisect between the fewest that met and the most that did
    not."""
    from shapely.geometry import Polygon

    t0 = time.perf_counter()
    say = progress or (lambda m: None)
    mending = not start.evaluation.meets
    # a mend gallops up to twice the start at most: memory grows with cameras × points
    most = min(max(most, start.count), MEND_GROWTH * start.count) if mending else start.count
    coarse = optimiser_step(site, most)
    points = sample_points(site, coarse)
    area = ceiling_area(site)
    bounds = area.bounds
    corner = Polygon(site.room).bounds[:2]  # the mounting grid's origin
    out = TiltedPlan(None, start=start.count, repaired=mending)
    kind = "tilted" if max_tilt > 0 else "free"
    problems = {}  # n → PoseProblem

    def out_of_time():
        return time.perf_counter() - t0 >= seconds

    def judge(poses):
        poses = _mounted(area, snapped(poses, step, max_tilt, *corner), step, corner)
        cams = posed_cameras(site, poses)
        if not evaluate(site, cams, coarse).meets:  # a quick look on the coarser grid
            return None
        ev = evaluate(site, cams)
        return (poses, cams, ev) if ev.meets else None

    def attempt(n, base) -> Attempt:
        first = [] if n > len(base) else [
            (f"the {len(base)}-camera layout less {len(base) - n}" if n < len(base) else
             f"the {len(base)}-camera layout", _less(site, base, len(base) - n, points))]
        for name, seed in first + \
                [(f"a {nx}×{ny} grid", _grid_seed(area, nx, ny, n, SEED_LEAN * max_tilt))
                 for nx, ny in _grid_shapes(area, n)]:
            if out_of_time():
                return Attempt(Outcome.OUT_OF_TIME)
            if n not in problems:
                problems[n] = PoseProblem(site, n, points)
            s = problems[n].solve(seed, bounds, max_tilt, judge, t0 + seconds)
            out.solves.append(s)
            got = s.judged or (None if s.late else judge(s.poses))
            say(f"  {kind} {n}: from {name}, {s.iterations} iterations, {s.seconds:.1f} s"
                + (" — meets" if got else " — out of time" if s.late else " — does not meet"))
            if got:
                return Attempt(Outcome.MET, *got, from_grid=name.startswith("a "))
            if s.late:
                return Attempt(Outcome.OUT_OF_TIME)
        return Attempt(Outcome.NOT_MET)

    def won(a: Attempt, family: str) -> str:
        family = "square" if a.from_grid else family  # the grid seeds are square lattices
        out.best = Candidate(kind, 0, 0, (), tuple(a.cameras[0].position[:2]), 0.0,
                             a.cameras, a.evaluation, seed=family)
        return family

    best = np.array([pose_of(c) for c in start.cameras])
    family, stride = start.family, 1
    fewest_bad = max(site.requirements.min_cameras, least) - 1
    if mending:
        got, failed = _repaired(attempt, best, most)
        if got.outcome is not Outcome.MET:
            out.seconds, out.complete = time.perf_counter() - t0, got.outcome is Outcome.NOT_MET
            return out
        best, family = got.poses, won(got, family)
        fewest_bad = max(fewest_bad, failed)
    timed_out = False
    while len(best) - fewest_bad > 1:
        galloping = fewest_bad == max(site.requirements.min_cameras, least) - 1
        n = max(len(best) - stride, fewest_bad + 1) if galloping \
            else (len(best) + fewest_bad + 1) // 2
        got = attempt(n, best)
        if got.outcome is Outcome.OUT_OF_TIME:
            timed_out = True
            break
        if got.outcome is Outcome.NOT_MET:
            fewest_bad = n
            continue
        best, family = got.poses, won(got, family)
        stride *= 2
    out.seconds = time.perf_counter() - t0
    out.complete = not timed_out
    return out


class Outcome(Enum):
    """How one count's attempt ended."""

    MET = "met"
    NOT_MET = "not met"  #: every start was solved and judged; none met
    OUT_OF_TIME = "out of time"  #: the time allowed ran out first: nothing is known


@dataclass
class Attempt:
    """One count's attempt: how it ended and, when a layout met, the layout."""

    outcome: Outcome
    poses: np.ndarray | None = None
    cameras: list | None = None
    evaluation: object = None
    from_grid: bool = False  #: the winning start was a grid seed (else the layout less some)


def _repaired(attempt, start, most: int):
    """The first count at which a solve meets, galloping up from the start's (n, then 1, 2,
    4, … more, up to ``most``), and the last count that did not meet: ``attempt(n, start)`` →
    :class:`Attempt`. The attempt that ended the gallop is returned as it is (not met, or
    out of time)."""
    n, step, failed, top = len(start), 1, 0, max(most, len(start))
    while True:
        got = attempt(n, start)
        if got.outcome is not Outcome.NOT_MET or n >= top:
            return got, failed
        failed, n, step = n, min(n + step, top), step * 2


def _information(site: Site, cams, points):
    """Each camera's share of the reference model at ``points``: which it sees (C×N) and its
    Fisher entries ``JᵀJ / σ²`` there (C×N×6, zero where unseen)."""
    seen = seen_by(site, cams, points)
    info = np.zeros(seen.shape + (6,))
    for k, cam in enumerate(cams):
        if seen[k].any():
            J = cam.jacobian(points[seen[k]])
            info[k, seen[k]] = np.stack([(J[:, :, i] * J[:, :, j]).sum(axis=1)
                                         for i, j in PAIRS], axis=-1)
    return seen, info / site.requirements.pixel_noise ** 2


def _met(site: Site, views, info) -> np.ndarray:
    """Per point (…×N): seen by enough cameras within the error bound, from the summed views
    (…×N) and Fisher entries (…×N×6)."""
    r = site.requirements
    tr, det = trace_adjugate_det(*np.moveaxis(info, -1, 0))
    with np.errstate(invalid="ignore", divide="ignore"):
        ok = (det > 0) & (tr / det <= r.max_error_p95 ** 2)
    return (views >= r.min_cameras) & ok


def _less(site: Site, poses, k: int, points) -> np.ndarray:
    """The layout without the ``k`` cameras whose loss, one at a time, hurts it least (the
    share of ``points`` it still serves within the requirements)."""
    if k <= 0:
        return poses
    seen, info = _information(site, posed_cameras(site, poses), points)
    views, total = seen.sum(axis=0), info.sum(axis=0)
    scores = np.concatenate([  # a few cameras at a time: memory stays that of `info`
        _met(site, views[None] - seen[i:i + 16], total[None] - info[i:i + 16]).mean(axis=1)
        for i in range(0, len(poses), 16)])
    return np.delete(poses, np.argsort(-scores, kind="stable")[:k], axis=0)


def _grid_shapes(area, n: int):
    """Columns × rows for ``n`` cameras whose cells are closest to square over the ceiling's
    bounding box (a last row may be short by less than a row)."""
    x0, y0, x1, y1 = area.bounds
    w, h = max(x1 - x0, 1e-9), max(y1 - y0, 1e-9)
    shapes = []
    for nx in range(1, n + 1):
        ny = math.ceil(n / nx)
        if nx * ny - n >= nx or (ny > 1 and nx * ny - n >= ny and nx > 1):
            continue
        cell = (w / nx) / (h / ny)
        shapes.append((abs(math.log(cell)), nx, ny))
    return [(nx, ny) for _, nx, ny in sorted(shapes)[:GRID_SEEDS]]


def _grid_seed(area, nx: int, ny: int, n: int, lean: float) -> np.ndarray:
    """``n`` cameras on an nx × ny grid of cell centres over the ceiling's bounding box, each
    leaning toward the room's middle by up to ``lean`` (rad) in proportion to how far out it
    hangs; a short last row is centred."""
    x0, y0, x1, y1 = area.bounds
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    out = []
    for j in range(ny):
        k = min(nx, n - j * nx)
        for i in range(k):
            x = x0 + (i + 0.5 + (nx - k) / 2) * (x1 - x0) / nx
            y = y0 + (j + 0.5) * (y1 - y0) / ny
            dx, dy = cx - x, cy - y
            reach = math.hypot((x1 - x0) / 2, (y1 - y0) / 2)
            d = math.hypot(dx, dy)
            theta = lean * d / reach if d > 1e-9 else 0.0
            # the axis leans along (dx, dy): w = θ·(dy, −dx)/d (see .poses)
            w = (theta * dy / d, -theta * dx / d) if d > 1e-9 else (0.0, 0.0)
            out.append((x, y, 0.0, *w))
    return np.array(out)


def _mounted(area, poses, step: float, corner) -> np.ndarray:
    """Poses moved onto the ceiling where they may hang: a position outside ``area`` goes to
    the nearest mounting-grid point inside it."""
    from shapely import contains_xy
    from shapely.geometry import Point
    from shapely.ops import nearest_points

    poses = poses.copy()
    x0, y0 = corner
    inside = contains_xy(area.buffer(1e-9), poses[:, 0], poses[:, 1])
    for k in np.flatnonzero(~inside):
        near = nearest_points(area, Point(poses[k, 0], poses[k, 1]))[0]
        cand = np.array([(x0 + step * (round((near.x - x0) / step) + i),
                          y0 + step * (round((near.y - y0) / step) + j))
                         for i in (-1, 0, 1) for j in (-1, 0, 1)])
        ok = contains_xy(area.buffer(1e-9), cand[:, 0], cand[:, 1])
        if ok.any():
            cand = cand[ok]
            best = np.argmin(np.hypot(cand[:, 0] - near.x, cand[:, 1] - near.y))
            poses[k, :2] = cand[best]
        else:
            poses[k, :2] = near.x, near.y
    return poses


__all__ = ["Attempt", "Outcome", "TiltedPlan", "tilted_plan"]
