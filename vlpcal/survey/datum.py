"""The datum of a free survey: what fixes the room's frame (origin, axes, scale) and how well.

A free survey's cameras and LED positions are known only up to a similarity transform (3
translations, 3 rotations, a scale) until something measured in the room pins them: reference
points measured with a tape, frame marks (an L-frame's coordinates, some of them unmeasured:
``X,,0,0`` fixes y and z of a point along +x), a floor plane (an LED at a stated height) and a
wand's length (scale alone). Each measured coordinate is one linear constraint on the seven
small motions; :func:`check_datum` says which motions nothing fixes, :func:`datum_floor` how
far the measurements' own noise moves the frame — a limit no calibration beats.
"""

from __future__ import annotations

import numpy as np

from .errors import SurveyError

#: the seven small motions of the frame, in the design's column order
MOTIONS = ("x", "y", "z", "tilt about x", "tilt about y", "turn about z", "scale")


def similarity_design(points, centre, free_height: bool = False) -> np.ndarray:
    """``n×k×p``: how each coordinate of ``points`` moves under the frame's small motions about
    ``centre`` (translation, rotation ω × d, scale); with a known floor plane (``free_height``)
    only x, y under x, y, the turn about z and scale (``k = 2, p = 4``), else ``k = 3, p =
    7``."""
    d = np.asarray(points, float) - centre
    n = len(d)
    rows = np.zeros((n, 3, 7))
    rows[:, :, :3] = np.eye(3)
    rows[:, 0, 4], rows[:, 0, 5] = d[:, 2], -d[:, 1]
    rows[:, 1, 3], rows[:, 1, 5] = -d[:, 2], d[:, 0]
    rows[:, 2, 3], rows[:, 2, 4] = d[:, 1], -d[:, 0]
    rows[:, :, 6] = d
    if free_height:  # z, and the tilts ω_x, ω_y, are fixed by the plane
        rows = rows[:, :2][:, :, [0, 1, 5, 6]]
    return rows


def _constraints(points, measured, free_height: bool, scale_rows: int, spread: float):
    """The measured coordinates' rows of the design (distances in units of ``spread``), and a
    row fixing the scale alone per ``scale_rows``."""
    P = np.asarray(points, float) / spread
    m = np.ones(P.shape, bool) if measured is None else np.asarray(measured, bool)
    rows = similarity_design(P, P.mean(axis=0), free_height)
    if free_height:
        m = m[:, :2]
    A = rows[m]
    if scale_rows:
        s = np.zeros((1, A.shape[1]))
        s[0, -1] = 1.0
        A = np.vstack([A, s])
    return A


def unfixed_motions(points, measured=None, free_height: bool = False, wand: bool = False,
                    spread: float = 1.0) -> list[str]:
    """Which of the frame's motions (:data:`MOTIONS`) the measured coordinates (``measured``
    N×3, True where measured; default all) of ``points`` and a wand (which fixes the scale)
    leave free; ``spread``: the scene's size (the cameras' distance), so that the test is the
    same at any scale."""
    names = [MOTIONS[i] for i in ((0, 1, 5, 6) if free_height else range(7))]

    def null(scale_row: bool):
        A = _constraints(points, measured, free_height, int(scale_row), spread)
        if not len(A):
            return np.eye(len(names))
        _, s, Vt = np.linalg.svd(A, full_matrices=True)
        s = np.r_[s, np.zeros(Vt.shape[0] - len(s))]
        return Vt[s <= 1e-3 * max(s[0], 1e-300)]

    left = null(wand)
    if not len(left):
        return []
    if not wand and not len(null(True)):  # a free scale moves every point; name it alone
        return ["scale"]
    weight = (left ** 2).sum(axis=0)
    return [names[i] for i in np.flatnonzero(weight > 1e-6)]


def is_mark(X) -> np.ndarray:
    """Which references (N×3, NaN: not measured) are frame marks: a point with an empty cell,
    or the origin's zeros in a survey that has empty cells."""
    X = np.asarray(X, float)
    measured = np.isfinite(X)
    if measured.all():
        return np.zeros(len(X), bool)
    return (~measured).any(axis=1) | (X == 0.0).all(axis=1)


def references_named(marks) -> str:
    """"the 12 reference points", "the 5 marks", "the 3 reference points and 2 marks"."""
    marks = np.asarray(marks, bool)
    k, n = int(marks.sum()), len(marks) - int(marks.sum())
    parts = ([f"{n} reference point{'s' if n != 1 else ''}"] if n else []) + (
        [f"{k} mark{'s' if k != 1 else ''}"] if k else [])
    return "the " + " and ".join(parts)


def check_datum(points, measured=None, free_height: bool = False, wand: bool = False,
                spread: float = 1.0, marks=None) -> None:
    """Refuse references and marks that cannot fix the room's frame, naming what they leave
    free and what would fix it. ``marks``: which points are frame marks (N bools; default:
    those with a coordinate not measured)."""
    free = unfixed_motions(points, measured, free_height, wand, spread)
    if not free:
        return
    n = len(points)
    if marks is None:
        marks = np.zeros(n, bool) if measured is None else ~np.asarray(measured).all(axis=1)
    named = references_named(marks)
    if measured is None or np.all(measured):  # tape-measured points only: say it plainly
        need = 2 if free_height else 3
        if n < need:
            raise SurveyError(f"{n} reference point{'s' if n != 1 else ''} seen by a camera; "
                              f"fixing the room's frame needs at least {need}"
                              + (" (or 2 with the LED at a stated height)"
                                 if not free_height else ""))
        s = np.linalg.svd(np.asarray(points, float) - np.mean(points, axis=0),
                          compute_uv=False)
        if not s[0] > 1e-3 * spread:
            raise SurveyError("the reference points are all at one place: they cannot fix the "
                              "room's scale and rotation (spread them over the room)")
        if not free_height:
            raise SurveyError("the reference points lie on one line: they cannot fix the "
                              "room's rotation about it (add a point off the line)")
    what = ", ".join(free)
    if free == ["scale"]:
        raise SurveyError(f"{named} fix the room's origin and axes but not its scale: give "
                          "the wand's length, or measure one distance between them (the X "
                          "mark's x)")
    if n == 0:
        raise SurveyError("no reference point or mark seen by a camera: nothing fixes the "
                          "room's frame (measure at least 3 points, or mark O, X and the floor)")
    raise SurveyError(f"{named} seen by the cameras leave the room's frame free in {what}: "
                      "spread them over the room (3 points not on one line, or marks O, X "
                      "and three on the floor)")


def datum_floor(references, sigma: float, where, free_height: bool = False, measured=None,
                wand_sigma: float | None = None) -> float:
    """RMS displacement (m) at the points ``where`` of the frame that ``references`` define,
    their ``measured`` coordinates (default all) known to ±``sigma`` per axis (one for all, or
    N×3), and a wand's length to a relative ±``wand_sigma`` (one error for the whole survey: the
    bar's): the similarity transform fitted to their noise, linearised."""
    R = np.asarray(references, float)
    c = R.mean(axis=0)
    m = np.ones(R.shape, bool) if measured is None else np.asarray(measured, bool)
    sig = np.broadcast_to(np.asarray(sigma, float), R.shape)
    if free_height:
        m, sig = m[:, :2], sig[:, :2]
    A = similarity_design(R, c, free_height)[m] / sig[m][:, None]
    if wand_sigma is not None:
        s = np.zeros((1, A.shape[1]))
        s[0, -1] = 1.0 / wand_sigma
        A = np.vstack([A, s])
    cov = np.linalg.pinv(A.T @ A)
    B = similarity_design(where, c, free_height)
    k = B.shape[1]
    B = B.reshape(-1, B.shape[-1])
    per = np.einsum("ij,jk,ik->i", B, cov, B).reshape(-1, k).sum(axis=1)
    return float(np.sqrt(per.mean()))
