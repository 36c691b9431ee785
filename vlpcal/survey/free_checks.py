"""Refusals of a free survey that cannot calibrate these cameras — said before or after the
fit, naming the cameras or references at fault: cameras the free LED never linked, a stated
height the free sets contradict, a fit that puts the LED outside the room or leaves spots far
from it."""

from __future__ import annotations

import numpy as np
from shapely import contains_xy
from shapely.geometry import Polygon

from ..triangulation import triangulate
from .datum import references_named
from .errors import SurveyError

#: free sets two cameras must share to count as linked (a relative pose needs five)
MIN_SHARED = 8
#: a spot farther from its fitted position than this many spot-noise sigmas is rejected
REJECT_SIGMAS = 5.0


def check_linked(camera_ids, seen) -> None:
    """Refuse cameras that never saw the LED with another, and camera groups no shared
    sightings link (named)."""
    C = len(camera_ids)
    shared = seen.astype(int) @ seen.T.astype(int)
    for k in range(C):
        if shared[k, np.arange(C) != k].max(initial=0) == 0:
            raise SurveyError(f"camera {camera_ids[k]}: never saw the free LED together with "
                              "another camera (move the LED where it and a neighbour both "
                              "see it)")
    linked = shared >= MIN_SHARED
    group, todo = {0}, [0]
    while todo:
        k = todo.pop()
        for j in np.flatnonzero(linked[k]):
            if j not in group:
                group.add(int(j))
                todo.append(int(j))
    if len(group) < C:
        a = ", ".join(camera_ids[k] for k in sorted(group))
        b = ", ".join(camera_ids[k] for k in range(C) if k not in group)
        raise SurveyError(f"cameras {a} and {b} are not linked by shared sightings (fewer than "
                          f"{MIN_SHARED} free sets seen by one of each): move the LED through "
                          "where they overlap")


def check_height(cameras, X, uv, uv_free, free_height, marks) -> None:
    """Refuse a stated free height the free sets contradict: where two cameras or more saw
    the LED, the nominal cameras place it; their heights must sit about ``free_height`` as
    closely as the references' triangulated heights sit about their measured ones (five times
    that, and the references as the yardstick: the nominal cameras' own error). ``marks``:
    which references are frame marks (N bools), for the words."""
    two = np.isfinite(uv_free).all(axis=2).sum(axis=0) >= 2
    ref_two = np.isfinite(uv).all(axis=2).sum(axis=0) >= 2
    if two.sum() < 10 or not ref_two.any():
        return
    z = triangulate(cameras, uv_free[:, two]).X[:, 2]
    zr = triangulate(cameras, uv[:, ref_two]).X[:, 2]
    yard = float(np.nanmedian(np.abs(zr - np.asarray(X, float)[ref_two, 2])))
    off = np.abs(z - free_height)
    if np.nanmedian(off) > 5 * yard + 1e-12:
        lo, hi = np.nanpercentile(z, [5, 95])
        raise SurveyError(f"a free height of {free_height:g} m: the {int(two.sum())} free sets "
                          f"that two cameras saw put the LED at {lo:.2f}–{hi:.2f} m (half of "
                          f"them more than {np.nanmedian(off):.2f} m from {free_height:g}), "
                          f"while {references_named(marks[ref_two])} come out within "
                          f"{yard * 1000:.0f} mm of their measured heights: the LED was not at "
                          "that height (if it moved up and down, state no height)")


def check_inside(free_xyz, room, cameras) -> None:
    """Refuse a fit that puts most free LED positions outside the room — the spots did not
    fit these cameras (a camera's ids swapped, frames of another site)."""
    P = free_xyz[np.isfinite(free_xyz).all(axis=1)]
    if room is None or len(P) < 10:
        return
    poly = Polygon(room)
    top = max(c.position[2] for c in cameras)
    grow = 0.1 * np.sqrt(poly.area)
    inside = contains_xy(poly.buffer(grow), P[:, 0], P[:, 1]) & (P[:, 2] > -grow) \
        & (P[:, 2] < top)
    if inside.mean() < 0.5:
        raise SurveyError(f"the fit puts {1 - inside.mean():.0%} of the free LED positions "
                          "outside the room: the free spots do not fit these cameras (are the "
                          "camera ids in free/ the deployment's? is the survey from this "
                          "site?); nothing was written")


def check_references_fit(seen, kept, ids) -> None:
    """Refuse a fit that threw out most of a camera's sightings of the references: where the
    free LED places that camera, the references it saw are not — its free spots are another
    camera's, or the survey is another site's."""
    lost = seen & ~kept
    for k in np.flatnonzero((lost.sum(axis=1) >= 2) & (lost.sum(axis=1) > seen.sum(axis=1) / 2)):
        raise SurveyError(f"the free spots do not fit these cameras: where they place camera "
                          f"{ids[k]}, {int(lost[k].sum())} of the {int(seen[k].sum())} "
                          "reference points it saw are not (are the camera ids in free/ the "
                          "deployment's? is the survey from this site?); nothing was written")


def check_fit(cams, X, uv, keep, s_px, ids) -> None:
    """Refuse a joint fit that left the free spots far from the LED positions it placed —
    a start outside its reach, or spots of other cameras — naming the cameras and how far."""
    per = {}
    for k, cam in enumerate(cams):
        idx = np.flatnonzero(keep[k])
        if len(idx):
            e = np.linalg.norm(cam.project(X[idx])[0] - uv[k, idx], axis=1)
            per[ids[k]] = float(np.nanmedian(np.nan_to_num(e, nan=np.inf)))
    typical = float(np.median(list(per.values()))) if per else 0.0
    bad = {c: e for c, e in per.items() if e > REJECT_SIGMAS * max(s_px, 0.2 * typical)
           and e > 2 * typical}
    if bad:
        names = ", ".join(f"{c} {e:.1f} px" for c, e in sorted(bad.items(), key=lambda t: -t[1]))
        raise SurveyError(f"the joint fit left camera(s) {names} from the free LED positions "
                          f"(the others {typical:.2f} px): their free spots do not fit the "
                          "rest — another camera's id, a moved camera, or a start too far off; "
                          "nothing was written")
