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

from .free import MIN_SHARED

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


def camera_words(camera, uv) -> str:
    """One camera's coverage in a few words: ``C3: 412 sightings, bottom-left quarter empty``."""
    counts = quarter_counts(camera, uv)
    total = int(counts.sum())
    if not total:
        return f"{camera.id}: never saw the LED"
    mean = total / 4
    gaps = []
    for (c, r), name in QUARTERS.items():
        if counts[r, c] == 0:
            gaps.append(f"{name} quarter empty")
        elif counts[r, c] < THIN_SHARE * mean:
            gaps.append(f"{name} quarter thin ({counts[r, c]})")
    return f"{camera.id}: {total} sightings, " + (", ".join(gaps) if gaps else "every quarter "
                                                  "covered")


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
