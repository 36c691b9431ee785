"""The terminal reports of planning, as lines of text the command prints: a plan's ranked
candidates and what the optimiser did, how to hang a tilted layout, why no layout meets, and a
layout's check against a site, a site's zones. (The maps are :func:`vlpcal.reports.plan_maps`.)"""

from __future__ import annotations

import math

from .check import LayoutCheck
from .families import mount_step
from .plan import Plan
from .poses import pose_of, tilts
from .site import Site, unit_doubt
from .zones import Zoning


def plan_lines(site: Site, plan: Plan) -> list[str]:
    """A plan that found candidates: the summary, the ranked candidates, why a family has
    none, the legend, then what the CasADi optimiser did beyond the lattices."""
    k = len(plan.candidates)
    lines = [f"{site.name}: {plan.candidates[0].count} cameras meet the requirements "
             f"({k} candidate{'s' if k > 1 else ''}; {plan.tried} layouts judged, "
             f"{plan.seconds:.1f} s)\n",
             f"{'#':>2s} {'layout':10s} {'cams':>4s} {'x×y':>6s} {'spacing m':>12s} "
             f"{'yaw':>5s} {'coverage':>8s} {'mean cm':>8s} {'p95 cm':>7s}"]
    for k, c in enumerate(plan.candidates, start=1):
        xs = {round(cam.position[0], 6) for cam in c.cameras}
        ys = {round(cam.position[1], 6) for cam in c.cameras}
        grid = f"{len(xs)}×{len(ys)}"
        sp = "×".join(f"{v:.2f}" for v in c.spacing) if c.spacing else "–"
        yaw = "/".join(str(a) for a in sorted({round(math.degrees(cam.yaw)) % 180
                                               for cam in c.cameras}))
        if c.family in ("tilted", "free") and len(xs) * len(ys) > c.count:
            grid = "–"  # not a grid: the positions are in the deployment
        yaw = yaw if len(yaw) <= 5 else "mixed"
        lines.append(f"{k:2d} {c.family:10s} {c.count:4d} {grid:>6s} {sp:>12s} {yaw:>5s} "
                     f"{c.evaluation.coverage:8.1%} {c.evaluation.mean * 100:8.2f} "
                     f"{c.evaluation.p95 * 100:7.2f}")
    lines += [f"   {family:10s} {why}" for family, why in plan.missing.items()]
    lines.append(f"x×y: distinct camera positions along x and y (cameras on a "
                 f"{mount_grid(site)} grid from the room's lower-left corner); yaw: "
                 f"degrees from the room's x axis to each image's {site.camera.width} px side "
                 "(the maps draw it)")
    return lines + tilted_lines(site, plan)


def solves(t) -> str:
    """What the CasADi optimiser's search ``t`` (a :class:`.tilted.TiltedPlan`) cost."""
    return (f"CasADi optimiser: {len(t.solves)} solve{'s' * (len(t.solves) != 1)}, "
            f"{sum(s.iterations for s in t.solves)} iterations, {t.seconds:.1f} s")


def tilted_lines(site: Site, plan: Plan) -> list[str]:
    """What the CasADi optimiser did beyond the lattices: the layout it mended when no
    lattice met, its tilted candidate and its cost when the site allows tilt, else what
    tilting would save."""
    lines = []
    deg = f"{math.degrees(plan.tilt):.3g}°"
    m = plan.mended
    if m is not None:
        tilted = site.mounting is not None and site.mounting.max_tilt > 0
        lines.append(f"{m.best.family}: no lattice meets the exact reference model "
                     f"(see above); from one of {m.start} cameras the optimiser mended a "
                     f"layout of {m.best.count}" + (" tilted" if tilted else " level")
                     + f" cameras ({solves(m)})")
    t = plan.tilted
    if t is None:
        if site.mounting is None and m is None and plan.candidates:
            lines.append(f"what tilting would save is not estimated for a layout this large "
                         f"({plan.candidates[0].count} cameras); a mounting: block in the "
                         "site plans tilted cameras")
        return lines
    if site.mounting is None and t.best is not None:
        fewer = "" if t.complete else " or fewer (the what-if ran out of its time)"
        lines.append(f"with tilt up to {deg}: {t.best.count} cameras{fewer} instead of "
                     f"{t.start} — needs tilting brackets (a mounting: block in the site "
                     f"would allow it; {solves(t)})")
    elif site.mounting is None and t.complete:
        lines.append(f"tilting up to {deg} would not save a camera ({solves(t)})")
    elif site.mounting is None:
        lines.append(f"what tilting up to {deg} would save was not found in the what-if's "
                     f"time ({solves(t)}); a mounting: block in the site plans tilted cameras")
    elif t.best is not None:
        most = math.degrees(max(tilts([pose_of(c) for c in t.best.cameras])))
        lines.append(f"tilted: {t.best.count} cameras, tilted up to {most:.0f}° (of {deg} "
                     f"allowed), from the best {t.best.seed} layout ({solves(t)})")
    else:
        lines.append(f"tilted: none below {t.start} cameras with tilts up to {deg} "
                     f"({solves(t)})")
    return lines


def no_plan_message(site: Site, plan: Plan, max_cameras: int,
                    max_cameras_name: str = "max_cameras") -> str:
    """Why a plan has no candidate, and what would help; ``max_cameras_name``: what the
    caller calls the limit on cameras (a command names its option)."""
    r = site.requirements
    if plan.refused:
        return (f"no layout of up to {max_cameras} cameras can meet the requirements: "
                f"{plan.refused}; raise {max_cameras_name}, relax the requirements or "
                "use a camera with a wider view" + unit_doubt(site))
    m = plan.mended
    kind = "tilted" if site.mounting and site.mounting.max_tilt > 0 else "level"
    tried = "" if m is None else (
        f"; the CasADi optimiser's {kind} cameras found {m.best.count}, more than "
        f"{max_cameras} ({solves(m)})" if m.best is not None else
        f"; the CasADi optimiser's {kind} cameras found none either ({solves(m)})"
        if m.complete else
        f"; the CasADi optimiser's {kind} cameras found none in its time ({solves(m)})")
    c = plan.closest
    best = (f"for comparison, a dense lattice of {c.count} camera"
            f"{'s' if c.count != 1 else ''} covers {c.evaluation.coverage:.1%}"
            + (f" with p95 {c.evaluation.p95 * 100:.2f} cm"
               if math.isfinite(c.evaluation.p95) else "")
            if c else "no layout could be evaluated")
    return (f"no layout of up to {max_cameras} cameras meets coverage "
            f"{r.coverage:.0%} with p95 ≤ {r.max_error_p95 * 100:g} cm ({best}{tried}); relax "
            "the requirements, lower the LED heights or use a camera with more pixels"
            + unit_doubt(site))


def mounting_lines(cameras) -> list[str]:
    """How to hang a layout whose cameras are not all level (none when they are): per camera
    where, the bracket's turn about the vertical, and which way and how far it tilts (what
    the maps draw)."""
    poses = [pose_of(c) for c in cameras]
    if all(math.hypot(p[3], p[4]) < math.radians(0.5) for p in poses):
        return []
    lines = ["how to hang it (turn: the level camera's image x axis from the room's x "
             "axis, set first; then tilt the optical axis toward the direction given, "
             "degrees from the room's x axis):"]
    for c, p in zip(cameras, poses):
        tilt = math.degrees(math.hypot(p[3], p[4]))
        toward = round(math.degrees(math.atan2(p[3], -p[4]))) % 360  # leans along (−wy, wx)
        lines.append(f"  {c.id:>4s} at ({p[0]:.2f}, {p[1]:.2f}) m: turn "
                     f"{round(math.degrees(p[2])) % 360:3d}°, tilt {tilt:2.0f}°"
                     + (f" toward {toward:3d}°" if tilt >= 0.5 else ""))
    return lines


def mount_grid(site: Site) -> str:
    """The site's mounting grid, said in the unit a person would use."""
    step = mount_step(site)
    return f"{step * 100:.3g} cm" if step >= 0.01 else f"{step * 1000:.3g} mm"


def _some(items: list[str]) -> str:
    """The first five of a list, and an ellipsis when there are more."""
    return f"{', '.join(items[:5])}{' …' if len(items) > 5 else ''}"


def check_lines(check: LayoutCheck, site: Site, site_source: str,
                layout_source: str) -> list[str]:
    """A layout's check against a site (the files named as given), up to its figures; the
    verdict is :func:`verdict_line`."""
    r, ev = site.requirements, check.evaluation
    hs = ", ".join(f"{h:g}" for h in check.levels)
    n = check.cameras
    lines = [f"{layout_source}: {n} camera{'' if n == 1 else 's'} judged against "
             f"{site_source} ({site.name}; LED at {hs} m, {r.min_cameras} cameras per point, "
             f"spot noise {r.pixel_noise:g} px):"]
    if check.other_size:
        lines.append(f"  note: {_some(list(check.other_size))} have another image size than "
                     "the site's camera model; each camera is judged as it is")
    if check.too_tilted:
        lines.append(f"  note: {_some([f'{c} ({t:.1f}°)' for c, t in check.too_tilted])} "
                     f"tilt past the site's max_tilt "
                     f"({math.degrees(site.mounting.max_tilt):g}°); judged as they are")
    if check.near_wall:
        lines.append(f"  note: {_some([f'{c} ({d:.2f} m)' for c, d in check.near_wall])} "
                     f"hang closer to a wall than the site's wall_clearance "
                     f"({site.mounting.wall_clearance:g} m); judged as they are")
    if check.outside or check.above:
        lines.append(f"  note: camera(s) {', '.join((check.outside + check.above)[:5])} hang "
                     "outside the room or above its ceiling; judged as they are")
    p95 = f"{ev.p95 * 100:.2f} cm" if math.isfinite(ev.p95) else "–"
    mean = f"{ev.mean * 100:.2f} cm" if math.isfinite(ev.mean) else "–"
    lines.append(f"  coverage {ev.coverage:.1%} (required {r.coverage:.1%}): the share of the "
                 f"floor's sample points seen by {r.min_cameras} or more cameras")
    lines.append(f"  predicted error over those points: p95 {p95} (required ≤ "
                 f"{r.max_error_p95 * 100:.3g} cm), mean {mean}")
    if check.room_differs:
        lines.append("  note: the deployment's room differs from the site's; the site's is "
                     "used")
    return lines


def verdict_line(check: LayoutCheck, site: Site) -> str:
    """The check's verdict, with the reasons when the layout does not meet the site."""
    r, ev = site.requirements, check.evaluation
    why = []
    if ev.coverage < r.coverage:
        why.append(f"coverage {ev.coverage:.1%} < {r.coverage:.1%}")
    if not ev.p95 <= r.max_error_p95:
        why.append(f"p95 {ev.p95 * 100:.3f} cm > {r.max_error_p95 * 100:.3f} cm"
                   if math.isfinite(ev.p95) else "p95 unbounded: some points are seen by "
                   "cameras at one place only, which cannot triangulate them")
    if why:
        return f"verdict: does not meet the site ({'; '.join(why)})"
    return "verdict: meets the site"


def zones_lines(zoning: Zoning, replaced: bool = False) -> list[str]:
    """A site's zones: one line each (its rectangle, its cameras), then the balance."""
    strips, pieces = zoning.grid
    cut = f"{strips} strip{'s' * (strips > 1)}" + (f" × {pieces}" if pieces > 1 else "")
    lines = [f"{len(zoning.zones)} zones ({cut}) over {zoning.cameras} cameras"
             + (" (the deployment's zones: replaced)" if replaced else "") + ":"]
    for z in zoning.zones:
        (x0, y0), _, (x1, y1), _ = z.polygon
        lines.append(f"  {z.id}: x {min(x0, x1):.2f}–{max(x0, x1):.2f} m, y {min(y0, y1):.2f}–"
                     f"{max(y0, y1):.2f} m, {len(z.cameras)} cameras ({_some(list(z.cameras))})")
    loads = zoning.loads
    lines.append(f"load: {loads.min()}–{loads.max()} cameras a zone (the most loaded "
                 f"{zoning.imbalance:.0%} over the mean); {zoning.shared} cameras on a border, "
                 "in two zones or more")
    return lines
