"""Simulated data on disk in vlpcal's formats (docs/formats.md): survey bundles, ``locate``
frame folders and deployment files (nominal, and the true cameras for evaluation). shapely, a
heavy import, is imported where a room's or keep-out's polygon is needed."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..datasets import write_frames_folder, write_survey_bundle, write_truth_csv
from ..deployment import Deployment, provenance, save
from ..survey.linkage import SWEEP_SETS
from ..survey.spots import REST_FRAMES
from ..writing import OutputSet
from .scene import ROBOT_RADIUS, STREAM_PATH, STREAM_TAPE, Scene, render_scene


def free_floor(profile, margin: float = 0.0, clearance: float | None = None):
    """The floor an LED may be carried or driven over: the room shrunk by ``margin`` (m) minus
    every keep-out grown by ``clearance`` (default ``margin``), as a shapely geometry (maybe
    empty)."""
    from shapely.geometry import Polygon
    from shapely.ops import unary_union

    room = Polygon(profile.room).buffer(-margin)
    if not profile.keep_out:
        return room
    grow = margin if clearance is None else clearance
    return room.difference(unary_union([Polygon(k) for k in profile.keep_out]).buffer(grow))


def onto_floor(floor, xy) -> np.ndarray:
    """``xy`` (``N×2``) with every point off ``floor`` (a shapely area) moved to the nearest
    point of it — a path through a wall or a keep-out follows its edge instead; points on the
    floor are left exactly as they are (all of them when there is no floor to go to)."""
    import shapely

    xy = np.array(xy, float)
    if floor.is_empty:
        return xy
    off = ~shapely.intersects_xy(floor, xy[:, 0], xy[:, 1])
    if off.any():
        lines = shapely.shortest_line(shapely.points(xy[off]), floor)
        xy[off] = shapely.get_coordinates(shapely.get_point(lines, 1))
    return xy


def grid_points(scene: Scene, step: float, heights, margin: float = 0.05,
                min_cameras: int = 1) -> np.ndarray:
    """A grid of LED points over the room (``step`` m) at each height, outside the keep-outs,
    kept where at least ``min_cameras`` true cameras see them: ``N×3``."""
    from shapely import contains_xy

    room = free_floor(scene.profile, margin)
    if room.is_empty:  # keep-outs over the whole floor
        return np.zeros((0, 3))
    x0, y0, x1, y1 = room.bounds
    gx, gy = np.meshgrid(np.arange(x0, x1 + 1e-9, step), np.arange(y0, y1 + 1e-9, step))
    xy = np.c_[gx.ravel(), gy.ravel()]
    xy = xy[contains_xy(room, xy[:, 0], xy[:, 1])]
    pts = np.concatenate([np.c_[xy, np.full(len(xy), h)] for h in heights])
    seen = np.stack([c.project(pts, margin=1.0)[2] for c in scene.true]).sum(axis=0)
    return pts[seen >= min_cameras]


def trajectory(scene: Scene, n: int, height: float = 0.15, seed: int = 0) -> np.ndarray:
    """A robot's LED path: a smooth closed loop inside the room at ``height`` (``n×3``),
    following the edge of a wall or keep-out it would cross."""
    from shapely.geometry import Polygon

    rng = np.random.default_rng([scene.seed, seed, STREAM_PATH])
    x0, y0, x1, y1 = Polygon(scene.profile.room).buffer(-0.3).bounds
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    a, b = rng.uniform(1, 3, 2).round()
    phase = rng.uniform(0, 2 * np.pi)
    x = (x0 + x1) / 2 + (x1 - x0) / 2 * 0.9 * np.sin(a * t + phase)
    y = (y0 + y1) / 2 + (y1 - y0) / 2 * 0.9 * np.sin(b * t)
    xy = onto_floor(free_floor(scene.profile, 0.3), np.c_[x, y])
    return np.c_[xy, np.full(n, height)]


def free_path(scene: Scene, n: int, height: float | None = None, seed: int = 0
              ) -> np.ndarray:
    """A free survey's LED (``n×3``): a person sweeping the room with the LED on a pole, up
    and down between the floor and 40 % of the ceiling's height — or, with ``height``, a robot
    driving the room at that height. Both wander over the whole floor (a Lissajous figure with
    incommensurate frequencies, jittered, as a hand or a planner would), around keep-outs and
    along the walls of a room that is not a rectangle."""
    from shapely.geometry import Polygon

    rng = np.random.default_rng([scene.seed, seed, STREAM_PATH, 2])
    x0, y0, x1, y1 = Polygon(scene.profile.room).buffer(-0.1).bounds
    t = np.linspace(0, 1, n)
    fx, fy, fz = 7.0, 7.0 * np.sqrt(2) + rng.uniform(-0.3, 0.3), 23.0 * np.sqrt(3)
    phase = rng.uniform(0, 2 * np.pi, 3)
    x = (x0 + x1) / 2 + (x1 - x0) / 2 * np.sin(2 * np.pi * fx * t + phase[0])
    y = (y0 + y1) / 2 + (y1 - y0) / 2 * np.sin(2 * np.pi * fy * t + phase[1])
    xy = np.c_[x, y] + rng.normal(0, 0.02 * min(x1 - x0, y1 - y0), (n, 2))
    xy = onto_floor(free_floor(scene.profile, 0.1), np.clip(xy, [x0, y0], [x1, y1]))
    if height is None:
        top = 0.4 * scene.profile.ceiling_height
        z = top * (0.5 + 0.5 * np.sin(2 * np.pi * fz * t + phase[2]))
    else:
        z = np.full(n, float(height))
    return np.c_[xy, z]


#: m (σ): a floor's height about the plane its marks set — a finished floor's flatness
#: tolerance (DIN 18202, table 3: 4 mm over 1 m, 10 mm over 4 m at most) as a scatter
FLOOR_UNEVENNESS = 0.002
#: m: how close to a wall a hand keeps the LED (a pole's, a wand's ends)
WALL_CLEARANCE = 0.1


def route_path(scene: Scene, route, n: int, seed: int = 0) -> np.ndarray:
    """A free survey's LED (``n×3``) carried as a planned route says (``route``: a
    :class:`~vlpcal.survey.free_plan.FreeRoute` in the scene's frame): the ``n`` sets shared
    equally by the stops, in walking order; at each stop the LED swept from the route's foot to
    the stop's top and back, a sweep every :data:`~vlpcal.survey.linkage.SWEEP_SETS` sets,
    landing anywhere within the square the plan allows a stop found by eye; kept off the walls
    and keep-outs."""

    stops = np.asarray(route.stops, float).reshape(-1, 2)
    if not len(stops) or n < 1:
        return np.zeros((0, 3))
    rng = np.random.default_rng([scene.seed, seed, STREAM_PATH, 4])
    at = np.minimum(np.arange(n) * len(stops) // n, len(stops) - 1)  # each set's stop
    r = route.linkage.reach if route.linkage is not None else None
    half = r.reach * r.step if r is not None else 0.0
    xy = stops[at] + rng.uniform(-half, half, (n, 2))
    xy = onto_floor(free_floor(scene.profile, WALL_CLEARANCE), xy)
    first = np.searchsorted(at, at)  # the set each stop starts with
    phase = (np.arange(n) - first) / SWEEP_SETS + rng.uniform(0, 1, len(stops))[at]
    rise = 1.0 - np.abs(1.0 - 2.0 * (phase % 1.0))  # 0 → 1 → 0 over a sweep
    tops = np.asarray(route.tops, float)[at]
    return np.c_[xy, route.low + (tops - route.low) * rise]


def wand_fits(profile, length: float) -> bool:
    """Whether a wand ``length`` m long can be held somewhere with both ends on the free floor
    whatever its direction (its centre :data:`WALL_CLEARANCE` + half its length from every
    wall and keep-out)."""
    return not free_floor(profile, WALL_CLEARANCE + length / 2, length / 2).is_empty


def longest_wand(profile) -> float:
    """m: the longest wand :func:`wand_fits` the room (to a centimetre, rounded down)."""
    lo, hi = 0.0, 2 * max(np.ptp(np.asarray(profile.room, float), axis=0))
    while hi - lo > 0.005:
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if wand_fits(profile, mid) else (lo, mid)
    return np.floor(lo * 100) / 100


def wand_path(scene: Scene, n: int, length: float, seed: int = 0, centre=None
              ) -> np.ndarray:
    """A wand's two LEDs (``n×2×3``, LED A then B, ``length`` m apart) waved through the room
    by a person: its centre follows :func:`free_path` (squeezed so that both ends stay on the
    free floor, :func:`wand_fits`), its direction wanders smoothly and at random over the
    sphere (its elevation and heading sums of slow sines), and both LEDs stay between the
    floor and 40 % of the ceiling's height — a direction too steep for that is flattened, and
    the centre rides as high as the ends allow. ``centre``: the path (``n×3``, from the floor
    to 40 % of the ceiling) the centre follows instead, e.g. :func:`route_path`'s. ``ValueError``
    when the wand cannot fit."""
    p = scene.profile
    if not (np.isfinite(length) and length > 0):
        raise ValueError(f"a wand's length must be a positive number of metres, got {length}")
    if not wand_fits(p, length):
        raise ValueError(f"a wand {length:g} m long does not fit in this room: its ends would "
                         "cross a wall or a keep-out wherever it is held (at most "
                         f"{longest_wand(p):.2f} m here)")
    top = 0.4 * p.ceiling_height
    centre = free_path(scene, n, None, seed) if centre is None else np.asarray(centre, float)
    # the free path's rectangle mapped onto the one the centre may use, then onto its floor
    floor = free_floor(p, WALL_CLEARANCE + length / 2, length / 2)
    a0, b0, a1, b1 = free_floor(p, WALL_CLEARANCE).bounds
    c0, d0, c1, d1 = floor.bounds
    xy = np.c_[c0 + (centre[:, 0] - a0) * (c1 - c0) / max(a1 - a0, 1e-12),
               d0 + (centre[:, 1] - b0) * (d1 - d0) / max(b1 - b0, 1e-12)]
    xy = onto_floor(floor, xy)
    rng = np.random.default_rng([scene.seed, seed, STREAM_PATH, 3])
    t = np.linspace(0, 1, n)

    def slow(lo, hi):  # three sines of lo–hi cycles over the whole survey, summed
        f, ph = rng.uniform(lo, hi, 3), rng.uniform(0, 2 * np.pi, 3)
        return np.sin(2 * np.pi * f[:, None] * t + ph[:, None]).sum(axis=0)

    # elevation up to ±85°, mostly nearer level; heading turning to and fro and round
    elevation = 0.95 * np.pi / 2 * slow(8.0, 30.0) / 3
    heading = 1.5 * slow(4.0, 16.0) + 2 * np.pi * (rng.uniform(-8, 8) * t + rng.uniform())
    # steep enough to leave [0, top] at both ends: flattened, keeping its heading
    dz = np.clip(np.sin(elevation), -0.9 * top / length, 0.9 * top / length)
    d = np.c_[np.c_[np.cos(heading), np.sin(heading)] * np.sqrt(1 - dz ** 2)[:, None], dz]
    half = 0.5 * length * np.abs(dz)
    z = half + (top - 2 * half) * np.clip(centre[:, 2] / top, 0.0, 1.0)
    mid = np.c_[xy, z]
    return np.stack([mid - 0.5 * length * d, mid + 0.5 * length * d], axis=1)


def simulate_free_survey(scene: Scene, root, references, n_free: int, seed: int = 0,
                         height: float | None = None, overwrite: bool = False,
                         carrier_radius: float | None = None, wand: float | None = None,
                         marks=None, truth=None, route=None):
    """A free survey bundle: the ``references`` (true positions) taped to
    ± ``profile.tape`` per axis with a burst of :data:`~vlpcal.survey.spots.REST_FRAMES`
    frames each (the LED rests there), and ``n_free`` free sets of the LED moved
    along :func:`free_path` (its positions unrecorded, as in life; a robot's body hides the
    floor under its LED, ``carrier_radius``, by default :data:`~.scene.ROBOT_RADIUS`).
    Returns (measured references ``N×3``, the free LED's true positions ``M×3``).

    ``wand`` (m): every free set shows two LEDs that far apart on a rigid bar waved by hand
    (:func:`wand_path`; not with ``height``); the true positions are then ``M×2×3`` (LED A,
    then B). A camera that sees either LED keeps its frame. The references show one LED.

    ``marks``: ``(ids, measured)``: the references' point ids (N) and which coordinates the
    survey records (``N×3`` booleans) — frame marks (docs/formats.md#survey-bundle-a-folder): an
    unmeasured coordinate is written NaN (an empty cell). A measured coordinate that is 0 (the
    origin mark, the x mark's y and z, the floor) is set by definition, not read off a tape: it
    is written 0 exactly. A mark is where the LED stood (its x and y define the frame), but the
    floor under it is not a plane: a height of 0 is off by ± :data:`FLOOR_UNEVENNESS`. Any other
    measured coordinate is taped (written ± ``profile.tape``). Without ``marks``: ids ``R01``…,
    every coordinate taped.

    ``route``: a planned route (:class:`~vlpcal.survey.free_plan.FreeRoute`, in the scene's frame)
    the LED — or the wand's centre — follows (:func:`route_path`) instead of wandering the
    room; not with ``height``.

    ``truth``: a CSV to write the free LED's true positions to (``set_id,led,x,y,z``, LED
    ``A``, and ``B`` for a wand's other; every set, seen or not), or None.
    """
    refs = np.asarray(references, float).reshape(-1, 3)
    n = len(refs)
    ids, measured = _marks(marks, n)
    if wand is not None and height is not None:
        raise ValueError("a wand is waved by hand: it has no height of its own")
    if route is not None and height is not None:
        raise ValueError("a route is walked with the LED on a pole: it has no height of its own")
    walked = route_path(scene, route, n_free, seed) if route is not None else None
    path = (free_path(scene, n_free, height, seed) if walked is None else walked) \
        if wand is None else wand_path(scene, n_free, wand, seed, centre=walked)
    if carrier_radius is None:
        carrier_radius = 0.0 if height is None else ROBOT_RADIUS
    placed, record = reference_placings(scene, refs, measured, seed)
    # each reference a burst: the LED rests there for REST_FRAMES frames
    rest = np.repeat(placed, REST_FRAMES, axis=0)
    r = len(rest)
    carrier = np.r_[np.zeros(r), np.full(n_free, carrier_radius)]
    if wand is None:
        frames, seen = render_scene(scene, np.vstack([rest, path]), seed=seed,
                                    carrier_radius=carrier, only_seen=True)
    else:
        # the references are one LED: the wand's second LED off
        both = np.concatenate([np.repeat(rest[:, None], 2, axis=1), path])
        on = np.r_[np.tile([True, False], (r, 1)), np.ones((n_free, 2), bool)]
        frames, seen = render_scene(scene, both, seed=seed, carrier_radius=carrier, on=on,
                                    only_seen=True)
        seen = seen.any(axis=2)
    kept = {cid: [f if s else None for f, s in zip(jpegs, seen[k])]
            for k, (cid, jpegs) in enumerate(frames.items())}
    bursts = {c: [[f for f in v[i:i + REST_FRAMES] if f is not None] or None
                  for i in range(0, r, REST_FRAMES)] for c, v in kept.items()}
    free_ids = [f"F{i + 1:05d}" for i in range(n_free)]
    write_survey_bundle(root, ids, record, bursts, overwrite=overwrite,
                        free_frames={c: v[r:] for c, v in kept.items()},
                        free_ids=free_ids)
    if truth is not None:
        write_led_truth(truth, free_ids, path)
    return record, path


def reference_placings(scene: Scene, refs, measured=None, seed: int = 0):
    """Where the LED really stood at each reference (``N×3``) and what the survey records (NaN:
    not measured), as :func:`simulate_free_survey` draws them: taped points off by
    ± ``profile.tape`` in the record; marks (``measured`` N×3) exact where they define the
    frame, their height off by the floor's unevenness."""
    refs = np.asarray(refs, float)
    rng = np.random.default_rng([scene.seed, seed, STREAM_TAPE])
    noise = rng.normal(0.0, scene.profile.tape, refs.shape)
    if measured is None:
        return refs, refs + noise
    defined = measured & (refs == 0.0)
    floor = rng.normal(0.0, FLOOR_UNEVENNESS, len(refs))
    placed = refs + np.where(defined & [False, False, True], floor[:, None], 0.0)
    return placed, np.where(measured, refs + np.where(defined, 0.0, noise), np.nan)


def _marks(marks, n: int):
    """``(ids, measured N×3 or None)`` from :func:`simulate_free_survey`'s ``marks``."""
    if marks is None:
        return [f"R{i + 1:02d}" for i in range(n)], None
    try:
        ids, measured = marks
    except (TypeError, ValueError):
        raise ValueError("marks: expected (point ids, N×3 booleans of the measured "
                         "coordinates)") from None
    ids = [str(i) for i in ids]
    measured = np.asarray(measured)
    if len(ids) != n or measured.shape != (n, 3) or measured.dtype != bool:
        raise ValueError(f"marks: expected {n} point ids and {n}×3 booleans for the {n} "
                         f"references, got {len(ids)} ids and {measured.dtype} "
                         f"{measured.shape}")
    if not measured.any(axis=1).all():
        k = int(np.flatnonzero(~measured.any(axis=1))[0])
        raise ValueError(f"marks: {ids[k]} has no measured coordinate (a point with none "
                         "tells the survey nothing)")
    return ids, measured


def write_led_truth(path, set_ids, positions) -> None:
    """Where each LED really was at each set: ``set_id,led,x,y,z`` (m), LEDs ``A``, ``B``… —
    one row per LED and set (``positions`` ``M×3`` for one LED or ``M×K×3``)."""

    pos = np.asarray(positions, float)
    pos = pos[:, None] if pos.ndim == 2 else pos
    names = [chr(ord("A") + k) for k in range(pos.shape[1])]
    with OutputSet(path) as (tmp,), open(tmp, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(("set_id", "led", "x", "y", "z"))
        w.writerows((sid, led, *(repr(round(float(v), 9)) for v in x))
                    for sid, xs in zip(set_ids, pos) for led, x in zip(names, xs))


def deployment_of(scene: Scene, which: str = "nominal", blocks: dict | None = None
                  ) -> Deployment:
    """The scene's ``nominal`` (what the installer believes) or ``true`` cameras as a file,
    with optional ``blocks`` (the ``leds:`` and ``bodies:`` of the LEDs it carries)."""
    p = scene.profile
    cams = list(scene.nominal if which == "nominal" else scene.true)
    prov = provenance("vlpcal simulate", profile=p.name, seed=scene.seed, cameras=which)
    return Deployment(f"{p.name}-sim", p.ceiling_height, [list(xy) for xy in p.room], cams,
                      [[list(xy) for xy in k] for k in p.keep_out],
                      extra={**(blocks or {}), "provenance": prov})


def write_deployments(scene: Scene, out, blocks: dict | None = None) -> tuple[Path, Path]:
    """``nominal.yaml`` (to calibrate) and ``truth.yaml`` (to evaluate against) in ``out``
    (``blocks``: as :func:`deployment_of` takes them)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = out / "nominal.yaml", out / "truth.yaml"
    save(deployment_of(scene, "nominal", blocks), paths[0],
         header=f"Simulated {scene.profile.name} install (seed {scene.seed}): the cameras as "
                "the installer believes them.")
    save(deployment_of(scene, "true", blocks), paths[1],
         header=f"Simulated {scene.profile.name} install (seed {scene.seed}): the cameras as "
                "they really are (for evaluation only).")
    return paths


def simulate_survey(scene: Scene, root, points, seed: int = 0, overwrite: bool = False):
    """Render a survey at ``points`` (true positions) and write the bundle; ``points.csv``
    records the positions as a tape measure would give them (± ``profile.tape`` per axis).
    Returns the measured positions."""
    points = np.asarray(points, float)
    frames, seen = render_scene(scene, points, seed=seed, only_seen=True)
    rng = np.random.default_rng([scene.seed, seed, STREAM_TAPE])
    measured = points + rng.normal(0.0, scene.profile.tape, points.shape)
    ids = [f"S{i + 1:04d}" for i in range(len(points))]
    kept = {cid: [f if s else None for f, s in zip(jpegs, seen[k])]
            for k, (cid, jpegs) in enumerate(frames.items())}
    write_survey_bundle(root, ids, measured, kept, overwrite=overwrite)
    return measured


def simulate_frames(scene: Scene, root, points, seed: int = 0, overwrite: bool = False):
    """Render a ``locate`` frames folder (every camera sends a frame for every instant) and
    write ``truth.csv`` beside it (``<root>.truth.csv``)."""
    points = np.asarray(points, float)
    frames, _ = render_scene(scene, points, seed=seed)
    ids = [f"{i:06d}" for i in range(len(points))]
    root = Path(root)
    write_frames_folder(root, ids, frames, overwrite=overwrite)
    write_truth_csv(root.with_name(root.name + ".truth.csv"), ids, points)
    return ids
