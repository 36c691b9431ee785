"""How much of each camera's image a free survey's LED has crossed, and which camera pairs have
seen it together: what a surveyor waving the LED needs to hear ("C3: bottom-left quarter
empty"), as motion-capture wanding tools show it. A lens is only fitted where the LED went:
an empty quarter leaves that corner's distortion a guess.

Judged relative to the data: a quarter is *empty* with no sighting and *thin* with under a
quarter of the camera's mean per quarter; a pair is linked once it shares :data:`LINKED`
moments (what the free calibration needs to tie two cameras together).
"""

from __future__ import annotations

import numpy as np
from shapely import contains_xy
from shapely.geometry import Polygon

from .free_checks import MIN_SHARED

#: image quarters by (column, row): 0 = left/top, 1 = right/bottom
QUARTERS = {(0, 0): "top-left", (1, 0): "top-right", (0, 1): "bottom-left",
            (1, 1): "bottom-right"}
#: a quarter with fewer sightings than this share of the camera's mean per quarter is thin
THIN_SHARE = 0.25
#: shared moments that link a pair (as the free calibration asks)
LINKED = MIN_SHARED


def quarter_counts(camera, uv) -> np.ndarray:
    """Sightings per image quarter, ``2×2`` indexed [row, column], of spots ``uv`` (N×2, NaN:
    not seen)."""
    uv = np.asarray(uv, float).reshape(-1, 2)
    uv = uv[np.isfinite(uv).all(axis=1)]
    col = (uv[:, 0] >= camera.width / 2).astype(int)
    row = (uv[:, 1] >= camera.height / 2).astype(int)
    counts = np.zeros((2, 2), int)
    np.add.at(counts, (row, col), 1)
    return counts


#: a quarter of which less than this share sees the room's floor looks at walls: the LED
#: cannot go there, and its emptiness is not the surveyor's to fix
IN_ROOM_SHARE = 0.25


def quarters_in_room(camera, room, height: float = 0.0) -> np.ndarray:
    """``2×2`` [row, column]: the share of each image quarter that sees the room's floor
    polygon ``room`` at ``height`` (an 8 × 8 grid of pixels per quarter)."""

    poly = Polygon(room)
    share = np.zeros((2, 2))
    g = (np.arange(8) + 0.5) / 16  # within a half of the image
    for (c, r) in QUARTERS:
        u, v = np.meshgrid((c / 2 + g) * camera.width, (r / 2 + g) * camera.height)
        xy = camera.ground(np.c_[u.ravel(), v.ravel()], height)
        ok = np.isfinite(xy).all(axis=1)
        share[r, c] = float((ok & contains_xy(poly, np.nan_to_num(xy[:, 0]),
                                              np.nan_to_num(xy[:, 1]))).mean())
    return share


def camera_words(camera, uv, room=None) -> str:
    """One camera's coverage in a few words: ``C3: 412 sightings, bottom-left quarter empty``;
    with the floor polygon ``room``, quarters that look mostly outside it are not asked for."""
    counts = quarter_counts(camera, uv)
    total = int(counts.sum())
    if not total:
        return f"{camera.id}: never saw the LED"
    inside = np.ones((2, 2)) if room is None else quarters_in_room(camera, room)
    mean = total / max(int((inside >= IN_ROOM_SHARE).sum()), 1)
    gaps = []
    for (c, r), name in QUARTERS.items():
        if inside[r, c] < IN_ROOM_SHARE:
            continue
        if counts[r, c] == 0:
            gaps.append(f"{name} quarter empty")
        elif counts[r, c] < THIN_SHARE * mean:
            gaps.append(f"{name} quarter thin ({counts[r, c]})")
    walls = [name for (c, r), name in QUARTERS.items() if inside[r, c] < IN_ROOM_SHARE]
    said = ", ".join(gaps) if gaps else "every quarter covered" if not walls else \
        "every quarter over the room covered"
    return (f"{camera.id}: {total} sightings, {said}"
            + (f" ({', '.join(walls)} beyond the room)" if walls else ""))


def pair_counts(cameras, uv) -> dict:
    """Moments each pair of cameras saw the LED together: ``(id, id) → count`` (C×N×2 ``uv``)."""
    seen = np.isfinite(np.asarray(uv, float)).all(axis=2)
    return {(cameras[k].id, cameras[j].id): int((seen[k] & seen[j]).sum())
            for k in range(len(cameras)) for j in range(k + 1, len(cameras))}


def pair_words(cameras, uv, overlapping=None) -> str:
    """The pairs in words: those not linked yet first. ``overlapping``: the pairs whose views
    can share the LED (others never will, and are not mentioned)."""
    counts = pair_counts(cameras, uv)
    if overlapping is not None:
        counts = {p: n for p, n in counts.items() if p in overlapping}
    short = [f"{a}+{b} {n}" for (a, b), n in counts.items() if n < LINKED]
    linked = sum(n >= LINKED for n in counts.values())
    out = f"pairs: {linked} of {len(counts)} linked"
    return out + (f"; not yet: {', '.join(short)}" if short else "")
