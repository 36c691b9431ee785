"""The reference model that judges every layout — the one contract ``plan``, ``check`` and the
maps share (docs/conventions.md, "Reference model"): sample points of the room minus keep-out at the
lowest, middle and highest LED height; a point is seen by a camera when it projects inside the
image (2 px margin) in front of it; the predicted error of a point seen by ≥ 2 cameras is
``sqrt(trace(F⁻¹))``, ``F = Σ JᵢᵀJᵢ / σ²``; an obstacle (a keep-out with a height) hides a
point from a camera when it stands across the segment between them; a layout meets the
requirements when at least ``coverage`` of the points are seen by ``min_cameras`` cameras and
the 95th percentile of their predicted error is within ``max_error_p95``.

shapely is imported inside the functions that use it: importing planning for its types (as the
viewer and the demo do) loads no GEOS library.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..geometry import Camera
from ..triangulation import predicted_rms_error
from .site import SAMPLE_STEP, Site, floor, footprint

#: px: a point is seen when it projects at least this far inside the image
MARGIN_PX = 2.0


def sample_step(site: Site) -> float:
    """The sample grid's step: :data:`~.site.SAMPLE_STEP` (the contract's "at most 10 cm"),
    finer for a scene whose camera footprint is under 1.2 m, so that a footprint spans at least
    12 cells at any scale."""
    return min(SAMPLE_STEP, min(footprint(site)) / 12)


def sample_grid(site: Site, step: float | None = None):
    """The reference model's floor grid: cell centres ``xs``, ``ys`` (``step`` ≤ 10 cm; by
    default :func:`sample_step`) over the floor's bounding box and the mask ``inside``
    (len(ys) × len(xs)) of the cells in the room minus keep-out areas."""
    from shapely import contains_xy

    step = sample_step(site) if step is None else step
    area = floor(site.room, site.keep_out)
    x0, y0, x1, y1 = area.bounds
    xs, ys = np.arange(x0 + step / 2, x1, step), np.arange(y0 + step / 2, y1, step)
    gx, gy = np.meshgrid(xs, ys)
    return xs, ys, contains_xy(area, gx, gy)


def sample_levels(site: Site) -> list[float]:
    """The LED heights the model samples: the lowest, halfway and highest."""
    hs = site.requirements.heights
    return sorted({min(hs), (min(hs) + max(hs)) / 2, max(hs)})


def sample_points(site: Site, step: float | None = None) -> np.ndarray:
    """The reference model's sample points ``N×3``: the room minus keep-out areas on a square
    grid (``step`` ≤ 10 cm, cell centres), at the lowest, middle (halfway between the lowest
    and the highest) and highest LED height, level after level."""
    xs, ys, inside = sample_grid(site, step)
    gx, gy = np.meshgrid(xs, ys)
    xy = np.c_[gx[inside], gy[inside]]
    return np.concatenate([np.c_[xy, np.full(len(xy), h)] for h in sample_levels(site)])


@dataclass
class Evaluation:
    """A layout judged by the reference model."""

    coverage: float  #: share of sample points seen by ≥ min_cameras cameras
    p95: float  #: m, 95th percentile of the predicted error over those points
    mean: float  #: m, mean predicted error over those points
    meets: bool
    points: np.ndarray  #: the sample points N×3
    views: np.ndarray  #: N, cameras that see each point
    error: np.ndarray  #: N, predicted RMS error (m; NaN where < 2 cameras)


def unobstructed(center, points, obstacles) -> np.ndarray:
    """Whether the segment from each of ``points`` (N×3) to a camera at ``center`` clears every
    obstacle (N): its stretch below an obstacle's top, seen from above, must not meet the
    obstacle's polygon."""
    import shapely

    points = np.asarray(points, float)
    C = np.asarray(center, float)
    clear = np.ones(len(points), bool)
    for height, poly in _by_height(obstacles):
        low = clear & (points[:, 2] < height)
        if not low.any():
            continue
        P = points[low]
        rise = C[2] - P[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(rise > height - P[:, 2], (height - P[:, 2]) / rise, 1.0)
        Q = P[:, :2] + t[:, None] * (C[:2] - P[:, :2])
        x0, y0, x1, y1 = poly.bounds
        near = (np.maximum(P[:, 0], Q[:, 0]) >= x0) & (np.minimum(P[:, 0], Q[:, 0]) <= x1) \
            & (np.maximum(P[:, 1], Q[:, 1]) >= y0) & (np.minimum(P[:, 1], Q[:, 1]) <= y1)
        if not near.any():
            continue
        lines = shapely.linestrings(np.stack([P[near, :2], Q[near]], axis=1))
        hit = np.zeros(len(P), bool)
        hit[near] = shapely.intersects(poly, lines)
        idx = np.flatnonzero(low)
        clear[idx[hit]] = False
    return clear


def _by_height(obstacles) -> list:
    """The obstacles as one prepared shape per height, tallest first: thousands of them
    cost a handful of vectorised tests per camera, not one each."""
    import shapely
    from shapely.geometry import Polygon

    key = tuple((o.height, tuple(map(tuple, o.polygon))) for o in obstacles)
    got = _SHAPES.get(key)
    if got is None:
        heights = sorted({o.height for o in obstacles}, reverse=True)
        got = [(h, shapely.union_all([Polygon(o.polygon).buffer(0) for o in obstacles
                                      if o.height == h])) for h in heights]
        for _, shape in got:
            shapely.prepare(shape)
        _SHAPES.clear()
        _SHAPES[key] = got
    return got


#: the last site's obstacles by height (a plan asks for them thousands of times)
_SHAPES: dict = {}


def seen_by(site: Site, cameras: list[Camera], points) -> np.ndarray:
    """C×N: which cameras see which points by the reference model — inside the image by
    :data:`MARGIN_PX`, in front, and not hidden by an obstacle."""
    if not cameras:
        return np.zeros((0, len(points)), bool)
    seen = np.stack([c.project(points, margin=MARGIN_PX)[2] for c in cameras])
    for k, c in enumerate(cameras):
        if site.obstacles and seen[k].any():
            seen[k, seen[k]] = unobstructed(c.center, points[seen[k]], site.obstacles)
    return seen


def evaluate(site: Site, cameras: list[Camera], step: float | None = None) -> Evaluation:
    """Judge a layout with the reference model, independently of any optimiser."""
    pts = sample_points(site, step)
    seen = seen_by(site, cameras, pts)
    views = seen.sum(axis=0)
    err = predicted_rms_error(cameras, pts, seen, site.requirements.pixel_noise) if cameras \
        else np.full(len(pts), np.nan)
    ok = views >= site.requirements.min_cameras
    coverage = float(ok.mean()) if len(pts) else 0.0
    # a point seen only from one place (cameras hung together) has no bounded error: inf
    unbounded = 1e300  # finite, so that the percentile's interpolation stays a number
    bounded = np.where(np.isfinite(err), err, unbounded)[ok]
    p95 = float(np.percentile(bounded, 95)) if ok.any() else math.inf
    p95 = math.inf if p95 >= unbounded / 2 else p95
    mean = float(np.mean(np.where(bounded < unbounded, bounded, np.inf))) if ok.any() \
        else math.inf
    r = site.requirements
    return Evaluation(coverage, p95, mean, coverage >= r.coverage and p95 <= r.max_error_p95,
                      pts, views, err)
