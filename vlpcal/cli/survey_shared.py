"""What the ``vlpcal survey`` commands share: how the terminal spells the library's
parameters, and the checks of a survey's positions and a wand's length against the room."""

from __future__ import annotations

import numpy as np
from shapely import contains_xy
from shapely.geometry import Polygon

from .common import UserError, _floor_diagonal, echo

#: a free or wand survey's capture: at most this long, this many sets (10 a second)
CAPTURE_SECONDS = 180.0
CAPTURE_SETS = 1800

#: the library's parameters (:data:`vlpcal.reports.survey_text.PARAMETERS`) as these
#: commands spell them, so that what the terminal says to change is what to type
FLAGS = {"lens": "--lens", "point_sigma": "--point-sigma", "wand": "--wand",
         "test_points": "--test-points", "free_height": "--free-height",
         "min_per_camera": "--min-per-camera", "tape": "--tape", "step": "--step",
         "plan_references": "survey plan --free"}


def say_lines(lines) -> None:
    """Print a terminal report's lines (:class:`~vlpcal.reports.survey_text.Line`), its
    warnings to stderr."""
    for line in lines:
        echo(line.text, err=line.err)


def _check_wand_fits(wand, dep, to_wave: bool = False) -> None:
    """Refuse a wand far longer than the room (a length in millimetres, not metres); one
    ``to_wave`` (a plan) at most the floor's diagonal, as ``simulate`` takes it."""
    if wand is not None and wand > 2 * dep.size:
        raise UserError(f"--wand {wand:g}: longer than the room ({dep.size:.3g} m across): "
                        "expected the wand's length in metres")
    if wand is not None and to_wave:
        diagonal = _floor_diagonal(dep.room)
        if wand > diagonal:
            raise UserError(f"--wand {wand:g}: longer than the room's diagonal "
                            f"({diagonal:.2f} m): it cannot be waved there")


def _check_survey_positions(survey_path, dep, X, ids, frame_marks: bool = False) -> None:
    """Refuse positions that cannot be in this room (millimetres read as metres, a typo): a
    margin of a fifth of the room's size around it, and under its ceiling; in a frame that
    marks define (``frame_marks``, or an empty cell), within the room's size of the origin."""
    margin = 0.2 * dep.size
    if frame_marks or np.isnan(X).any():  # positions in the marks' frame, not the room's
        near = np.abs(np.nan_to_num(X[:, :2])).max(axis=1) <= dep.size + margin
        inside = near & ~(X[:, 2] <= -margin) & ~(X[:, 2] >= dep.ceiling_height)
    else:
        room = Polygon(dep.room).buffer(margin)
        inside = contains_xy(room, X[:, 0], X[:, 1]) & (X[:, 2] > -margin) \
            & (X[:, 2] < dep.ceiling_height)
    if not inside.all():
        i = int(np.flatnonzero(~inside)[0])
        raise UserError(f"{survey_path}: point {ids[i]} at ({X[i, 0]:g}, {X[i, 1]:g}, "
                        f"{X[i, 2]:g}) m is not in the room of {dep.name} (a margin of a fifth "
                        f"of its size) or under its {dep.ceiling_height:g} m ceiling: metres "
                        "expected")
