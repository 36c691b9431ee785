"""The paper's approach (c): for each floor region, the camera pair that was most accurate
there on the survey (section 3.3 (c): "we select the pair known to perform better within the
specific regions ... based on prior knowledge and experimental data")."""

from __future__ import annotations

import numpy as np
from shapely.geometry import Polygon, box

from ..fusion import RegionMap, pair_estimates
from ..geometry import Camera


def region_cell(cameras: list[Camera], room) -> float:
    """The side of a region-map cell: half the median distance from a camera to its nearest
    neighbour in top view (0.3 m for the paper's 0.6 m spacing), so the map resolves the pairs'
    overlaps at any scale; a single camera: a tenth of the room's larger side."""
    xy = np.array([c.position[:2] for c in cameras], float)
    if len(xy) > 1:
        d = np.linalg.norm(xy[:, None] - xy[None], axis=2)
        np.fill_diagonal(d, np.inf)
        near = np.min(d, axis=1)
        near = near[near > 0]
        if len(near):
            return float(np.median(near) / 2)
    return float(np.ptp(np.asarray(room, float), axis=0).max() / 10)


def learn_region_map(cameras: list[Camera], uv, X, room, cell: float | None = None,
                     pair_method: str = "paper", min_points: int = 1) -> RegionMap:
    """Square cells of ``cell`` m (default :func:`region_cell`) over the room's bounding box,
    each naming the camera pair with the lowest mean 3D error on the survey points (``X`` N×3
    measured, ``uv`` C×N×2) that fall in it. Cells with fewer than ``min_points`` usable points
    are left out (the fusion falls back to the nearest pair there).
    """
    X = np.asarray(X, float)
    if cell is None:
        cell = region_cell(cameras, room)
    pairs, Xp = pair_estimates(cameras, uv, pair_method)
    if not pairs:  # one camera: no pair to choose
        return RegionMap([])
    err = np.linalg.norm(Xp - X[None], axis=2)  # P×N, NaN where the pair has no estimate
    room_poly = Polygon(room)
    x0, y0, x1, y1 = room_poly.bounds
    ix = np.floor((X[:, 0] - x0) / cell).astype(int)
    iy = np.floor((X[:, 1] - y0) / cell).astype(int)
    regions = []
    for cx, cy in sorted(set(zip(ix.tolist(), iy.tolist()))):
        inside = (ix == cx) & (iy == cy)
        e = err[:, inside]
        usable = np.isfinite(e).sum(axis=1)
        if usable.max() < min_points:
            continue
        total = np.where(np.isfinite(e), e, 0.0).sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(usable >= min_points, total / usable, np.inf)
        best = int(np.argmin(mean))
        square = box(x0 + cx * cell, y0 + cy * cell, x0 + (cx + 1) * cell, y0 + (cy + 1) * cell)
        poly = square.intersection(room_poly)
        if poly.is_empty or poly.geom_type != "Polygon":
            continue
        regions.append((poly, (cameras[pairs[best][0]].id, cameras[pairs[best][1]].id)))
    return RegionMap(regions)
