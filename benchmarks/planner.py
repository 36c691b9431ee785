"""`vlpcal plan` against a fine exhaustive search over rectangular lattices, on six sites.

The baseline: every rectangular lattice (spacings a ≠ b on a 5 cm grid from 0.25 to 1.1
footprints, offsets on a 5 cm grid within one period, camera yaw 0° and 90°), its cameras
clipped to the room, judged by the reference model (docs/conventions.md) in closed form; layouts are
visited by ascending camera count, and once one meets the requirements only layouts with as
few cameras are judged. Its winner is judged again by `evaluate` (the model's reference
implementation). The planner: `plan_site` as `vlpcal plan` runs it (lattices of every family
on the 10 cm mounting grid, then the local search beyond lattices; without the what-if of
tilting a level site's plan adds, which the tilt table below covers), its answer judged by
`evaluate` as well. Both run here, in the same process, one core, on the same sites:

- the three earlier sites (a 4 × 3 m rectangle, a 5 × 4 m L-shape with a pillar, a 10 × 1.6 m
  corridor; 160 × 120 px cameras, LED 0–0.35 m, p95 ≤ 2 cm at 0.3 px);
- a 6 × 3.6 m bay under 2.8 m (160 × 120 px, LED 0–0.5 m, p95 ≤ 2 cm);
- an L-shaped 7 × 6 m room with a 0.5 m pillar (320 × 240 px at 3.2 m, LED 0–0.8 m,
  p95 ≤ 1.5 cm);
- a 10 × 8 m hall under 3 m (160 × 120 px, LED 0–0.3 m): the planner must finish in 60 s.

All sites ask k = 2 cameras over 95 % of the sample points. Prints a table.

Tilt (the same run): every site above and two more — a 7 × 4.5 m room under 3 m with a 0.5 m
pillar to the ceiling and a 2 × 0.4 m shelf 1.8 m tall along a wall (obstacles: they hide
what is behind them; 160 × 120 px, LED 0–0.5 m, p95 ≤ 2 cm), and a wide-lens 8 × 5 m room
under 3 m (160 × 120 px at fx = fy = 40, LED 0–0.5 m, p95 ≤ 2 cm) — are planned again with
``mounting: {max_tilt: 30°}`` (``plan_site``, one run, timed; every candidate judged by
``evaluate``) beside the level plan, and against the strongest simple tilted baseline: an
exhaustive search over rectangular nx × ny grids spanning the room's bounding box, cameras at
the cells' centres or with the outer ones on the walls (``linspace(x0, x1, nx)``), grid
cameras outside the room polygon dropped, every camera at yaw 0° or every one at 90°, the
outer columns leaning inward by one angle and the outer rows by another (each on a 5° grid
from 0 to 30°; a corner camera leans diagonally, by both, its tilt capped at 30°). Layouts go
by ascending camera count; each count's layouts are screened on a 20 cm sample grid (the
reference model vectorised over the 49 lean pairs, coverage 2 points and p95 10 % of slack),
the screened ones judged on the full grid best first, and the first that meets is confirmed
by ``evaluate``; counts start at a lower bound on any layout with tilts up to 30° (the "≥"
column: the sample points a camera's largest tilted footprint holds at the highest LED
height, see :func:`tilted_lower_bound`). The wide-lens room also gets a hand layout: 4 × 2
cameras on the walls, leaning 10° inward (``evaluate``). A second table, and these checks
(yes/NO lines):

- with tilt up to 30° the bay needs ≤ 9 cameras;
- the tilted plan needs strictly fewer cameras than the level plan on at least five sites,
  and never more;
- the tilted plan never needs more cameras than the tilted baseline;
- every exported plan (each candidate of the level and of the tilted plan) meets by
  ``evaluate``;
- the wide-lens room's tilted plan needs ≤ 8 cameras;
- the pillar + shelf room's plans (level and tilted) meet with the obstacles' shadows
  counted (``evaluate``);
- the hall with tilt is planned within 60 s.

Writes every figure to benchmarks/out/planner.json. Exits 1 if the planner needs more
cameras than the lattice baseline on any site, is not strictly better on an irregular room,
is slower than 1/5 of the baseline, or takes 60 s or more on the hall (level), or if any of
the tilt checks above fails; else 0.

    python benchmarks/planner.py            # every site (about 8 minutes here)
    python benchmarks/planner.py --quick    # without the hall's lattice baseline (about 6)
"""

from __future__ import annotations

import dataclasses
import math
import statistics
import sys
import time

import _common  # noqa: F401  (one-core setup before numpy)
import numpy as np
from _common import table, write_json

from vlpcal.planning import evaluate, lattice_search, plan_site, site_from_dict
from vlpcal.planning.poses import pose_of, posed_cameras, rotation, tilts
from vlpcal.planning.reference import (
    MARGIN_PX,
    sample_grid,
    sample_levels,
    sample_points,
    sample_step,
    unobstructed,
)
from vlpcal.planning.site import CameraMounting
from vlpcal.triangulation import trace_adjugate_det

C160 = {"width": 160, "height": 120, "fx": 153.3, "fy": 153.3, "cx": 79.5, "cy": 59.5,
        "dist": [0, 0, 0, 0, 0]}
C320 = {"width": 320, "height": 240, "fx": 306.6, "fy": 306.6, "cx": 159.5, "cy": 119.5,
        "dist": [0, 0, 0, 0, 0]}
BASELINE_STEP = 0.05  #: m, spacing and offset grid of the exhaustive baseline


def site(name, room, ceiling, camera, heights, p95, keep_out=()):
    return site_from_dict({
        "format": "vlpcal-site", "version": 1,
        "site": {"name": name, "ceiling_height": ceiling, "room": room,
                 "keep_out": list(keep_out)},
        "camera": camera,
        "requirements": {"heights": heights, "min_cameras": 2, "coverage": 0.95,
                         "max_error_p95": p95, "pixel_noise": 0.3},
        "families": ["linear", "triangular", "square", "free"]})


def square(x0, y0, side):
    return [[x0, y0], [x0 + side, y0], [x0 + side, y0 + side], [x0, y0 + side]]


#: (site, irregular?)
SITES = [
    (site("rectangle 4×3 m", [[0, 0], [4, 0], [4, 3], [0, 3]], 2.5, C160, [0.0, 0.35], 0.02),
     False),
    (site("L 5×4 m, pillar", [[0, 0], [5, 0], [5, 2], [2.5, 2], [2.5, 4], [0, 4]], 2.8, C160,
          [0.0, 0.35], 0.02, [square(1.0, 1.0, 0.4)]), True),
    (site("corridor 10×1.6 m", [[0, 0], [10, 0], [10, 1.6], [0, 1.6]], 2.5, C160,
          [0.0, 0.35], 0.02), False),
    (site("bay 6×3.6 m", [[0, 0], [6, 0], [6, 3.6], [0, 3.6]], 2.8, C160, [0.0, 0.5], 0.02),
     False),
    (site("L 7×6 m, pillar", [[0, 0], [7, 0], [7, 3], [3.5, 3], [3.5, 6], [0, 6]], 3.2, C320,
          [0.0, 0.8], 0.015, [square(1.5, 1.5, 0.5)]), True),
]
HALL = site("hall 10×8 m", [[0, 0], [10, 0], [10, 8], [0, 8]], 3.0, C160, [0.0, 0.3], 0.02)

CWIDE = {"width": 160, "height": 120, "fx": 40.0, "fy": 40.0, "cx": 79.5, "cy": 59.5,
         "dist": [0, 0, 0, 0, 0]}
#: rad: the tilt the tilted plans and the tilted baseline may use
MAX_TILT = math.radians(30.0)
#: rad: the tilted baseline's lean angles (5° grid, 0–30°)
LEANS = np.radians(np.arange(0.0, 30.0 + 1e-9, 5.0))
#: m: the tilted baseline's screening grid; its slack (coverage missed, p95 over the bound)
SCREEN_STEP, SCREEN_COVERAGE, SCREEN_P95 = 0.20, 0.02, 1.10


def rect(x0, y0, x1, y1):
    return [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]


#: the new sites (tilt only): a room with obstacles, a wide-lens room
PILLAR_SHELF = site("pillar + shelf 7×4.5 m", rect(0, 0, 7, 4.5), 3.0, C160, [0.0, 0.5], 0.02,
                    [{"polygon": square(3.25, 2.0, 0.5), "height": 3.0},
                     {"polygon": rect(2.5, 0.0, 4.5, 0.4), "height": 1.8}])
WIDE = site("wide lens 8×5 m", rect(0, 0, 8, 5), 3.0, CWIDE, [0.0, 0.5], 0.02)
NEW_SITES = [PILLAR_SHELF, WIDE]
#: the wide-lens room's hand layout: 4 × 2 on the walls, leaning 10° inward (columns, rows)
HAND = {"nx": 4, "ny": 2, "placement": "walls", "yaw": 0.0, "col": math.radians(10.0),
        "row": math.radians(10.0)}


def tilted(s):
    """The site with tilt allowed up to :data:`MAX_TILT` (no wall clearance)."""
    return dataclasses.replace(s, mounting=CameraMounting(MAX_TILT, 0.0))


# -- the tilted baseline ---------------------------------------------------------------------

def _axis(lo: float, hi: float, n: int, placement: str) -> np.ndarray:
    """A grid's positions along one axis: the n cells' centres, or n from wall to wall (one
    alone: the middle)."""
    if placement == "centres" or n == 1:
        return lo + (np.arange(n) + 0.5) * (hi - lo) / n
    return np.linspace(lo, hi, n)


def _inward(n: int) -> np.ndarray:
    """Per index along an axis: +1 for the first (it leans toward +), −1 for the last, 0 inside
    (a single row or column does not lean)."""
    out = np.zeros(n)
    if n > 1:
        out[0], out[-1] = 1.0, -1.0
    return out


def _lean(sx: float, sy: float, a: float, b: float) -> tuple[float, float]:
    """(wx, wy) of a camera leaning by a along sx and b along sy, its tilt capped at
    :data:`MAX_TILT`: the axis leans toward (dx, dy)/d by θ ⇒ w = θ·(dy, −dx)/d."""
    dx, dy = sx * a, sy * b
    d = math.hypot(dx, dy)
    if d < 1e-12:
        return 0.0, 0.0
    theta = min(d, MAX_TILT)
    return theta * dy / d, -theta * dx / d


def grid_poses(s, nx: int, ny: int, placement: str, yaw: float, col: float,
               row: float) -> np.ndarray:
    """The poses (n×5) of one grid layout, its cameras outside the room dropped."""
    from shapely import contains_xy
    from shapely.geometry import Polygon

    room = Polygon(s.room)
    x0, y0, x1, y1 = room.bounds
    xs, ys = _axis(x0, x1, nx, placement), _axis(y0, y1, ny, placement)
    sx, sy = _inward(nx), _inward(ny)
    out = [(xs[i], ys[j], yaw, *_lean(sx[i], sy[j], col, row))
           for j in range(ny) for i in range(nx)]
    out = np.array(out, float).reshape(-1, 5)
    return out[contains_xy(room.buffer(1e-9), out[:, 0], out[:, 1])]


class _Model:
    """The reference model (:func:`evaluate`'s) on one sample grid, each camera pose's share
    (which points it sees; its Fisher entries there) kept: a layout is the sum of its
    cameras'."""

    PAIRS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))

    def __init__(self, s, step=None):
        self.site, self.points = s, sample_points(s, step)
        self._clear, self._seen, self._info, self._rotations = {}, {}, {}, {}

    @staticmethod
    def key(pose) -> tuple:
        return tuple(round(float(v), 9) for v in pose)

    def seen(self, key) -> np.ndarray:
        if key not in self._seen:
            cam = posed_cameras(self.site, [key])[0]
            seen = cam.project(self.points, margin=MARGIN_PX)[2]
            if self.site.obstacles:  # what obstacles hide depends only on where it hangs
                seen = seen & self._clear_at(key)
            self._seen[key] = seen
        return self._seen[key]

    def seen_many(self, keys) -> np.ndarray:
        """len(keys) × points: :meth:`seen` of many poses at once — for an undistorted lens
        projected in one batch (the same test as ``Camera.project``), else one by one."""
        todo = [k for k in dict.fromkeys(keys) if k not in self._seen]
        if todo and not any(self.site.camera.dist):
            m = self.site.camera
            R = np.stack([self._rotation(k[2:], rotation) for k in todo])
            C = np.array([(k[0], k[1], self.site.ceiling_height) for k in todo])
            P = self.points.T[:, None, :]  # 3 × 1 × points
            for lo in range(0, len(todo), 64):  # 64 poses at a time: bounded memory
                Rb, Cb = R[lo:lo + 64], C[lo:lo + 64]
                D = [P[i] - Cb[:, i, None] for i in range(3)]  # poses × points
                x, y, z = (Rb[:, i, 0, None] * D[0] + Rb[:, i, 1, None] * D[1]
                           + Rb[:, i, 2, None] * D[2] for i in range(3))
                front = z > 1e-9
                with np.errstate(divide="ignore", invalid="ignore"):
                    iz = 1.0 / np.where(front, z, np.nan)
                    u = x * iz * m.fx + m.cx
                    v = y * iz * m.fy + m.cy
                    a = MARGIN_PX - 0.5
                    seen = front & (u >= a) & (u <= m.width - 0.5 - MARGIN_PX) \
                        & (v >= a) & (v <= m.height - 0.5 - MARGIN_PX)
                for k, row in zip(todo[lo:lo + 64], seen):
                    if self.site.obstacles:
                        row &= self._clear_at(k)
                    self._seen[k] = row
        return np.stack([self.seen(k) for k in keys])

    def _rotation(self, angles, rotation):
        if angles not in self._rotations:
            self._rotations[angles] = rotation(*angles)
        return self._rotations[angles]

    def _clear_at(self, key) -> np.ndarray:
        """Which points no obstacle hides from a camera hung at the pose's (x, y)."""
        if key[:2] not in self._clear:
            C = (key[0], key[1], self.site.ceiling_height)
            self._clear[key[:2]] = unobstructed(C, self.points, self.site.obstacles)
        return self._clear[key[:2]]

    def info(self, key) -> np.ndarray:
        if key not in self._info:
            seen = self.seen(key)
            F = np.zeros((len(self.points), 6))
            if seen.any():
                cam = posed_cameras(self.site, [key])[0]
                J = cam.jacobian(self.points[seen])
                F[seen] = np.stack([(J[:, :, i] * J[:, :, j]).sum(axis=1)
                                    for i, j in self.PAIRS], axis=-1)
            self._info[key] = F / self.site.requirements.pixel_noise ** 2
        return self._info[key]

    def verdict(self, keys, views=None) -> tuple[float, float]:
        """(coverage, p95 m) of the layout of poses ``keys``, as :func:`evaluate` has them."""
        r = self.site.requirements
        if views is None:
            views = np.sum([self.seen(k) for k in keys], axis=0)
        ok = views >= r.min_cameras
        if not ok.any():
            return float(ok.mean()), math.inf
        F = np.sum([self.info(k)[ok] for k in keys], axis=0)
        adj, det = trace_adjugate_det(*F.T)
        with np.errstate(invalid="ignore", divide="ignore"):
            err = np.sqrt(adj / det)
        return float(ok.mean()), float(np.percentile(err, 95))

    def clear_cache(self):
        self._seen.clear()
        self._info.clear()


def tilted_lower_bound(s) -> int:
    """A lower bound on the cameras of any layout with tilts up to :data:`MAX_TILT`, as
    :func:`vlpcal.planning.plan.fewest_possible` has it for level cameras, counted in the
    reference model's sample points: the highest LED height's points must be seen by
    ``min_cameras`` cameras over ``3·coverage − 2`` of them, and a camera sees at most the
    grid points in its footprint there — for a footprint of area A and perimeter P at most
    A/s² + P/(2s) + 1 on a grid of step s (Nosarzewska), the largest footprint a camera tilted
    by up to 30° in any direction has (image border sampled, 1° steps)."""
    from shapely.geometry import Polygon

    r = s.requirements
    m = s.camera
    top = max(r.heights)
    step = sample_step(s)
    u = np.linspace(-0.5, m.width - 0.5, 41)
    v = np.linspace(-0.5, m.height - 0.5, 31)
    border = np.concatenate([np.c_[u, np.full_like(u, v[0])], np.c_[np.full_like(v, u[-1]), v],
                             np.c_[u[::-1], np.full_like(u, v[-1])],
                             np.c_[np.full_like(v, u[0]), v[::-1]]])
    cells = 0.0
    for theta in np.radians(np.arange(0.0, math.degrees(MAX_TILT) + 1e-9, 5.0)):
        for phi in np.radians(np.arange(0.0, 360.0, 1.0)):
            cam = posed_cameras(s, [(0.0, 0.0, 0.0, theta * math.cos(phi),
                                     theta * math.sin(phi))])[0]
            xy = cam.ground(border, top)
            if not np.isfinite(xy).all():
                return r.min_cameras
            f = Polygon(xy)
            cells = max(cells, f.area / step ** 2 + f.length / (2 * step) + 1)
            if theta == 0:
                break
    share = max(0.0, 3 * r.coverage - 2) if len(sample_levels(s)) == 3 else r.coverage
    points = int(sample_grid(s)[2].sum())  # per LED height
    return max(r.min_cameras, math.ceil(r.min_cameras * share * points / cells - 1e-9))


def tilted_baseline(s, most: int) -> dict:
    """The fewest cameras of a tilted rectangular grid that meet (see the module's
    docstring), up to ``most`` cameras: its layout, verdict and cost."""
    from shapely import contains_xy
    from shapely.geometry import Polygon

    t0 = time.perf_counter()
    r = s.requirements
    fewest = tilted_lower_bound(s)
    room = Polygon(s.room)
    x0, y0, x1, y1 = room.bounds
    inside = room.buffer(1e-9)
    groups = {}  # positions → (count, nx, ny, placement)
    for nx in range(1, 2 * most + 1):
        for ny in range(1, 2 * most // nx + 1):
            for placement in ("centres", "walls"):
                X, Y = np.meshgrid(_axis(x0, x1, nx, placement), _axis(y0, y1, ny, placement))
                n = int(contains_xy(inside, X, Y).sum())
                key = (nx, ny, tuple(np.round(X.ravel(), 9)), tuple(np.round(Y.ravel(), 9)))
                if fewest <= n <= most and key not in groups:
                    groups[key] = (n, nx, ny, placement)
    coarse, fine = _Model(s, SCREEN_STEP), _Model(s)
    pairs = [(i, j) for i in range(len(LEANS)) for j in range(len(LEANS))]
    screened = judged = 0
    found = None
    for count in sorted({g[0] for g in groups.values()}):
        passed = []
        for _, nx, ny, placement in sorted(g for g in groups.values() if g[0] == count):
            for yaw in (0.0, math.pi / 2):
                layouts = [grid_poses(s, nx, ny, placement, yaw, LEANS[i], LEANS[j])
                           for i, j in pairs]
                keys = [[coarse.key(p) for p in lay] for lay in layouts]
                uniq = sorted({k for ks in keys for k in ks})
                index = {k: m for m, k in enumerate(uniq)}
                S = coarse.seen_many(uniq)
                idx = np.array([[index[k] for k in ks] for ks in keys])
                views = S[idx].sum(axis=1, dtype=np.int16)  # layouts × points
                screened += len(layouts)
                cover = (views >= r.min_cameras).mean(axis=1)
                for c in np.flatnonzero(cover >= r.coverage - SCREEN_COVERAGE):
                    _, p95 = coarse.verdict(keys[c], views[c])
                    if p95 <= SCREEN_P95 * r.max_error_p95:
                        passed.append((p95, -cover[c], nx, ny, placement, yaw, pairs[c],
                                       layouts[c]))
                coarse.clear_cache()
        passed.sort(key=lambda p: p[:2])
        for p95, _, nx, ny, placement, yaw, (i, j), poses in passed:
            judged += 1
            cov, p95 = fine.verdict([fine.key(p) for p in poses])
            if not (cov >= r.coverage and p95 <= r.max_error_p95):
                continue
            ev = evaluate(s, posed_cameras(s, poses))
            if ev.meets:
                found = {"count": len(poses), "nx": nx, "ny": ny, "placement": placement,
                         "yaw_deg": math.degrees(yaw), "col_deg": math.degrees(LEANS[i]),
                         "row_deg": math.degrees(LEANS[j]), "coverage": ev.coverage,
                         "p95_cm": ev.p95 * 100, "poses": poses.tolist()}
                break
        fine.clear_cache()
        if found:
            break
    return {"best": found, "screened": screened, "judged": judged, "most": most,
            "lower_bound": fewest,
            "seconds": time.perf_counter() - t0}


def grid_label(b: dict | None) -> str | None:
    if not b:
        return None
    return (f"{b['nx']}×{b['ny']} {b['placement']} {b['yaw_deg']:.0f}° "
            f"lean {b['col_deg']:.0f}/{b['row_deg']:.0f}°")


def run(s, irregular: bool, baseline: bool = True, repeat: int = 3) -> dict:
    times = []
    for _ in range(repeat):  # the same answer each time (deterministic); the median time
        t0 = time.perf_counter()
        plan = plan_site(s, tilt_hint=False)  # the level search alone (the what-if aside)
        times.append(time.perf_counter() - t0)
    t_plan = statistics.median(times)
    best = plan.candidates[0] if plan.candidates else None
    row = {"site": s.name, "irregular": irregular,
           "plan_cameras": best.count if best else None,
           "plan_family": best.family if best else None,
           "plan_p95_cm": best.evaluation.p95 * 100 if best else None,
           "plan_verified": bool(best is not None and evaluate(s, best.cameras).meets),
           "plan_candidates_verified": bool(best is not None and all(
               evaluate(s, c.cameras).meets for c in plan.candidates)),
           "plan_s": t_plan,
           # beyond the level search: the mending of a lattice that fails in shadows (last
           # run; the what-if of tilting is off here, so its entries stay empty)
           "plan_whatif_s": plan.tilted.seconds if plan.tilted else 0.0,
           "plan_whatif_cameras": plan.tilted.best.count
           if plan.tilted and plan.tilted.best else None,
           "plan_mended_s": plan.mended.seconds if getattr(plan, "mended", None) else 0.0}
    if baseline:
        r = lattice_search(s, ("square",), BASELINE_STEP)
        b = r.best
        row.update({"baseline_cameras": b.count if b else None,
                    "baseline_p95_cm": b.evaluation.p95 * 100 if b else None,
                    "baseline_verified": bool(b is not None and b.evaluation.meets),
                    "baseline_layouts": r.layouts, "baseline_s": r.seconds,
                    "time_ratio": r.seconds / t_plan})
    return row


def run_tilted(s, level: dict, baseline: bool = True) -> dict:
    """The site planned with tilt up to :data:`MAX_TILT` (one run, timed), beside its level
    plan ``level`` (a :func:`run` row), and the tilted baseline."""
    st = tilted(s)
    t0 = time.perf_counter()
    plan = plan_site(st)
    t_plan = time.perf_counter() - t0
    best = plan.candidates[0] if plan.candidates else None
    # the optimiser's work: mending a lattice that fails in shadows, then the tilted search
    stages = [t for t in (getattr(plan, "mended", None), plan.tilted) if t is not None]
    row = {"site": s.name, "level_cameras": level["plan_cameras"],
           "level_family": level["plan_family"],
           "level_verified": level["plan_candidates_verified"],
           "tilted_cameras": best.count if best else None,
           "tilted_family": best.family if best else None,
           "tilted_seed": best.seed if best else None,
           "tilted_p95_cm": best.evaluation.p95 * 100 if best else None,
           "tilted_coverage": best.evaluation.coverage if best else None,
           "tilted_most_tilt_deg": math.degrees(max(tilts([pose_of(c) for c in best.cameras])))
           if best else None,
           "tilted_verified": bool(best is not None and
                                   all(evaluate(st, c.cameras).meets for c in plan.candidates)),
           "tilted_s": t_plan,
           "tilted_search_s": sum(t.seconds for t in stages),
           "tilted_solves": sum(len(t.solves) for t in stages),
           "tilted_iterations": sum(x.iterations for t in stages for x in t.solves),
           "tilted_complete": all(t.complete for t in stages),
           "tilted_mended": bool(getattr(plan, "mended", None)),
           "tilted_poses": [pose_of(c).tolist() for c in best.cameras] if best else None}
    if baseline:
        # up to half again the level plan's count: a grid spanning the room can need more
        most = math.ceil(1.5 * max(n for n in (level["plan_cameras"],
                                               row["tilted_cameras"], 2) if n)) + 4
        b = tilted_baseline(st, most)
        row.update({"grid_cameras": b["best"]["count"] if b["best"] else None,
                    "grid_layout": grid_label(b["best"]),
                    "grid_p95_cm": b["best"]["p95_cm"] if b["best"] else None,
                    "grid_s": b["seconds"], "grid_screened": b["screened"],
                    "grid_judged": b["judged"], "grid_most": b["most"],
                    "lower_bound": b["lower_bound"], "grid": b["best"]})
    return row


def hand_layout(s, h: dict) -> dict:
    """A hand layout (a grid as :func:`grid_poses` makes it) judged by :func:`evaluate`."""
    st = tilted(s)
    poses = grid_poses(st, h["nx"], h["ny"], h["placement"], h["yaw"], h["col"], h["row"])
    ev = evaluate(st, posed_cameras(st, poses))
    return {"hand_cameras": len(poses), "hand_meets": bool(ev.meets),
            "hand_p95_cm": ev.p95 * 100, "hand_coverage": ev.coverage,
            "hand_layout": grid_label({"nx": h["nx"], "ny": h["ny"],
                                       "placement": h["placement"],
                                       "yaw_deg": math.degrees(h["yaw"]),
                                       "col_deg": math.degrees(h["col"]),
                                       "row_deg": math.degrees(h["row"])}),
            "hand_poses": poses.tolist()}


def main() -> int:
    quick = "--quick" in sys.argv
    t_start = time.perf_counter()
    plan_site(SITES[0][0], max_cameras=4)  # imports and caches warm before any timing
    rows = []
    for s, irregular in SITES + [(HALL, False)]:
        rows.append(run(s, irregular, baseline=not (quick and s is HALL)))
        r = rows[-1]
        print(f"  {r['site']}: plan {r['plan_cameras']} in {r['plan_s']:.1f} s, baseline "
              f"{r.get('baseline_cameras', '–')} in {r.get('baseline_s', float('nan')):.1f} s",
              file=sys.stderr, flush=True)
    print("Fewest cameras meeting the requirements (k = 2 over 95 %, reference model), "
          "vlpcal plan vs an exhaustive search over rectangular lattices on a 5 cm grid "
          "(one core; plan: median of 3 runs, baseline: one run)")
    print(table(rows, [("site", "site", ""), ("plan_cameras", "plan", "d"),
                       ("plan_family", "layout", ""), ("plan_p95_cm", "p95 cm", ".2f"),
                       ("plan_s", "time s", ".1f"), ("baseline_cameras", "lattice", "d"),
                       ("baseline_p95_cm", "p95 cm", ".2f"), ("baseline_s", "time s", ".1f"),
                       ("time_ratio", "plan ×faster", ".1f")]))
    judged = [r for r in rows if "baseline_cameras" in r]
    never_more = all(r["plan_verified"] and (r["baseline_cameras"] is None or
                     r["plan_cameras"] <= r["baseline_cameras"]) for r in judged)
    fewer = any(r["irregular"] and r["plan_cameras"] < r["baseline_cameras"] for r in judged)
    # the time ratio is asked of the five sites; the hall is asked to plan in 60 s
    fast = all(r["time_ratio"] >= 5 for r in judged if r["site"] != HALL.name)
    hall = next(r for r in rows if r["site"] == HALL.name)
    print(f"\nplan never needs more cameras: {'yes' if never_more else 'NO'}; strictly fewer "
          f"on an irregular room: {'yes' if fewer else 'NO'}; at least 5× faster on the five "
          "sites: "
          f"{'yes' if fast else 'NO'}; {HALL.name} planned in {hall['plan_s']:.1f} s "
          f"({'under' if hall['plan_s'] < 60 else 'NOT under'} 60 s)")
    ok = never_more and fewer and fast and hall["plan_s"] < 60

    # -- tilt up to 30°: every site again, the two new ones, the tilted baseline -----------
    levels = {r["site"]: r for r in rows}
    for s in NEW_SITES:
        levels[s.name] = run(s, True, baseline=False, repeat=1)
    tilt_rows = []
    for s in [s for s, _ in SITES] + [HALL] + NEW_SITES:
        tilt_rows.append(run_tilted(s, levels[s.name]))
        t = tilt_rows[-1]
        if s is WIDE:
            t.update(hand_layout(s, HAND))
        print(f"  {t['site']} (tilt ≤ 30°): level {t['level_cameras']}, tilted "
              f"{t['tilted_cameras']} in {t['tilted_s']:.1f} s, tilted grid "
              f"{t.get('grid_cameras', '–')} in {t.get('grid_s', float('nan')):.1f} s",
              file=sys.stderr, flush=True)
    print("\nWith tilt up to 30° (mounting: max_tilt 30°): plan_site (one run) vs the level "
          "plan and the tilted-grid baseline (rectangular nx × ny grids, cell centres or "
          "outer cameras on the walls, outer columns/rows leaning inward on a 5° grid, yaw "
          "0°/90°; the fewest that meets by evaluate)")
    print(table(tilt_rows, [("site", "site", ""), ("level_cameras", "level", "d"),
                            ("lower_bound", "≥", "d"), ("tilted_cameras", "tilted", "d"),
                            ("tilted_family", "layout", ""),
                            ("tilted_p95_cm", "p95 cm", ".2f"),
                            ("tilted_most_tilt_deg", "max tilt°", ".0f"),
                            ("tilted_s", "time s", ".1f"),
                            ("tilted_solves", "solves", "d"),
                            ("tilted_verified", "verified", ""),
                            ("grid_cameras", "tilted grid", "d"),
                            ("grid_layout", "grid layout", ""),
                            ("grid_p95_cm", "p95 cm", ".2f"), ("grid_s", "time s", ".1f")]))
    print("≥: a lower bound on any layout with tilts up to 30° (the grid points a camera's "
          "largest footprint holds at the highest LED height); the tilted grid is searched "
          "from it up")
    wide = next(t for t in tilt_rows if t["site"] == WIDE.name)
    print(f"{WIDE.name}: hand layout {wide['hand_layout']}: {wide['hand_cameras']} cameras, "
          f"p95 {wide['hand_p95_cm']:.2f} cm, coverage {wide['hand_coverage']:.1%}: "
          f"{'meets' if wide['hand_meets'] else 'does NOT meet'}")

    def yes(flag):
        return "yes" if flag else "NO"

    by = {t["site"]: t for t in tilt_rows}
    bay = by[SITES[3][0].name]
    shelf = by[PILLAR_SHELF.name]
    hall_t = by[HALL.name]
    counted = [t for t in tilt_rows if t["level_cameras"] and t["tilted_cameras"]]
    n_fewer = sum(t["tilted_cameras"] < t["level_cameras"] for t in counted)
    worse = [t["site"] for t in counted if t["tilted_cameras"] > t["level_cameras"]]
    over_grid = [t["site"] for t in tilt_rows if t.get("grid_cameras") is not None and
                 (t["tilted_cameras"] is None or t["tilted_cameras"] > t["grid_cameras"])]
    unmet = [t["site"] for t in tilt_rows if not (t["tilted_verified"] and t["level_verified"])]
    checks = {
        "bay_at_most_9": bool(bay["tilted_cameras"] is not None and bay["tilted_cameras"] <= 9),
        "fewer_on_five_never_more": len(counted) == len(tilt_rows) and n_fewer >= 5
        and not worse,
        "never_more_than_tilted_grid": not over_grid,
        "every_plan_meets": not unmet,
        "wide_at_most_8": bool(wide["tilted_cameras"] is not None and
                               wide["tilted_cameras"] <= 8),
        "pillar_shelf_meets": bool(shelf["tilted_verified"] and shelf["level_verified"]),
        "hall_tilted_under_60s": hall_t["tilted_s"] < 60,
    }
    print(f"\n{bay['site']} with tilt ≤ 30° needs ≤ 9 cameras: "
          f"{yes(checks['bay_at_most_9'])} ({bay['tilted_cameras']})")
    print(f"tilted strictly fewer than level on ≥ 5 sites, never more: "
          f"{yes(checks['fewer_on_five_never_more'])} (fewer on {n_fewer} of {len(tilt_rows)}"
          + (f"; more on {', '.join(worse)}" if worse else "") + ")")
    print(f"tilted never more than the tilted-grid baseline: "
          f"{yes(checks['never_more_than_tilted_grid'])}"
          + (f" (more on {', '.join(over_grid)})" if over_grid else ""))
    print(f"every exported plan (level and tilted, every candidate) meets by evaluate: "
          f"{yes(checks['every_plan_meets'])}" + (f" (not on {', '.join(unmet)})" if unmet
                                                   else ""))
    print(f"{WIDE.name} needs ≤ 8 cameras: {yes(checks['wide_at_most_8'])} "
          f"({wide['tilted_cameras']})")
    print(f"{PILLAR_SHELF.name}: the plans meet with the obstacles' shadows counted: "
          f"{yes(checks['pillar_shelf_meets'])} (level {shelf['level_cameras']}, tilted "
          f"{shelf['tilted_cameras']})")
    print(f"{HALL.name} with tilt planned within 60 s: {yes(checks['hall_tilted_under_60s'])} "
          f"({hall_t['tilted_s']:.1f} s)")
    path = write_json("planner", {"rows": rows, "baseline_step_m": BASELINE_STEP,
                                  "quick": quick, "tilt_rows": tilt_rows,
                                  "new_site_levels": [levels[s.name] for s in NEW_SITES],
                                  "max_tilt_deg": math.degrees(MAX_TILT),
                                  "tilted_grid": {"leans_deg": np.degrees(LEANS).tolist(),
                                                  "screen_step_m": SCREEN_STEP,
                                                  "screen_coverage_slack": SCREEN_COVERAGE,
                                                  "screen_p95_factor": SCREEN_P95},
                                  "checks": {"never_more": never_more,
                                             "fewer_on_irregular": fewer, "fast": fast,
                                             "hall_under_60s": hall["plan_s"] < 60,
                                             **checks},
                                  "seconds": time.perf_counter() - t_start})
    print(f"wrote {path}")
    return 0 if ok and all(checks.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
