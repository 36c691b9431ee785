"""The whole plan, as ``vlpcal plan`` runs it: every lattice of the site's families on the
mounting grid, then a local search beyond lattices from the best one; every exported layout
judged by the reference model itself.

shapely is imported inside :func:`_tilted_footprint`: importing planning for its types (as the
viewer and the demo do) loads no GEOS library.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..deployment import Deployment, provenance
from .families import Candidate, ceiling_cameras, mount_step, rank_key
from .free import fewer_cameras, snap
from .lattice import SPACING_RANGE, Mounting, lattice_search
from .nadir import YAWS, NadirModel
from .optimiser import too_coarse
from .poses import pose_of, posed_cameras, tilts
from .reference import evaluate
from .site import CameraMounting, Site, floor, footprint
from .tilted import TiltedPlan, tilted_plan

#: the searches' coarse models keep every n-th sample point along each axis (the exact model
#: judges after): the lattice screen, the local search
SCREEN_EVERY, SEARCH_EVERY = 2, 3
#: rad: for a site without ``mounting:``, the tilt the plan says what would save
HINT_TILT = math.radians(30.0)
#: the what-if's time, as a multiple of the level plan's own (a hint, not the plan)
HINT_TIME = 4.0
#: s: the least time the optimiser is given to mend a plan no lattice meets
MEND_TIME = 20.0
#: sample-grid cells per LED height a plan takes on (a 200 × 100 m hall at 10 cm has 2·10⁶:
#: gigabytes and hours)
MAX_SAMPLE_CELLS = 500_000


@dataclass
class Plan:
    """The result of planning: the layouts that meet the site's requirements, fewest cameras
    first (empty when none does), and what the search did."""

    candidates: list  # Candidate, by rank_key
    tried: int  # layouts judged
    seconds: float
    closest: Candidate | None = None  # when nothing meets: the densest lattice tried
    missing: dict[str, str] = field(default_factory=dict)  # family → why it has no candidate
    #: the CasADi optimiser's search below the best level layout (when it ran)
    tilted: TiltedPlan | None = None
    #: rad: the tilt ``tilted`` allowed; for a site without ``mounting:`` it is
    #: :data:`HINT_TILT`, a what-if whose layout is not a candidate
    tilt: float = 0.0
    #: the optimiser's mending of the best lattice when none met the exact model
    mended: TiltedPlan | None = None
    #: why no layout can meet the requirements, known before any search (else empty)
    refused: str = ""


def plan_site(site: Site, max_cameras: int = 60, progress=None, tilt_hint: bool = True) -> Plan:
    """The fewest cameras that meet the requirements.

    1. Each grid family of the site (square: a × b, a ≠ b; triangular; linear) by the
       exhaustive lattice search on the mounting grid (:func:`.lattice.lattice_search`), both
       yaws, cameras clipped to the room; a family after the first only looks for layouts
       with no more cameras than the best so far.
    2. ``free`` (when the site allows it): from the best lattice, :func:`.free.fewer_cameras`
       removes cameras and repairs the layout by moves on the mounting grid.
    3. Every candidate on the mounting grid (a triangular lattice's cameras snapped to it and
       repaired if snapping broke it) and judged by :func:`evaluate`, the reference model.
    4. ``tilted`` (when the site's ``mounting`` allows tilt): from the best level layout, the
       CasADi optimiser over every camera's pose (:func:`.tilted.tilted_plan`) takes cameras
       away while the exact model still meets. A site without ``mounting`` runs it as a
       what-if at :data:`HINT_TILT` (:attr:`Plan.tilted`), not as a candidate, unless
       ``tilt_hint`` is false.
    """
    t0 = time.perf_counter()
    say = progress or (lambda m: None)
    fewest = fewest_possible(site)
    if fewest > max_cameras:  # before any sample point is made: a hall of 10⁴ m² stays quick
        return Plan([], 0, time.perf_counter() - t0,
                    refused=f"at least {fewest} cameras are needed (the served share of the "
                            "floor, times the cameras per point, over a camera's footprint)")
    step = mount_step(site)
    model = NadirModel(site)
    if model.n_points == 0:
        return Plan([], 0, time.perf_counter() - t0,
                    refused="no point of the reference model's sample grid falls on the floor "
                            "(a room narrower than one grid cell?)")
    if model.inside.size > MAX_SAMPLE_CELLS:
        return Plan([], 0, time.perf_counter() - t0,
                    refused=f"the reference model's {model.step * 100:g} cm grid has "
                            f"{model.inside.size:,} cells per height, more than the "
                            f"{MAX_SAMPLE_CELLS:,} a plan handles here: plan the room in parts")
    screen = NadirModel(site, every=SCREEN_EVERY)
    grids = [f for f in ("square", "triangular", "linear") if f in site.families]
    if "free" in site.families and "square" not in grids:
        grids.insert(0, "square")  # the local search starts from a lattice
    found, missing, tried, best_n, failing = {}, {}, 0, max_cameras, []
    for family in grids:
        r = lattice_search(site, (family,), step, model, fewest=best_n, screen=screen)
        tried += r.judged
        if r.best is None:
            missing[family] = f"no {family} lattice of ≤ {best_n} cameras meets the requirements"
            say(f"  {family}: none of ≤ {best_n} cameras meets ({r.seconds:.1f} s)")
            continue
        cand = _on_grid(site, model, step, r.best)
        if cand is not None and not cand.evaluation.meets:
            failing.append(cand)  # the optimiser may repair it
        if cand is None or not cand.evaluation.meets:
            # the search's closed form ignores lens distortion: the reference model decides
            missing[family] = ("its best lattice fails the reference model once snapped to "
                               "the mounting grid" if cand is None else
                               "its best lattice fails the reference model (the "
                               + " and ".join(_left_out(site)) + " the search leaves out)")
            continue
        found[family] = cand
        best_n = min(best_n, cand.count)
        say(f"  {family}: {cand.count} cameras ({r.seconds:.1f} s)")
    if "free" in site.families and found:
        seed = min(found.values(), key=rank_key)
        t1 = time.perf_counter()
        search = NadirModel(site, every=SEARCH_EVERY)
        cams = fewer_cameras(search, model, step, [c.position[:2] for c in seed.cameras],
                             [_yaw(c) for c in seed.cameras])
        ev = evaluate(site, cams)
        if ev.meets and (len(cams) < seed.count or seed.family not in site.families):
            found["free"] = Candidate("free", 0, 0, (), tuple(cams[0].position[:2]), 0.0,
                                      cams, ev)
            say(f"  free: {len(cams)} cameras ({time.perf_counter() - t1:.1f} s)")
        else:
            missing["free"] = f"no layout beyond lattices with fewer than {seed.count} cameras"
            say(f"  free: none below {seed.count} cameras ({time.perf_counter() - t1:.1f} s)")
    candidates = sorted((c for f, c in found.items() if f in site.families), key=rank_key)
    tilt = site.mounting.max_tilt if site.mounting else (HINT_TILT if tilt_hint else 0.0)
    mended = tilted = None
    if not candidates and failing:
        # no lattice meets once shadows (or distortion) count: the optimiser mends the best
        # one — tilted if the site allows it, else level cameras moved and turned
        allowed = site.mounting.max_tilt if site.mounting else 0.0
        lattice = min(failing, key=rank_key)
        say(f"  mend: the CasADi optimiser from the best lattice ({lattice.count} cameras), "
            "which fails the reference model")
        mended = tilted_plan(site, lattice, step, allowed, progress=say, most=max_cameras,
                             least=fewest,
                             seconds=max(MEND_TIME, HINT_TIME * (time.perf_counter() - t0)))
        if mended.best is not None:
            candidates = [mended.best]
            missing = {f: m for f, m in missing.items() if f != mended.best.family}
    closest = None
    if not candidates:
        closest = _densest(site, step)
    if not candidates and closest is not None and mended is None and site.mounting \
            and site.mounting.max_tilt > 0:
        # no level lattice meets at all (a narrow ceiling, a low max_cameras): tilted
        # cameras may, from the densest lattice — given a bounded time, as the answer may
        # be that nothing meets
        say(f"  mend: the CasADi optimiser from the densest lattice ({closest.count} cameras)")
        budget = max(MEND_TIME, HINT_TIME * (time.perf_counter() - t0))
        mended = tilted_plan(site, closest, step, site.mounting.max_tilt, progress=say,
                             most=max_cameras, seconds=budget, least=fewest)
        if mended.best is not None and mended.best.count <= max_cameras:
            candidates = [mended.best]
    if candidates and not site.mounting and too_coarse(site, candidates[0].count):
        tilt = 0.0  # a what-if this large would model the room too coarsely to be worth it
    if candidates and tilt > 0 and not (mended and site.mounting):
        say(f"  tilted: the CasADi optimiser, tilts up to {math.degrees(tilt):.0f}°"
            + ("" if site.mounting else " (a what-if: the site has no mounting: block)"))
        budget = math.inf if site.mounting else HINT_TIME * (time.perf_counter() - t0)
        least = fewest_possible(replace(site, mounting=CameraMounting(tilt, 0.0)))
        tilted = tilted_plan(site, candidates[0], step, tilt, progress=say, seconds=budget,
                             least=least)
        if site.mounting and tilted.best is not None:
            candidates = sorted(candidates + [tilted.best], key=rank_key)
    return Plan(candidates, tried, time.perf_counter() - t0, closest,
                {f: m for f, m in missing.items() if f in site.families}, tilted, tilt, mended)


def _left_out(site: Site) -> list:
    """What the lattice search's closed form leaves out of the reference model here."""
    return (["the lens distortion"] if any(site.camera.dist) else []) \
        + (["obstacles' shadows"] if site.obstacles else []) or ["rounding"]


def fewest_possible(site: Site) -> int:
    """A lower bound on the cameras any layout needs: the highest LED height must be seen by
    ``min_cameras`` cameras over at least ``3·coverage − 2`` of its floor (the other two
    heights can at most make up the rest), and each camera sees at most its footprint there."""
    r = site.requirements
    area = floor(site.room, site.keep_out)
    fw, fd = footprint(site)
    seen = max(fw * fd, _tilted_footprint(site)) if site.mounting else fw * fd
    share = max(0.0, 3 * r.coverage - 2)
    return max(r.min_cameras, math.ceil(r.min_cameras * share * area.area / seen - 1e-9))


def _tilted_footprint(site: Site) -> float:
    """m²: the largest floor area a camera tilted by the site's ``max_tilt`` sees at the
    highest LED height, over the directions it may lean (a tilted view is larger: its far
    side is further away); infinite when its view reaches the horizon."""
    from shapely.geometry import Polygon

    tilt = site.mounting.max_tilt
    most = 0.0
    for lean in np.radians(np.arange(0, 180, 15)):
        cam = posed_cameras(site, [[0.0, 0.0, 0.0, tilt * math.cos(lean),
                                    tilt * math.sin(lean)]])[0]
        quad = cam.footprint(max(site.requirements.heights))
        if not np.isfinite(quad).all():
            return math.inf
        most = max(most, Polygon(quad).area)
    return most


def _yaw(camera) -> float:
    """A level camera's yaw about the vertical, from its image x-axis: the nearest of the
    yaws the searches use (0° or 90°; an image turned by 180° sees the same)."""
    a = camera.yaw % np.pi
    return min(YAWS, key=lambda y: min(abs(a - y), np.pi - abs(a - y)))


def _on_grid(site: Site, model: NadirModel, step: float, cand: Candidate):
    """A lattice's layout on the mounting grid, judged by :func:`evaluate`: as it is when its
    cameras are on the grid already, else snapped (and repaired by the local search's moves
    if snapping broke it); None if it cannot be made to meet."""
    xy = np.array([c.position[:2] for c in cand.cameras])
    yaws = [_yaw(c) for c in cand.cameras]
    lay = snap(model, step, xy, yaws)
    if lay is None:
        return None
    cams = lay.cameras()
    if np.allclose([c.position[:2] for c in cams], xy, atol=1e-9):
        return cand
    ev = evaluate(site, cams)
    return Candidate(cand.family, cand.nx, cand.ny, cand.spacing, tuple(cams[0].position[:2]),
                     cand.yaw, cams, ev) if ev.meets else None


def _densest(site: Site, step: float) -> Candidate | None:
    """When nothing meets: the square lattice at the smallest spacings searched, judged (the
    closest a lattice comes to the coverage)."""
    fw, fd = footprint(site)
    a, b = max(step, SPACING_RANGE[0] * fw), max(step, SPACING_RANGE[0] * fd)
    mount = Mounting(site, step)
    xs = np.arange(mount.x0, mount.x1 + 1e-9, a)
    ys = np.arange(mount.y0, mount.y1 + 1e-9, b)
    X, Y = np.meshgrid(xs, ys)
    keep = mount(X, Y)
    xy = np.c_[X[keep], Y[keep]]
    if not len(xy):
        return None
    cams = ceiling_cameras(site, xy, [0.0] * len(xy))
    return Candidate("square", len(xs), len(ys), (a, b), tuple(xy[0]), 0.0, cams,
                     evaluate(site, cams))


def planned_deployment(site: Site, cand: Candidate, rank: int = 1, source: str = "") -> Deployment:
    """The deployment file of a planned layout, with its predicted figures in the provenance
    (so that the survey can later report planned against achieved)."""
    ev, r = cand.evaluation, site.requirements
    layout = {"family": cand.family, "cameras": cand.count, "rank": rank,
              "mounting_grid_m": float(mount_step(site))}
    if cand.family == "tilted":
        layout.update({"started_from": cand.seed, "optimiser": "CasADi (IPOPT)",
                       "max_tilt_deg": round(math.degrees(float(max(tilts(
                           [pose_of(c) for c in cand.cameras])))), 3)})
    elif cand.family != "free":
        layout.update({"grid": [cand.nx, cand.ny],
                       "spacing_m": [round(float(v), 6) for v in cand.spacing],
                       "origin_m": [round(float(v), 6) for v in cand.origin],
                       "yaw_rad": float(cand.yaw)})
    prov = provenance(
        "vlpcal plan", **{"from": {"site": str(source)}}, plan=layout,
        predicted={"coverage": ev.coverage, "mean_error_m": ev.mean, "p95_error_m": ev.p95,
                   "model": "reference model (docs/formats.md)", "pixel_noise_px": r.pixel_noise})
    return Deployment(site.name, site.ceiling_height, site.room, cand.cameras, site.keep_out,
                      {"uncertainty": {"pixel_noise": r.pixel_noise}, "provenance": prov})
