"""Planning a tape survey: where to put the LED, in the order an installer walks, on a grid
as fine as the cameras' precision needs. A free or wand survey's plans are
:mod:`.free_plan`'s."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from shapely import contains_xy, union_all
from shapely.geometry import Polygon, box

from .budget import calibration_ratio
from .errors import SurveyError
from .lens import MIN_POINTS_POSE

#: points a survey plan gives each camera by default: twice what its pose needs, so that a
#: k-fold check can judge a lens fit (more points let it fit more of the lens)
MIN_POINTS_PLANNED = 12
#: spots as precise as the default detector gets them (``blob``, 0.03 px RMS on saturated
#: spots, README's detector table): a survey sized for the best spots is enough for worse ones
SPOT_NOISE_PX = 0.03
#: a tape measure, per axis
TAPE_M = 0.003
#: the grid is made finer until the calibration it allows adds at most this share to the
#: cameras' own mean error, for a typical tape (the median of the predicted draws) …
TYPICAL_SHARE = 0.10
#: … and at most this share for an unlucky one (their 95th percentile)
UNLUCKY_SHARE = 0.20
#: the finest grid stops before this many points (days of work with a tape; beyond it a free
#: survey, or a more precise measurement, is the way)
MAX_PLANNED_POINTS = 1500


def tape_mark(tape: float) -> float:
    """m: what a tape measuring to ``tape`` per axis marks — the decimal unit at or under its
    precision (±3 mm: 1 mm)."""
    return float(10.0 ** np.floor(np.log10(tape) + 1e-9))


def to_marks(xyz, tape: float = TAPE_M) -> np.ndarray:
    """Planned positions rounded to what the tape marks: a surveyor reads 1.234 m, not
    1.23456789."""
    q = tape_mark(tape)
    return np.round(np.asarray(xyz, float) / q) * q


def duration_words(minutes: float) -> str:
    """A survey's time as a person says it: ``12 min``, ``3.5 h``."""
    if minutes < 90:
        return f"{max(1, round(minutes)):d} min"
    return f"{minutes / 60:.1f} h"


#: about this long (min) to place the LED at a point, measure it and let the cameras see it
MINUTES_PER_POINT = 1.0


@dataclass
class SurveyPlan:
    """Points to measure: ids in walking order, planned positions N×3, who sees what."""

    ids: list[str]
    xyz: np.ndarray
    seen: np.ndarray  # C×N: each camera sees the point (nominal cameras, 5 px margin)
    camera_ids: list[str]
    step: float = float("nan")  #: the grid's spacing, m
    #: predicted mean fix error with cameras calibrated from these points ÷ with exact
    #: cameras: (typical, unlucky) — :func:`.budget.calibration_ratio`
    predicted: tuple[float, float] = (float("nan"), float("nan"))
    tape: float = TAPE_M
    spot_noise: float = SPOT_NOISE_PX
    #: the coarser grids tried first: (step m, points, typical, unlucky)
    coarser: list = field(default_factory=list)
    capped: bool = False  #: a finer grid would have passed :data:`MAX_PLANNED_POINTS`

    @property
    def mark(self) -> float:
        """m: what the tape marks, to which the positions are rounded (:func:`tape_mark`)."""
        return tape_mark(self.tape)

    @property
    def minutes(self) -> float:
        """About how long measuring the points takes (:data:`MINUTES_PER_POINT` each)."""
        return len(self.ids) * MINUTES_PER_POINT

    @property
    def meets_budget(self) -> bool:
        """The calibration these points allow stays within the planned shares (or nothing
        could be predicted: no place seen by two cameras)."""
        typical, unlucky = self.predicted
        return not (typical > 1 + TYPICAL_SHARE or unlucky > 1 + UNLUCKY_SHARE)


def plan_survey(deployment, step: float | None = None, heights=(0.0, 0.35, 0.7),
                min_per_camera: int = MIN_POINTS_PLANNED, min_per_pair: int = 6,
                margin_px: float = 5.0, tape: float = TAPE_M,
                spot_noise: float = SPOT_NOISE_PX) -> SurveyPlan:
    """The points to measure: a grid over the room (minus keep-out areas) at each height, kept
    where a camera sees them, made finer where a camera or an overlapping pair of cameras would
    otherwise get fewer than ``min_per_camera`` / ``min_per_pair`` points. Two heights or more:
    a floor-only survey cannot separate a camera's height from its focal length.

    ``step`` None: as fine as the cameras' precision asks. Each point's tape error (``tape`` m)
    stays in the calibrated cameras, averaged over the points; precise cameras (``spot_noise``
    px, many px per metre) need many points before that average falls below their own noise.
    The grid starts at an eighth of a camera's floor footprint and is made finer by √2 until
    the predicted calibration adds at most :data:`TYPICAL_SHARE` to the fixes' mean error
    (:data:`UNLUCKY_SHARE` for an unlucky tape), or until :data:`MAX_PLANNED_POINTS`.
    Relative throughout: the same scene at any scale, its tape scaled alike, gets the same plan.

    Ids follow the order an installer walks: height by height, rows in a serpentine.
    """
    if step is not None:
        return _plan_grid(deployment, step, heights, min_per_camera, min_per_pair,
                          margin_px, tape, spot_noise)
    cams = deployment.cameras
    reach = float(np.median([max(c.width / c.fx, c.height / c.fy)
                             * (c.position[2] - min(heights)) for c in cams]))
    if not reach > 0:
        raise SurveyError("the cameras are not above the survey's heights")
    step = reach / 8
    plan = _plan_grid(deployment, step, heights, min_per_camera, min_per_pair, margin_px,
                      tape, spot_noise)
    tried: list = []
    while not plan.meets_budget:
        if len(plan.ids) * 2 > MAX_PLANNED_POINTS:  # the next grid has about twice the points
            plan.capped = True
            break
        finer = _plan_grid(deployment, step / np.sqrt(2), heights, min_per_camera,
                           min_per_pair, margin_px, tape, spot_noise, predict=False)
        if len(finer.ids) > MAX_PLANNED_POINTS:
            plan.capped = True
            break
        _predict(finer, deployment, heights, margin_px)
        tried.append((plan.step, len(plan.ids), *plan.predicted))
        step, plan = step / np.sqrt(2), finer
    plan.coarser = tried
    return plan


#: a grid of more points than this is refused before it is built (memory and time)
MAX_GRID_POINTS = 50_000


def _plan_grid(deployment, step, heights, min_per_camera, min_per_pair, margin_px, tape,
               spot_noise, predict: bool = True) -> SurveyPlan:
    """:func:`plan_survey` at a stated grid spacing, with its predicted calibration."""
    heights = sorted(set(float(h) for h in heights))
    if len(heights) < 2:
        raise SurveyError("a survey needs points at two or more heights (a floor-only survey "
                          "cannot separate height from scale)")
    room = survey_floor(deployment)
    if room.is_empty:
        raise SurveyError("the keep-out areas leave no floor to survey")
    room = room.intersection(_views_box(deployment.cameras, min(heights), room))  # in view
    if room.is_empty:
        raise SurveyError("no camera looks at the room's floor")
    if room.area < (step / 2) ** 2:
        raise SurveyError(f"the floor ({room.area:.3g} m²) is smaller than one grid cell of "
                          f"{step:g} m: choose a finer step")
    count = room.area / step ** 2 * len(heights)
    if count > MAX_GRID_POINTS:
        raise SurveyError(f"a grid step of {step:g} m would lay about {count:.3g} points "
                          f"(at most {MAX_GRID_POINTS}): choose a coarser step")
    cams = deployment.cameras

    def grid(s, offset=0.0):
        x0, y0, x1, y1 = room.bounds
        gx, gy = np.meshgrid(np.arange(x0 + s / 2 + offset, x1, s),
                             np.arange(y0 + s / 2 + offset, y1, s))
        xy = np.c_[gx.ravel(), gy.ravel()]
        return xy[contains_xy(room, xy[:, 0], xy[:, 1])]

    def seen_by(pts):
        return np.stack([c.project(pts, margin=margin_px)[2] for c in cams])

    base = grid(step)
    pts = np.concatenate([np.c_[base, np.full(len(base), h)] for h in heights])
    pts = pts[seen_by(pts).any(axis=0)]
    # where a camera or an overlapping pair has too few points: add a finer grid there
    quantum = step * 1e-6  # points closer than this are one (relative: any scale alike)
    for level in (2, 4):
        seen = seen_by(pts).astype(np.float32)
        shared = seen @ seen.T  # points each pair of cameras shares
        short = np.diag(shared) < min_per_camera
        fine_xy = grid(step / level, step / (2 * level))
        fine = np.concatenate([np.c_[fine_xy, np.full(len(fine_xy), h)] for h in heights])
        # only cameras that lack points, alone or with a neighbour, ask for the finer grid
        near = short | (shared < min_per_pair).any(axis=1)
        if not near.any():
            break
        fine_seen = np.zeros((len(cams), len(fine)), np.float32)
        fine_seen[near] = np.stack([cams[k].project(fine, margin=margin_px)[2]
                                    for k in np.flatnonzero(near)])
        overlap = (fine_seen @ fine_seen.T) > 0
        lacking = overlap & (shared < min_per_pair)  # overlapping pairs short of shared points
        np.fill_diagonal(lacking, False)
        want = (fine_seen[short] > 0).any(axis=0) | \
            ((fine_seen.T @ lacking.astype(np.float32)) * fine_seen.T > 0).any(axis=1)
        if not want.any():
            break
        pts = np.concatenate([pts, fine[want]])
        _, first = np.unique(np.round(pts / quantum), axis=0, return_index=True)
        pts = pts[np.sort(first)]
    pts = to_marks(pts, tape)  # what the tape marks; points it merges are one
    _, first = np.unique(np.round(pts / quantum), axis=0, return_index=True)
    pts = pts[np.sort(first)]
    seen = seen_by(pts)
    for k, cam in enumerate(cams):
        if seen[k].sum() < MIN_POINTS_POSE:
            raise SurveyError(f"camera {cam.id}: sees only {int(seen[k].sum())} points of the "
                              "room at these heights (is it looking at the floor, or is the "
                              "grid step too coarse for its view?)")
    order = walking_order(pts, quantum)
    pts, seen = pts[order], seen[:, order]
    ids = [f"S{i + 1:04d}" for i in range(len(pts))]
    plan = SurveyPlan(ids, pts, seen, [c.id for c in cams], float(step), tape=float(tape),
                      spot_noise=float(spot_noise))
    if predict:
        _predict(plan, deployment, heights, margin_px)
    return plan


def survey_floor(deployment):
    """The room's floor less its keep-out areas (a shapely geometry)."""
    room = Polygon(deployment.room)
    for poly in deployment.keep_out:
        room = room.difference(Polygon(poly))
    return room


def _views_box(cams, height: float, room):
    """Where on the floor (at ``height``) the cameras look: the union of each camera's view's
    bounding box — a grid beyond it would be points no camera sees."""

    boxes = []
    for c in cams:
        u = np.array([0.0, c.width - 1.0, c.width - 1.0, 0.0, (c.width - 1) / 2])
        v = np.array([0.0, 0.0, c.height - 1.0, c.height - 1.0, (c.height - 1) / 2])
        xy = c.ground(np.c_[u, v], height)
        ok = np.isfinite(xy).all(axis=1)
        if ok.sum() < 4:  # a view that does not meet the floor all round: the whole room
            boxes.append(room.envelope)
            continue
        xy = xy[ok]
        (x0, y0), (x1, y1) = xy.min(axis=0), xy.max(axis=0)
        pad = 0.05 * max(x1 - x0, y1 - y0)
        boxes.append(box(x0 - pad, y0 - pad, x1 + pad, y1 + pad))
    return union_all(boxes) if boxes else Polygon()


def _predict(plan: SurveyPlan, deployment, heights, margin_px) -> None:
    """Set ``plan.predicted``: what calibrating from it costs the fixes."""
    room = survey_floor(deployment)
    plan.predicted = calibration_ratio(deployment.cameras, plan.xyz,
                                       _fix_places(room, heights, plan.step), plan.tape,
                                       plan.spot_noise, margin_px=margin_px)


#: at most this many places judge a survey's predicted calibration
FIX_PLACES = 1500


def _fix_places(room, heights, step) -> np.ndarray:
    """Where fixes are judged: a grid offset from the survey's, at its heights and halfway
    between them, thinned evenly to :data:`FIX_PLACES`."""
    x0, y0, x1, y1 = room.bounds
    s = step / 1.7
    gx, gy = np.meshgrid(np.arange(x0 + s / 3, x1, s), np.arange(y0 + s / 3, y1, s))
    xy = np.c_[gx.ravel(), gy.ravel()]
    xy = xy[contains_xy(room, xy[:, 0], xy[:, 1])]
    hs = sorted(set(heights))
    levels = hs + [(a + b) / 2 for a, b in zip(hs, hs[1:])]
    pts = np.concatenate([np.c_[xy, np.full(len(xy), h)] for h in levels])
    if len(pts) > FIX_PLACES:
        pts = pts[np.linspace(0, len(pts) - 1, FIX_PLACES).round().astype(int)]
    return pts


def walking_order(pts: np.ndarray, quantum: float) -> np.ndarray:
    """The order an installer walks the points: height by height, row by row (rows of equal
    y), each row entered from the end nearer to where the last one left off — a serpentine
    even where the finer grid makes rows of unequal extent."""
    order: list = []
    x_at = None
    key = np.round(pts / quantum).astype(np.int64)  # equal heights and rows, at any scale
    for z in np.unique(key[:, 2]):
        on = np.flatnonzero(key[:, 2] == z)
        for y in np.unique(key[on, 1]):
            row = on[key[on, 1] == y]
            row = row[np.argsort(pts[row, 0], kind="stable")]
            if x_at is not None and abs(pts[row[-1], 0] - x_at) < abs(pts[row[0], 0] - x_at):
                row = row[::-1]
            order.extend(row.tolist())
            x_at = pts[row[-1], 0]
    return np.array(order, int)
