"""The plan's frame carried into the frame that frame marks define.

A marks-only survey sets its own origin and axes (``O,0,0,0``, ``X,,0,0``: docs/formats.md,
survey bundle); the deployment's room, keep-outs and nominal cameras are in the plan's frame,
which the marks may put anywhere. Everything judged against the room (free positions inside
it, the datum floor over its floor, the region map) is judged with the room moved along with
the cameras: the nominal room is taken as roughly placed, like the nominal cameras.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..geometry import rotation_vector
from .network import similarity


def marks_similarity(nominal, fitted) -> tuple[float, np.ndarray, np.ndarray]:
    """``(s, R, t)`` putting the nominal cameras' centres, and a point along each optical axis,
    on the fitted ones (C cameras each → the plan's frame to the marks')."""
    reach = float(np.median([c.position[2] for c in nominal])) or 1.0

    def anchors(cams):
        return np.vstack([[c.center for c in cams], [c.center + reach * c.axis for c in cams]])

    return similarity(anchors(nominal), anchors(fitted))


def cameras_in_marks_frame(nominal, fitted) -> list:
    """The nominal cameras moved into the frame the marks define."""
    s, R, t = marks_similarity(nominal, fitted)
    return [replace(c, position=tuple(s * R @ c.center + t),
                    rotation=tuple(rotation_vector(c.R @ R.T))) for c in nominal]


def polygons_in_marks_frame(nominal, fitted, polygons) -> list:
    """Floor polygons (each K×2, the room and keep-outs) moved with the cameras into the
    frame the marks define."""
    s, R, t = marks_similarity(nominal, fitted)

    def move(poly):
        P = np.c_[np.asarray(poly, float), np.zeros(len(poly))]
        return [[float(x), float(y)] for x, y in (s * P @ R.T + t)[:, :2]]

    return [move(p) for p in polygons]
