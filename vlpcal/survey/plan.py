"""Planning a survey: where to put the LED, in the order an installer walks."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import SurveyError
from .lens import MIN_POINTS_POSE

#: points a survey plan gives each camera by default: twice what its pose needs, so that a
#: k-fold check can judge a lens fit (more points let it fit more of the lens)
MIN_POINTS_PLANNED = 12


@dataclass
class SurveyPlan:
    """Points to measure: ids in walking order, planned positions N×3, who sees what."""

    ids: list[str]
    xyz: np.ndarray
    seen: np.ndarray  # C×N: each camera sees the point (nominal cameras, 5 px margin)
    camera_ids: list[str]


def plan_survey(deployment, step: float = 0.3, heights=(0.0, 0.35, 0.7),
                min_per_camera: int = MIN_POINTS_PLANNED, min_per_pair: int = 6,
                margin_px: float = 5.0) -> SurveyPlan:
    """The points to measure: a grid over the room (minus keep-out areas) at each height, kept
    where a camera sees them, made finer where a camera or an overlapping pair of cameras would
    otherwise get fewer than ``min_per_camera`` / ``min_per_pair`` points. Two heights or more:
    a floor-only survey cannot separate a camera's height from its focal length.

    Ids follow the order an installer walks: height by height, rows in a serpentine.
    """
    from shapely import contains_xy
    from shapely.geometry import Polygon

    heights = sorted(set(float(h) for h in heights))
    if len(heights) < 2:
        raise SurveyError("a survey needs points at two or more heights (a floor-only survey "
                          "cannot separate height from scale)")
    room = Polygon(deployment.room)
    for poly in deployment.keep_out:
        room = room.difference(Polygon(poly))
    if room.is_empty or room.area < (step / 2) ** 2:
        raise SurveyError("the keep-out areas leave no floor to survey")
    cams = deployment.cameras

    def grid(s, offset=0.0):
        x0, y0, x1, y1 = room.bounds
        gx, gy = np.meshgrid(np.arange(x0 + s / 2 + offset, x1, s),
                             np.arange(y0 + s / 2 + offset, y1, s))
        xy = np.c_[gx.ravel(), gy.ravel()]
        return xy[contains_xy(room, xy[:, 0], xy[:, 1])]

    def seen_by(pts):
        return np.stack([c.project(pts, margin=margin_px)[2] for c in cams])

    pts = np.concatenate([np.c_[grid(step), np.full(len(grid(step)), h)] for h in heights])
    pts = pts[seen_by(pts).any(axis=0)]
    # where a camera or an overlapping pair has too few points: add a finer grid there
    for level in (2, 4):
        seen = seen_by(pts)
        fine_xy = grid(step / level, step / (2 * level))
        fine = np.concatenate([np.c_[fine_xy, np.full(len(fine_xy), h)] for h in heights])
        fine_seen = seen_by(fine)
        want = np.zeros(len(fine), bool)
        for k in range(len(cams)):
            if seen[k].sum() < min_per_camera:
                want |= fine_seen[k]
            for j in range(k + 1, len(cams)):
                both = fine_seen[k] & fine_seen[j]
                if both.any() and (seen[k] & seen[j]).sum() < min_per_pair:
                    want |= both
        if not want.any():
            break
        pts = np.unique(np.concatenate([pts, fine[want]]).round(6), axis=0)
    seen = seen_by(pts)
    for k, cam in enumerate(cams):
        if seen[k].sum() < MIN_POINTS_POSE:
            raise SurveyError(f"camera {cam.id}: sees only {int(seen[k].sum())} points of the "
                              "room at these heights (is it looking at the floor?)")
    order = _walking_order(pts)
    pts, seen = pts[order], seen[:, order]
    ids = [f"S{i + 1:04d}" for i in range(len(pts))]
    return SurveyPlan(ids, pts, seen, [c.id for c in cams])


def _walking_order(pts: np.ndarray) -> np.ndarray:
    """The order an installer walks the points: height by height, row by row (rows of equal
    y), each row entered from the end nearer to where the last one left off — a serpentine
    even where the finer grid makes rows of unequal extent."""
    order: list = []
    x_at = None
    for z in np.unique(np.round(pts[:, 2], 6)):
        on = np.flatnonzero(np.isclose(pts[:, 2], z))
        for y in np.unique(np.round(pts[on, 1], 4)):
            row = on[np.isclose(np.round(pts[on, 1], 4), y)]
            row = row[np.argsort(pts[row, 0], kind="stable")]
            if x_at is not None and abs(pts[row[-1], 0] - x_at) < abs(pts[row[0], 0] - x_at):
                row = row[::-1]
            order.extend(row.tolist())
            x_at = pts[row[-1], 0]
    return np.array(order, int)
