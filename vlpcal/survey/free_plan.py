"""Planning a free or wand survey: the reference points to measure (or the frame marks to put
on the floor), and the route to carry the LED — or wave the wand — along while the cameras
record, stopping where it links every camera the geometry lets it link."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from shapely import contains_xy

from .errors import SurveyError
from .frame_error import frame_errors, mark_covariances, roles_information, zone_weight
from .free_checks import MIN_SHARED
from .linkage import (
    PLACING_SHARE,
    SWEEP_SECONDS,
    SWEEP_SETS,
    WALK_SPEED,
    _box,
    _components,
    footprint,
    link_cameras,
    reach,
)
from .plan import (
    TAPE_M,
    SurveyPlan,
    survey_floor,
    to_marks,
    walking_order,
)


def plan_references(deployment, count: int | None = None, heights=None,
                    margin_px: float = 5.0, tape: float = TAPE_M) -> SurveyPlan:
    """Where a free survey's reference points go: where two or more cameras see
    them, spread over the room (farthest-point order) at three heights (:data:`REFERENCE_HEIGHTS`
    of the ceiling: cameras that all look down cannot tell a longer focal length from a
    deeper LED by the free LED alone; references spread in depth tell them), and where cameras
    overlap only in pairs (a line of cameras chained by small overlaps) and the count allows
    two in every overlap, at least that. ``count``: 6 where some point is seen by three cameras
    or more, else four per overlapping pair, at most 12 — or as given. Ids ``R01``… in walking
    order; positions to the marks of a tape measuring to ``tape`` (:func:`to_marks`).

    With more overlapping pairs than the count (twelve cameras), each overlap gets its share
    only where the count has one for each, and the farthest-point order spreads the rest:
    pairs taken in turn, two each, would use up the count in the first few overlaps and leave
    the rest of the room without a reference."""
    cams = deployment.cameras
    room = survey_floor(deployment)
    if room.is_empty:
        raise SurveyError("the keep-out areas leave no floor to survey")
    if heights is None:
        heights = tuple(round(f * deployment.ceiling_height, 2) for f in REFERENCE_HEIGHTS)
    x0, y0, x1, y1 = room.bounds
    step = max(min(x1 - x0, y1 - y0) / 24, np.sqrt(room.area / 5000))  # ≤ ~5000 places
    gx, gy = np.meshgrid(np.arange(x0 + step / 2, x1, step), np.arange(y0 + step / 2, y1, step))
    xy = np.c_[gx.ravel(), gy.ravel()]
    xy = xy[contains_xy(room, xy[:, 0], xy[:, 1])]
    cand = np.concatenate([np.c_[xy, np.full(len(xy), h)] for h in heights])
    seen = np.stack([c.project(cand, margin=margin_px)[2] for c in cams])
    two = seen.sum(axis=0) >= 2
    cand, seen = cand[two], seen[:, two]
    if not len(cand):
        raise SurveyError("no point of the room is seen by two cameras: a free survey needs "
                          "cameras that overlap")
    pairs = [(k, j) for k in range(len(cams)) for j in range(k + 1, len(cams))
             if (seen[k] & seen[j]).any()]
    triples = (seen.sum(axis=0) >= 3).mean() >= 0.5  # cameras overlap in threes, mostly
    if count is None:
        count = 6 if triples else min(12, max(6, 4 * len(pairs)))
    chosen: list = []

    def farthest(pool, n):
        for _ in range(n):
            free = np.setdiff1d(pool, chosen)
            if not len(free):
                return
            if chosen:
                d = np.min(np.linalg.norm(cand[free, None, :2] - cand[None, chosen, :2], axis=2)
                           + 0.5 * np.abs(cand[free, None, 2] - cand[None, chosen, 2]), axis=1)
                chosen.append(int(free[np.argmax(d)]))
            else:
                centre = cand[pool, :2].mean(axis=0)
                chosen.append(int(free[np.argmax(np.linalg.norm(cand[free, :2] - centre, axis=1))]))

    if not triples and len(pairs) <= count:  # every overlap gets its share (one at least)
        for k, j in pairs:
            farthest(np.flatnonzero(seen[k] & seen[j]), count // len(pairs))
    farthest(np.arange(len(cand)), max(0, count - len(chosen)))
    pts = to_marks(cand[chosen[:count]], tape)
    order = walking_order(pts, step * 1e-6)
    pts = pts[order]
    seen = np.stack([c.project(pts, margin=margin_px)[2] for c in cams])
    return SurveyPlan([f"R{i + 1:02d}" for i in range(len(pts))], pts, seen,
                      [c.id for c in cams], tape=float(tape))


@dataclass
class FrameMarks(SurveyPlan):
    """A wand survey's frame marks: ``O`` (the origin), ``X`` (along the frame's +x
    from it) and floor marks ``F1``… at ``xyz`` in the nominal frame (where to put them; seen
    by ``seen``), and ``recorded``: what the survey's ``points.csv`` holds for them (N×3, NaN:
    a coordinate nobody measures — ``O,0,0,0``, ``X,,0,0``, ``F1,,,0``). ``axis``: the nominal
    axis (``x`` or ``y``) the O→X line runs along, which becomes the calibrated frame's x."""

    recorded: np.ndarray = None
    axis: str = "x"


#: floor marks besides O and X: with them, five points fix the floor plane with redundancy
FLOOR_MARKS = 3


#: a frame mark stays this share of the image's shorter side inside every view it counts on:
#: a spot near the border is clipped, and its centre pulled inward (~0.2 px at 5 px), which
#: would tilt or shift the whole frame the marks define
MARK_MARGIN = 0.1


def plan_marks(deployment, floor_marks: int = FLOOR_MARKS, tape: float = TAPE_M) -> FrameMarks:
    """Where a wand survey's frame marks go (no tape: the wand's length gives the scale, the
    marks the frame): every mark on the floor where two cameras or more see it well inside
    their images (:data:`MARK_MARGIN`). ``O`` where the most cameras see it nearest their
    images' centres — the origin is where the cameras agree best, as every fix is measured
    from it — with half the marks' zone ahead of it along one room axis (the nominal x,
    unless the zone is twice as long along y); then ``X`` ahead of it and ``floor_marks``
    marks ``F1``… where they fix the frame best for the fixes (:func:`_frame_marks`)."""
    cams = deployment.cameras
    room = survey_floor(deployment)
    if room.is_empty:
        raise SurveyError("the keep-out areas leave no floor to survey")
    # the grid over the floor the cameras see (a few cameras in a large hall are not lost
    # between the points of a grid over the whole hall)
    x0, y0, x1, y1 = _seen_bounds(cams, room.bounds)
    size = footprint(cams, 0.0)
    area = (x1 - x0) * (y1 - y0)
    step = max(min(x1 - x0, y1 - y0) / 48, np.sqrt(area / 20000))
    gx, gy = np.meshgrid(np.arange(x0 + step / 2, x1, step), np.arange(y0 + step / 2, y1, step))
    pts = np.c_[gx.ravel(), gy.ravel(), np.zeros(gx.size)]

    def inside(P):  # C×N pixels and whether well inside each camera's image
        got = [c.project(P, margin=MARK_MARGIN * min(c.width, c.height)) for c in cams]
        return np.stack([g[0] for g in got]), np.stack([g[2] for g in got])

    uv, views = inside(pts)
    two = contains_xy(room, pts[:, 0], pts[:, 1]) & (views.sum(axis=0) >= 2)
    # a mark is put by eye: it must stay in two views wherever it lands, nearby
    w = int(round(PLACING_SHARE * size / step))
    two = _box(two.reshape(gx.shape)[None].astype(float), w)[0].ravel() > 1 - 1e-9
    xy, uv, views = pts[two, :2], uv[:, two], views[:, two]
    if len(xy) < 2 + floor_marks:
        raise SurveyError("too few places on the floor are seen by two cameras for the frame's "
                          "marks: a wand survey needs cameras that overlap")
    # the axis O→X runs along: x, unless the marks' zone is twice as long along y
    extent = np.ptp(xy, axis=0)
    a = 1 if extent[1] >= 2 * extent[0] else 0
    # O: among places with half the zone still ahead of them along that axis (room for X), the
    # most views, then the nearest the centres of the images that see it
    size_px = np.array([[c.width, c.height] for c in cams], float)[:, None]
    centre = np.array([[c.cx, c.cy] for c in cams])[:, None]
    r = np.nan_to_num(np.linalg.norm((uv - centre) / size_px, axis=2))
    off = np.where(views, r, 0.0).sum(axis=0)
    n_views = views.sum(axis=0)
    # the grid's rows along that axis: how far each place's row runs on ahead of it
    row = np.round((xy[:, 1 - a] - xy[:, 1 - a].min()) / step).astype(int)
    row_end = np.full(row.max() + 1, -np.inf)
    np.maximum.at(row_end, row, xy[:, a])
    room_for_x = row_end[row] - xy[:, a] >= extent[a] / 2
    o = int(np.lexsort((off / n_views, -n_views, ~room_for_x))[0])
    chosen = _frame_marks(cams, xy, views, o, (row == row[o]) & (xy[:, a] > xy[o, a]), a,
                          floor_marks, 2 * PLACING_SHARE * size)
    pts = to_marks(np.c_[xy[chosen], np.zeros(len(chosen))], tape)
    ids = ["O", "X"] + [f"F{i + 1}" for i in range(floor_marks)]
    recorded = np.full((len(ids), 3), np.nan)
    recorded[0] = 0.0
    recorded[1, 1:] = 0.0
    recorded[2:, 2] = 0.0
    return FrameMarks(ids, pts, inside(pts)[1], [c.id for c in cams], tape=float(tape),
                      recorded=recorded, axis="xy"[a])


def _seen_bounds(cams, bounds) -> tuple[float, float, float, float]:
    """``bounds`` (x0, y0, x1, y1, the room's) cut to the box of the cameras' floor
    footprints (their image corners on the floor; the room's where no corner reaches it)."""
    corners = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], float)
    feet = np.vstack([c.ground(corners * [c.width - 1, c.height - 1], 0.0) for c in cams])
    feet = feet[np.isfinite(feet).all(axis=1)]
    if len(feet) < len(cams) * len(corners):  # a view that reaches past the floor's horizon
        return bounds
    lo, hi = feet.min(axis=0), feet.max(axis=0)
    x0, y0, x1, y1 = max(bounds[0], lo[0]), max(bounds[1], lo[1]), min(bounds[2], hi[0]), \
        min(bounds[3], hi[1])
    return (x0, y0, x1, y1) if x1 > x0 and y1 > y0 else bounds


#: ``X`` candidates tried along O's row (evenly spaced): each costs one greedy choice of the
#: floor marks
X_CANDIDATES = 24


def _frame_marks(cams, xy, views, o: int, row, axis: int, floor_marks: int,
                 apart: float) -> list[int]:
    """Indices into ``xy`` (N×2 floor places, ``views`` C×N) of O, X and the floor marks: X on
    ``row`` (N booleans, ahead of O along the plan's ``axis``, 0: x, 1: y; X's recorded zeros
    are the other horizontal coordinate and z) and each floor mark, greedily, where the
    predicted error the frame gives the fixes over the marks' zone is least
    (:mod:`.frame_error`) — a mark far out fixes the floor's tilt with a long lever, one seen
    by more cameras or at a wider angle is placed better; the best trade is measured, not
    guessed. Marks stay ``apart`` m from each other (a mark's spot bias is the same wherever
    it stands, so two marks at one place are one)."""
    P = np.c_[xy, np.zeros(len(xy))]
    cov = mark_covariances(cams, P, views)
    # the model in the room's own measure: from O, in camera heights (a site far from the
    # plan's origin, or at any scale, is judged alike)
    lift = float(np.median([c.position[2] for c in cams])) or 1.0
    Q = (P - P[o]) / lift
    cov = cov / lift ** 2
    weight = zone_weight(np.vstack([Q, Q + [0.0, 0.0, 0.25]]))
    as_o, as_x, on_floor = roles_information(Q, cov, 1 - axis)
    base = as_o[o]
    ahead = np.flatnonzero(row)
    if not len(ahead):
        raise SurveyError("no place ahead of the origin mark is seen by two cameras: a wand "
                          "survey needs cameras that overlap along the room")
    tried = ahead[np.unique(np.linspace(0, len(ahead) - 1, min(X_CANDIDATES, len(ahead)))
                            .round().astype(int))]
    best, best_err = None, np.inf
    for x in tried:
        chosen, info = [o, int(x)], base + as_x[x]
        err = np.inf
        for _ in range(floor_marks):
            far = np.min(np.linalg.norm(xy[:, None] - xy[None, chosen], axis=2), axis=1) >= apart
            errs = np.full(len(xy), np.inf)
            errs[far] = frame_errors(info[None] + on_floor[far], weight)
            f = int(np.argmin(errs))
            if not np.isfinite(errs[f]):
                break
            chosen.append(f)
            info, err = info + on_floor[f], errs[f]
        if len(chosen) == 2 + floor_marks and err < best_err:
            best, best_err = chosen, err
    if best is None:
        raise SurveyError("the floor places two cameras see lie on one line: no floor marks "
                          "can fix the floor's tilt across it")
    return best


#: a free survey's reference points: on the floor, and at these shares of the ceiling's
#: height (a tripod, a pole) — on qvga's three cameras 12 references at 0 and 15 % gave
#: 1.60 × the datum floor, at 0 and 40 % 1.40 ×, at 0, 20 and 40 % 1.15 ×
REFERENCE_HEIGHTS = (0.0, 0.2, 0.4)


@dataclass
class FreeRoute:
    """Where to carry the LED in a free survey: stops in walking order (``N×2`` floor
    positions), at each a sweep from ``low`` up to ``tops[i]`` m (``high`` unless the stop is in
    a thin overlap, which only a low sweep crosses for long) and back; per stop the camera pairs
    it shows the LED to together (half the moments a link needs, or more), and the cameras whose
    image quarter it fills. ``sets``: ``C×C``, the moments each pair is expected to share over
    the whole route; ``linkage``: what the geometry allows (:func:`.linkage.link_cameras`)."""

    stops: np.ndarray
    pairs: list[list[tuple[str, str]]]
    quarters: list[list[str]]
    low: float
    high: float
    tops: np.ndarray = None
    sets: np.ndarray = None
    linkage: object = field(default=None, repr=False)

    def __post_init__(self):
        if self.tops is None:
            self.tops = np.full(len(self.stops), self.high)

    @property
    def groups(self) -> list:
        """Camera ids of each group the route links (pairs sharing
        :data:`MIN_SHARED` moments), the largest first."""

        ids = self.linkage.camera_ids
        return [[ids[k] for k in g] for g in _components(self.sets >= MIN_SHARED)]

    @property
    def minutes(self) -> float:
        """About how long the walk takes: a sweep at each stop, and the walk between them."""
        walk = float(np.linalg.norm(np.diff(self.stops, axis=0), axis=1).sum())
        return (len(self.stops) * SWEEP_SECONDS + walk / WALK_SPEED) / 60


#: image quarters, in words, by (column, row) of the quarter
QUARTER_WORDS = {(0, 0): "top-left", (1, 0): "top-right", (0, 1): "bottom-left",
                 (1, 1): "bottom-right"}


def free_sweep(deployment, wand: float | None = None) -> tuple[float, float]:
    """m: the heights a free survey sweeps its LED between by default — from the floor to 40 %
    of the ceiling, a wand's LEDs half its length higher — kept below nine tenths of the
    lowest camera (the sweep stays under every camera's view)."""
    top = 0.4 * deployment.ceiling_height + (wand / 2 if wand is not None else 0.0)
    under = 0.99 * 0.9 * min(c.position[2] for c in deployment.cameras)
    return 0.0, min(round(top, 2), round(under, 2))


def free_route(deployment, heights=None, margin_px: float = 5.0, obstacles=None) -> FreeRoute:
    """A short walk for a free survey that links every camera the geometry
    lets a free LED link and passes through every quarter of every camera's image: a stop in
    the shared view of each pair a stop can link (:mod:`.linkage`), thin overlaps included —
    there the sweep stays as low as the overlap reaches, else it would cross it in a moment —
    where one stop gives the pair the most, the pair with the least shared air first, until
    every such pair is expected to share :data:`MIN_SHARED` moments over the stops; then
    one under the middle of each image quarter no stop falls in (at ``margin_px``), visited in
    nearest-neighbour order from the stop nearest a corner of the room. At each stop the LED is
    swept up and down: depth is what separates a camera's height from its focal length."""

    cams = deployment.cameras
    if heights is None:
        heights = free_sweep(deployment)
    low, high = float(min(heights)), float(max(heights))
    at = reach(deployment, low, high, obstacles=obstacles)
    linkage = link_cameras(deployment, at=at)
    T = at.top_index
    C = len(cams)
    pairs = [(k, j) for k in range(C) for j in range(k + 1, C)]
    need = MIN_SHARED / SWEEP_SETS
    todo = [p for p in pairs if at.score(*p).best[: T + 1].max() >= need]
    if not todo:
        raise SurveyError("no place in the room is seen by two cameras long enough for a "
                          "free LED to link them: a free survey needs cameras that overlap")
    overlapping = [p for p in pairs if at.score(*p).air > 0]
    got = np.zeros(len(overlapping))
    where = {p: i for i, p in enumerate(overlapping)}
    cells, tops, shown = [], [], []

    def add(cell, m):
        share = at.stop_sets(cell, m, overlapping)
        got[:] += share
        cells.append(cell)
        tops.append(m)
        shown.append([overlapping[i] for i in np.flatnonzero(share >= MIN_SHARED / 2)])

    todo.sort(key=lambda p: (at.score(*p).air, p))  # the least shared air first: least free
    for p in todo:
        if got[where[p]] >= MIN_SHARED:
            continue
        s = at.score(*p)
        m = max(m for m in range(T + 1) if s.best[m] >= need)  # as high as still links
        add(tuple(int(v) for v in s.where[m]), m)
        if p not in shown[-1]:
            shown[-1].append(p)

    def quarter(c, cell):
        uv, _, ok = c.project(np.array([[*at.place(cell), low]]), margin=margin_px)
        return (int(uv[0, 0] >= c.width / 2), int(uv[0, 1] >= c.height / 2)) if ok[0] else None

    for k, c in enumerate(cams):  # every image quarter gets a stop under it, at the sweep's foot
        for qc, qr in QUARTER_WORDS:
            if any(quarter(c, cell) == (qc, qr) for cell in cells):
                continue
            target = c.ground(np.array([[(0.25 + 0.5 * qc) * c.width,
                                         (0.25 + 0.5 * qr) * c.height]]), low)[0]
            if not np.isfinite(target).all():
                continue
            iy, ix = np.nonzero(at.seen[k, 0])
            if len(iy):
                d = np.hypot(at.xs[ix] - target[0], at.ys[iy] - target[1])
                add((int(iy[np.argmin(d)]), int(ix[np.argmin(d)])), T)
    stops = np.array([at.place(cell) for cell in cells])
    ids = [c.id for c in cams]
    pairs_at = [[(ids[k], ids[j]) for k, j in sorted(sh)] for sh in shown]
    quarters_at = [[f"{c.id} {QUARTER_WORDS[q]}" for c in cams if (q := quarter(c, cell))]
                   for cell in cells]
    corners = np.array(at.room.envelope.exterior.coords[:4])
    order = [int(np.argmin(np.min(np.linalg.norm(stops[:, None] - corners[None], axis=2),
                                  axis=1)))]
    while len(order) < len(stops):
        rest = [i for i in range(len(stops)) if i not in order]
        order.append(min(rest, key=lambda i: np.linalg.norm(stops[i] - stops[order[-1]])))
    sets = np.zeros((C, C))
    for (k, j), n in zip(overlapping, got):
        sets[k, j] = sets[j, k] = n
    return FreeRoute(stops[order], [pairs_at[i] for i in order],
                     [quarters_at[i] for i in order], low, high,
                     at.levels[np.array(tops)[order]], sets, linkage)


#: a tape survey this long (min) or longer has a wand survey proposed beside it
WAND_PROPOSED_MINUTES = 60.0
#: the wand a proposal assumes, m between its LEDs
PROPOSED_WAND = 0.5


def wand_alternative(deployment, plan: SurveyPlan) -> FreeRoute | None:
    """Where a tape survey takes hours (:data:`WAND_PROPOSED_MINUTES`), the route a
    :data:`PROPOSED_WAND` wand would be waved along instead, which needs no tape; None where
    the tape survey is short or no wand route links the cameras."""
    if plan.minutes < WAND_PROPOSED_MINUTES:
        return None
    try:
        return free_route(deployment, free_sweep(deployment, PROPOSED_WAND))
    except SurveyError:
        return None
