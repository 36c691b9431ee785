"""Calibration from a freely moving LED and a few measured reference points.

As motion-capture suites do: the cameras calibrate each other from what they see of the LED
at the same moments (a *free set*: one moment, the LED somewhere nobody measured), and a
handful of tape-measured *reference points* fix the world's origin, axes and scale. One
bundle adjustment (:func:`~.calibration.refine_jointly`) over every camera's pose and lens,
every free position (no prior) and every reference (within its measurement precision, estimated
by variance components unless stated). With ``free_height`` every free position is at that
height (an LED on a robot): the floor plane then fixes the vertical, the tilts and, with two
references, everything else. A wand's (:mod:`.wand`) adds its length between each set's two
LEDs.

Accuracy without a full survey: each reference left out in turn (its prior removed, its spots
kept) against its measured position, the free spots' reprojection spread per camera, and the
*datum floor*: how far the references' own measurement noise moves the whole frame
(:func:`~.datum.datum_floor`), which no calibration can beat.

:func:`calibrate_free` runs the steps in order: the inputs checked (:mod:`.free_checks`), the
starts (:mod:`.free_start`), the pose-only fit with rejection from each start
(:class:`FreeFit`), the lens models, the joint fit, each reference left out, the prediction
and the references that stand far beyond the others.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..geometry import Camera
from .budget import fix_errors
from .calibration import refine_jointly
from .datum import check_datum, datum_floor, is_mark, unfixed_motions
from .errors import SurveyError
from .free_checks import (
    MIN_SHARED,
    REJECT_SIGMAS,
    check_fit,
    check_height,
    check_inside,
    check_linked,
    check_references_fit,
)
from .free_fit import FreeFit, best_fit, fit_starts
from .free_lens import forced_choices, lens_models, robot_lens
from .free_start import reference_start
from .marks_frame import polygons_in_marks_frame
from .network import label_wand
from .suspects import far_beyond, suspects_of
from .wand import (
    LABEL_TOLERANCE,
    WAND_PRECISION,
    WandError,
    check_both_seen,
    check_wand_error,
    wand_errors,
    wand_points,
)

__all__ = ["MIN_SHARED", "REJECT_SIGMAS", "WAND_PRECISION", "FreeCalibration", "WandError",
           "calibrate_free", "datum_floor", "mark_shares", "progress_steps", "wand_errors"]

#: reference coordinates beyond the datum's that a precision estimate needs …
MIN_REDUNDANT = 6
#: … else this precision (a tape measure, per axis, m) is assumed and said
ASSUMED_TAPE = 0.003
#: … or, where every reference is a frame mark, this one (m per axis): a mark is where the LED
#: stood, so only its height is in doubt — the floor's unevenness under it
MARK_PRECISION = 0.002
#: references left out in turn, at most (an even sample of more)
MAX_LEFT_OUT = 24
#: joint-fit iterations from the calibration to its refit without the references named as
#: suspect (:mod:`.suspects`)
WITHOUT_ITERATIONS = 15
#: a survey whose cameras are predicted to place fixes this many times worse than its references
#: and spots allow is weak (the free LED cannot fix the lens across pair overlaps alone)
WEAK_FACTOR = 2.0
#: a frame mark's coordinate set by definition (the origin's x and y, the x mark's y: the frame
#: is where the LED stood) is held to this share of :data:`MARK_PRECISION`
DEFINED_SHARE = 0.01


@dataclass
class FreeCalibration:
    """The cameras fitted to a free survey, and what the fit found."""

    cameras: list[Camera]
    models: list[str]
    lens: list  #: LensChoice per camera
    free_xyz: np.ndarray  #: M×3 fitted LED positions (NaN: the set was not used)
    references: np.ndarray  #: N×3 adjusted reference positions
    point_sigma: float  #: m per axis, the references' precision
    point_sigma_estimated: bool
    pixel_sigma: float  #: px, the spots' precision
    used_sets: int
    rejected: dict  #: camera id → spots rejected (the one view of a set that disagrees)
    spread_px: dict  #: camera id → RMS reprojection of its free spots, px
    leave_one_out: np.ndarray  #: per reference: m from its record, fitted without it (NaN)
    datum_floor: float  #: m, predicted RMS error of the frame the references fix
    dropped_sets: int = 0  #: free sets of two views that disagree (which is wrong: unknown)
    notes: list = field(default_factory=list)  #: what was assumed or limited, in words
    point_sigma_assumed: bool = False  #: too few references to estimate it: a tape's assumed
    #: m, predicted mean 3D error of fixes over the floor with these cameras (median of the
    #: linearised adjustment's draws, :func:`.budget.fix_errors`), and with exact cameras
    predicted_error: float = float("nan")
    exact_error: float = float("nan")
    wand: float | None = None  #: m, the wand's length
    wand_error: WandError | None = None  #: on held-out wand sets
    #: C×M×2 the free positions' spots as fitted (a wand's LEDs at 2m, 2m + 1, matched)
    free_uv: np.ndarray | None = None
    #: every reference is a frame mark (:func:`mark_shares`): no tape, only the marks' heights
    #: in doubt
    marks_only: bool = False
    #: the room's floor polygon in the fit's frame (moved into the marks' frame when marks set
    #: it; :mod:`.marks_frame`), or None
    room: list | None = None
    #: the frame is the marks' (a reference has an empty cell), not the plan's
    in_marks_frame: bool = False
    #: references whose left-out residual stands far beyond the others'
    #: (:class:`~.suspects.Suspect`, with what the survey gives without them)
    suspects: list = field(default_factory=list)
    reference_ids: list = field(default_factory=list)  #: as given, one per reference

    @property
    def weakly_fixed(self) -> bool:
        """Whether the survey leaves the cameras far looser than its references allow: fixes
        predicted more than :data:`WEAK_FACTOR` times the error of exact cameras placed in the
        references' frame (the spot noise and the datum floor together)."""
        return bool(self.predicted_error > WEAK_FACTOR * np.hypot(self.exact_error,
                                                                  self.datum_floor)) \
            or self.references_disagree

    @property
    def references_disagree(self) -> bool:
        """Whether the references, each left out in turn, land farther from their records
        than their own noise and the predicted error of fixes together allow, by more than
        :data:`WEAK_FACTOR` on average: the survey's own check on a prediction that cannot see
        a lens and a pose trading off where the free LED could not tell them apart. The
        references named as suspect (:attr:`suspects`) are not counted: one reference far off
        its record says that reference is wrong, not the cameras."""
        named = {s.point_id for s in self.suspects}
        ids = self.reference_ids or [str(i) for i in range(len(self.leave_one_out))]
        mine = np.array([i not in named for i in ids], bool)
        loo = self.leave_one_out[np.isfinite(self.leave_one_out) & mine]
        if len(loo) < 3 or not np.isfinite(self.predicted_error):
            return False
        return bool(loo.mean() > WEAK_FACTOR * self.left_out_allowed)

    @property
    def left_out_allowed(self) -> float:
        """m: how far a reference left out may land from its record, by its own noise (3D)
        and the predicted error of fixes together (its noise alone where nothing predicts
        the fixes, as with a wand)."""
        predicted = self.predicted_error if np.isfinite(self.predicted_error) else 0.0
        return float(np.hypot(np.sqrt(3) * self.point_sigma, predicted))


def mark_shares(X) -> tuple[np.ndarray, bool]:
    """Each reference coordinate's precision as a share of the references' (N×3), and whether
    every reference is a frame mark. A mark — a point with an empty cell, or the origin's
    zeros, in a survey that has empty cells — is where the LED stood: its horizontal zeros
    define the frame (:data:`DEFINED_SHARE`); a taped point's zero is a reading like any
    other."""
    X = np.asarray(X, float)
    measured = np.isfinite(X)
    share = np.ones(X.shape)
    if not (~measured).any():
        return share, False
    marks = is_mark(X)
    share[:, :2][marks[:, None] & measured[:, :2] & (X[:, :2] == 0.0)] = DEFINED_SHARE
    return share, bool((X[measured] == 0.0).all())




def progress_steps(references: int, wand: float | None = None, labelled: bool = False) -> int:
    """The steps :func:`calibrate_free` counts to its ``progress`` from a start (a second start
    from the free sets adds three): the fits and each reference left out in turn."""
    return 5 + min(references, MAX_LEFT_OUT) + (3 if wand is not None and not labelled else 0)


def calibrate_free(nominal: list[Camera], X, uv, ids, uv_free, lens: str = "auto",
                   point_sigma: float | str = "auto", free_height: float | None = None,
                   room=None, progress=None, wand: float | None = None,
                   labelled: bool = False) -> FreeCalibration:
    """Calibrate every camera from a free survey: ``X`` N×3 the references' measured
    positions (NaN: a coordinate not measured, as a frame mark's), ``uv`` C×N×2 their spots,
    ``uv_free`` C×M×2 the free sets' spots (NaN: not seen) — with a ``wand`` of that length
    (m), C×M×2×2, each camera's two spots in the LEDs' order if ``labelled``, else matched
    across cameras here. ``lens``: ``"auto"`` (one model for every camera, chosen by the
    free LED's held-out consistency: :func:`~.free_lens.joint_lens_choice`) or a model of
    :class:`~.lens.LensModel`. ``room``: the floor polygon (the plan's frame) the free
    positions and the datum floor are judged over. ``progress(i, n)``: :func:`progress_steps`.
    A joint fit that cannot converge is a :class:`SurveyError` that says how far the fit
    got."""
    try:
        return _calibrate_free(nominal, X, uv, ids, uv_free, lens, point_sigma, free_height,
                               room, progress, wand, labelled)
    except np.linalg.LinAlgError:
        raise SurveyError("the joint fit did not converge: its equations became singular "
                          "(cameras or references that nothing ties to the rest); nothing "
                          "was written") from None


def _assumed_precision(point_sigma, coords: int, datum: int, n_ref: int, marks_only: bool):
    """The references' precision: estimated from the fit (``point_sigma`` "auto"), as stated,
    or — where the references have too few coordinates beyond what fixes the room to show
    their own scatter — a tape's (a floor's, for marks) assumed. Returns (stated m or None,
    estimated, assumed, the note that says so or "")."""
    estimated = isinstance(point_sigma, str)
    stated = None if estimated else float(point_sigma)
    if not (estimated and coords - datum < MIN_REDUNDANT):
        return stated, estimated, False, ""
    note = (f"{n_ref} marks cannot show how precisely the LED stood on them (they have "
            f"{max(coords - datum, 0)} coordinates beyond what fixes the room): "
            f"±{MARK_PRECISION * 1000:g} mm in height (a floor's unevenness) assumed; state "
            "it, or add floor marks" if marks_only else
            f"{n_ref} reference points cannot show how precisely they were measured "
            f"(they have {max(coords - datum, 0)} coordinates beyond what fixes the "
            f"room): ±{ASSUMED_TAPE * 1000:g} mm (a tape) assumed; state their "
            "precision, or measure more points")
    return (MARK_PRECISION if marks_only else ASSUMED_TAPE), False, True, note


class _LeaveOneOut:
    """Each reference of ``left_out`` left out in turn — its prior removed (its spots kept),
    where the rest put it, when the rest still fix the frame — on the final fit's
    observations ``obs``, lens ``models`` and priors ``base``."""

    def __init__(self, fit: FreeFit, u, obs, models, keep, base, s_px, left_out, used_r):
        self.fit, self.u, self.obs, self.models, self.keep = fit, u, obs, models, keep
        self.base, self.s_px, self.left_out, self.used_r = base, s_px, left_out, used_r

    def __call__(self, cams_, adj_, out_, count=True):
        """Per reference: how far from its record the fit (from ``cams_``, ``adj_``) puts it
        without its prior (m; NaN where the rest would not fix the room or it was not left
        out), the references ``out_`` (N bools) left out all along (their priors removed)."""
        fit, N, X0, measured = self.fit, self.fit.N, self.u.X0, self.fit.measured
        loo_ = np.full(N, np.nan)
        start = np.where(out_[:, None], adj_[:N], X0)
        for i in self.left_out:
            if count:
                fit.tick()
            rest = self.used_r & ~out_
            rest[i] = False
            if out_[i] or self.keep[:, i].sum() < (1 if fit.free_height is not None else 2) \
                    or unfixed_motions(adj_[:N][rest], measured[rest],
                                       fit.free_height is not None, fit.wand is not None,
                                       fit.scale):
                continue
            sig = self.base.copy()
            sig[:N][out_] = np.inf
            sig[i] = np.inf
            _, moved = refine_jointly(cams_, np.vstack([start[:i], adj_[i:i + 1],
                                                        start[i + 1:N], adj_[N:]]), self.obs,
                                      point_sigma=sig, pixel_sigma=self.s_px,
                                      models=self.models, iterations=6,
                                      lengths=fit.lengths(self.u, self.keep),
                                      aspect=fit.aspect)
            off = np.where(measured[i], moved[i] - X0[i], 0.0)
            loo_[i] = float(np.linalg.norm(off))
        return loo_


def _suspects(leave_out: _LeaveOneOut, ids, loo, allowed, cams, adj) -> list:
    """The references whose left-out residual stands far beyond the others' (``allowed``: what
    their own noise lets one miss by), each with what the survey gives without them: refitted
    without their priors, the others left out in turn again."""
    fit, u, N = leave_out.fit, leave_out.u, leave_out.fit.N
    named, limit = far_beyond(loo, allowed)
    if not named.any():
        return []
    with_ = without = moved = float("nan")
    used_r = leave_out.used_r
    if not unfixed_motions(adj[:N][used_r & ~named], fit.measured[used_r & ~named],
                           fit.free_height is not None, fit.wand is not None, fit.scale):
        sig = leave_out.base.copy()
        sig[:N][named] = np.inf
        cams_w, adj_w = refine_jointly(
            cams, np.vstack([np.where(named[:, None], adj[:N], u.X0), adj[N:]]), leave_out.obs,
            point_sigma=sig, pixel_sigma=leave_out.s_px, models=leave_out.models,
            iterations=WITHOUT_ITERATIONS, lengths=fit.lengths(u, leave_out.keep),
            aspect=fit.aspect)
        loo_w = leave_out(cams_w, adj_w, named, count=False)
        both = np.isfinite(loo) & np.isfinite(loo_w) & ~named
        if both.any():
            with_, without = float(loo[both].mean()), float(loo_w[both].mean())
        moved = max(float(np.linalg.norm(np.subtract(a.center, b.center)))
                    for a, b in zip(cams, cams_w))
    return suspects_of(ids, loo, named, limit, with_, without, moved)


def _calibrate_free(nominal: list[Camera], X, uv, ids, uv_free, lens: str = "auto",
                    point_sigma: float | str = "auto", free_height: float | None = None,
                    room=None, progress=None, wand: float | None = None,
                    labelled: bool = False) -> FreeCalibration:
    """:func:`calibrate_free`, its steps in order; a singular joint fit raises
    ``LinAlgError``."""
    X, uv, uv_free = np.asarray(X, float), np.asarray(uv, float), np.asarray(uv_free, float)
    N = len(X)
    ids_c = [c.id for c in nominal]
    spots = uv_free if wand is not None else uv_free[:, :, None]
    if wand is not None and (uv_free.ndim != 4 or uv_free.shape[2] != 2):
        raise ValueError("uv_free: a wand's spots are C×M×2×2")
    seen_f = np.isfinite(spots[..., 0]).any(axis=2)
    if wand is not None:
        check_both_seen(spots)
    seen_r = np.isfinite(uv).all(axis=2)
    measured = np.isfinite(X)
    check_linked(ids_c, seen_f)
    scale = float(np.median([c.position[2] for c in nominal])) or 1.0
    X0 = reference_start(nominal, X, uv)
    used_r = seen_r.any(axis=0)
    check_datum(X0[used_r], measured[used_r], free_height is not None, wand is not None,
                scale, marks=is_mark(X)[used_r])
    if free_height is not None:
        check_height(nominal, X0, uv, uv_free, free_height, is_mark(X))
    notes: list = []
    # what the references must fix first: the frame's motions, but the scale a wand fixes
    datum = (4 if free_height is not None else 7) - (wand is not None)
    share, marks_only = mark_shares(X)
    stated, estimated, assumed, note = _assumed_precision(
        point_sigma, int(measured[used_r].sum()), datum, int(used_r.sum()), marks_only)
    if note:
        notes.append(note)
    tries, errs = fit_starts(nominal, X, uv, uv_free, spots, wand, labelled)
    X0 = reference_start(tries[0][0], X, uv)
    lens, kept = robot_lens(lens, free_height, seen_r, X0, ids_c)
    if kept:
        notes.append(f"lens kept as in the deployment (pose only): {kept}")
    step = 0
    total = progress_steps(N, wand, labelled) + 3 * (len(tries) - 1)

    def tick():
        nonlocal step
        step += 1
        if progress:
            progress(step, total)

    fit = FreeFit(nominal, X, uv, free_height, wand, stated, share, scale, notes, tick)
    ((obs, s_x, s_px, cams, adj, keep), u), best, fits = best_fit(fit, tries)
    if best == 1:
        notes.append(f"the cameras' start placed from the free sets (they fit them to "
                     f"{errs[1]:.2g} px, the deployment's cameras to {errs[0]:.2g} px; the "
                     f"fit from them to ±{s_px:.2g} px, from the deployment's to "
                     f"±{fits[0][0][2]:.2g} px)")
    if wand is not None and not labelled:
        # the ends named again with the fitted cameras, every set's views at once, and
        # fitted again
        order = label_wand(cams, spots, wand, LABEL_TOLERANCE * s_px)
        (obs, s_x, s_px, cams, adj, keep), u = fit.fitted_from(
            cams, wand_points(spots, order, False))
    models, choices = lens_models(fit, u, lens, cams, adj, keep, s_x, s_px)
    tick()
    obs, (s_x, s_px, cams, adj) = fit.adjust(u, cams, models, keep)
    tick()
    check_fit(cams, adj[N:], u.uv_all[:, N:], keep[:, N:], s_px, ids_c)
    check_references_fit(seen_r, keep[:, :N], ids_c)
    in_marks_frame = bool((~measured).any())  # frame marks define a frame of their own
    if room is not None and in_marks_frame:  # the room moved into it
        room = polygons_in_marks_frame(nominal, cams, [room])[0]
    check_inside(adj[N:], room, cams)
    # the wand's length on held-out sets: a wand that does not fit is refused before the
    # references are left out in turn (each a joint fit)
    wand_error = None if wand is None else wand_errors(cams, u.pts_free[:, u.held_out], wand,
                                                        ids_c, s_px)
    if wand_error is not None:
        check_wand_error(wand_error, wand, int(u.held_out.sum()) // 2, s_px)
    # each reference left out: of many, an even sample (each costs a joint fit)
    left_out = np.unique(np.linspace(0, N - 1, min(N, MAX_LEFT_OUT)).round().astype(int))
    if len(left_out) < N:
        notes.append(f"{len(left_out)} of the {N} references left out in turn (an even "
                     "sample: each costs a joint fit)")
    leave_out = _LeaveOneOut(fit, u, obs, models, keep, fit.prior(u, s_x), s_px, left_out,
                             used_r)
    loo = leave_out(cams, adj, np.zeros(N, bool))
    free_xyz = np.full((u.pts_free.shape[1], 3), np.nan)
    free_xyz[u.free_idx] = adj[N:]
    spread = {}
    for k, cam in enumerate(cams):
        idx = np.flatnonzero(keep[k] & u.free)
        err = np.linalg.norm(cam.project(adj[idx])[0] - u.uv_all[k, idx], axis=1)
        spread[ids_c[k]] = float(np.sqrt(np.mean(err ** 2))) if len(err) else float("nan")
    where = adj[N:] if room is None else _floor_points(room, adj[N:])
    floor = datum_floor(adj[:N][used_r], s_x * share[used_r], where, free_height is not None,
                        measured=measured[used_r],
                        wand_sigma=None if wand is None else WAND_PRECISION)
    # what the whole survey leaves in the cameras, predicted by the linearised adjustment
    # (a wand's lengths are not in the linearised model: without them its scale is free)
    errs = None if wand is not None else fix_errors(cams, adj, where, fit.prior(u, s_x), s_px,
                                                    models[0])
    exact, predicted = (float("nan"),) * 2 if errs is None else map(
        lambda e: float(np.median(e)), errs)
    while step < total:  # the steps that had nothing to do (a reference no camera pair saw)
        tick()
    if not choices:
        choices = forced_choices(fit, u, models, cams, adj, keep, kept)
    cal = FreeCalibration(cams, models, choices, free_xyz, adj[:N], float(s_x),
                          estimated, float(s_px), int((keep[:, N:].sum(axis=0) >= 1).sum())
                          // fit.per_set, u.rejected, spread, loo, floor, u.dropped, notes,
                          assumed, predicted, exact, wand, wand_error, u.pts_free, marks_only,
                          room, in_marks_frame, reference_ids=[str(i) for i in ids])
    cal.suspects = _suspects(leave_out, ids, loo, cal.left_out_allowed, cams, adj)
    return cal


def _floor_points(room, free_xyz) -> np.ndarray:
    """Where accuracy matters: the room's floor on a grid, at the free positions' heights."""
    room = np.asarray(room, float)
    lo, hi = room.min(axis=0), room.max(axis=0)
    g = np.stack(np.meshgrid(np.linspace(lo[0], hi[0], 12), np.linspace(lo[1], hi[1], 12)),
                 -1).reshape(-1, 2)
    zs = np.nanpercentile(free_xyz[:, 2], [10, 50, 90]) if len(free_xyz) else [0.0]
    return np.vstack([np.c_[g, np.full(len(g), z)] for z in zs])
