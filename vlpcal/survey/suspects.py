"""Survey points that disagree with the rest: a reference (or a tape point) whose left-out
residual — how far from its record the cameras fitted without it put it — stands far beyond
the others'.

One rule for a free survey's references and a tape survey's points: judged against the other
points' own left-out residuals (their median: robust to the suspect itself and to a second
one), never against a length fixed in advance, with a floor from the survey's own precision
so that points far closer than the tape can read are never named.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .calibration import format_length

#: a point is named when its left-out residual exceeds this many times the others' median.
#: Good surveys stay far below it: on 15 simulated free surveys (paper-2024, cheap-wide and
#: qvga, seeds 0–4, 800 free sets, 12 references) no reference came beyond 3.2 × the others'
#: median, and on the paper-2024 and qvga tape surveys (95 points held out) no point beyond
#: 3.0 ×; a reference read 0.30 m off in x stands 40 × beyond, a tape point 60 ×.
SUSPECT_FACTOR = 6.0
#: other points a residual is judged against, at least (fewer have no median worth the name)
MIN_OTHERS = 3


@dataclass
class Suspect:
    """A survey point whose left-out residual stands far beyond the others' (lengths in m)."""

    point_id: str
    residual: float  #: its left-out residual: its record against where the rest put it
    typical: float  #: the other points' median left-out residual
    limit: float  #: the residual beyond which a point is named
    #: the survey's held-out figure over the other points (their mean left-out residual), as
    #: calibrated with it, and refitted without the named points (NaN: the rest cannot be
    #: refitted, e.g. they no longer fix the room)
    others_with: float
    others_without: float
    #: the largest camera move between the calibration with it and the one without (NaN: not
    #: refitted as a whole)
    cameras_moved: float = float("nan")

    def to_dict(self) -> dict:
        def num(v):
            return float(v) if np.isfinite(v) else None

        return {"point_id": self.point_id, "left_out_error_m": num(self.residual),
                "others_median_m": num(self.typical), "named_beyond_m": num(self.limit),
                "others_mean_with_m": num(self.others_with),
                "others_mean_without_m": num(self.others_without),
                "cameras_moved_m": num(self.cameras_moved)}


def far_beyond(residuals, floor: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Which of the points' left-out ``residuals`` (m; NaN: not judged) stand far beyond the
    others': more than :data:`SUSPECT_FACTOR` times the median of the other finite residuals,
    or of ``floor`` (m: what the survey's own precision lets a good point miss by), whichever
    is larger. Returns (named N bools, each point's limit N m, NaN where not judged)."""
    r = np.asarray(residuals, float)
    ok = np.isfinite(r)
    limit = np.full(len(r), np.nan)
    if ok.sum() < MIN_OTHERS + 1:
        return np.zeros(len(r), bool), limit
    floor = floor if np.isfinite(floor) else 0.0
    for i in np.flatnonzero(ok):
        others = r[ok & (np.arange(len(r)) != i)]
        limit[i] = SUSPECT_FACTOR * max(float(np.median(others)), floor)
    with np.errstate(invalid="ignore"):
        return ok & (r > limit), limit


def typical_of_others(residuals, i: int) -> float:
    """The median of the finite residuals other than point ``i``'s (m)."""
    r = np.asarray(residuals, float)
    others = r[np.isfinite(r) & (np.arange(len(r)) != i)]
    return float(np.median(others)) if len(others) else float("nan")


def suspects_of(ids, residuals, named, limit, others_with: float, others_without: float,
                cameras_moved: float = float("nan")) -> list[Suspect]:
    """The :class:`Suspect` records of the ``named`` points (:func:`far_beyond`'s), with the
    other points' held-out figure with them and without them (m, on the same points)."""
    r = np.asarray(residuals, float)
    return [Suspect(str(ids[i]), float(r[i]), typical_of_others(r, i), float(limit[i]),
                    float(others_with), float(others_without), float(cameras_moved))
            for i in np.flatnonzero(named)]


def suspect_words(s: Suspect, held_out: bool = False) -> str:
    """One suspect in a surveyor's words: its residual against the others', and what leaving
    it out gives. A free survey's reference is left out in turn (its record against where the
    rest put it); a tape survey's point is ``held_out`` (located by cameras calibrated on the
    other folds)."""
    f = format_length
    if held_out:
        said = (f"point {s.point_id}: held out, the cameras calibrated without it put it "
                f"{f(s.residual)} from its record, where the other points land {f(s.typical)} "
                f"(their median; a point is named beyond {f(s.limit)}): mis-measured, or "
                "moved since?")
        if np.isfinite(s.others_without):
            said += (f" Without it the others are {f(s.others_without)} off on average, held "
                     f"out, instead of {f(s.others_with)}.")
        return said
    said = (f"reference {s.point_id}: left out, the rest put it {f(s.residual)} from its "
            f"record, where the other references land {f(s.typical)} (their median; one is "
            f"named beyond {f(s.limit)}): mis-measured, or moved since?")
    if np.isfinite(s.others_without):
        said += (f" Without it the others, each left out in turn, land {f(s.others_without)} "
                 f"from their records on average instead of {f(s.others_with)}")
        if np.isfinite(s.cameras_moved):
            said += f", and the cameras move by up to {f(s.cameras_moved)}"
        said += "."
    return said
