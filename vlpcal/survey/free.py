"""Calibration from a freely moving LED and a few measured reference points (issue 15).

As motion-capture suites do: the cameras calibrate each other from what they see of the LED
at the same moments (a *free set*: one moment, the LED somewhere nobody measured), and a
handful of tape-measured *reference points* fix the world's origin, axes and scale. One
bundle adjustment (:func:`~.calibration.refine_jointly`) over every camera's pose and lens,
every free position (no prior) and every reference (within its measurement precision, estimated
by variance components unless stated). With ``free_height`` every free position is at that
height (an LED on a robot): the floor plane then fixes the vertical, the tilts and, with two
references, everything else.

Accuracy without a full survey: each reference left out in turn (its prior removed, its spots
kept) against its measured position, the free spots' reprojection spread per camera, and the
*datum floor*: how far the references' own measurement noise moves the whole frame
(:func:`datum_floor`), which no calibration can beat.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..geometry import Camera
from .calibration import estimate_precision, format_length, refine_jointly
from .datum import check_datum, datum_floor, is_mark, references_named, unfixed_motions
from .errors import SurveyError
from .lens import LENS_MODELS
from .suspects import far_beyond, suspects_of

#: free sets two cameras must share to count as linked (a relative pose needs five)
MIN_SHARED = 8
#: a spot farther from its fitted position than this many spot-noise sigmas is rejected
REJECT_SIGMAS = 5.0
#: the free sets one calibration uses at most (an even sample beyond: 1800 × 6 cameras take
#: ~25 s on one core, 33 000 sets exhausted the sparse solver's memory)
MAX_FREE_SETS = 5000
#: reference coordinates beyond the datum's that a precision estimate needs …
MIN_REDUNDANT = 6
#: references left out in turn, at most (an even sample of more)
MAX_LEFT_OUT = 24
#: joint-fit iterations from the calibration to its refit without the references named as
#: suspect (:mod:`.suspects`)
WITHOUT_ITERATIONS = 15
#: a survey whose cameras are predicted to place fixes this many times worse than its references
#: and spots allow is weak (the free LED cannot fix the lens across pair overlaps alone)
WEAK_FACTOR = 2.0
#: … else this precision (a tape measure, per axis, m) is assumed and said
ASSUMED_TAPE = 0.003
#: … or, where every reference is a frame mark, this one (m per axis): a mark is where the LED
#: stood, so only its height is in doubt — the floor's unevenness under it
MARK_PRECISION = 0.002
#: a frame mark's coordinate set by definition (the origin's x and y, the x mark's y: the frame
#: is where the LED stood) is held to this share of :data:`MARK_PRECISION`
DEFINED_SHARE = 0.01
#: a wand's length, relative: a bar cut and measured to a millimetre per metre
WAND_PRECISION = 1e-3
#: a stated wand length and the one the deployment's cameras show must agree within this
#: factor (a unit slip is a thousand; a hand-hung install's scale is off by a few per cent)
WAND_SCALE_RATIO = 3.0
#: a wand whose held-out sets miss its length by more than this share of it, on average, does
#: not fit (a good survey misses by a few thousandths)
WAND_MISFIT = 0.1
#: free sets whose two LEDs two cameras see, at least, for a wand survey (its length is held
#: on them, and a tenth are held out to measure it)
MIN_WAND_SETS = 20
#: a wand's spots are told apart within this many times the fitted spots' precision
LABEL_TOLERANCE = 5.0
#: pixels are square: a camera's fx / fy stays the deployment's within this relative spread
#: (a lens's anamorphism or a sensor's scaling, about 1 %, as a scatter; without it a camera
#: that sees the LED over part of its image stretches one focal length against its pose)
ASPECT_SPREAD = 0.02
#: every this many wand sets, one is held out of the fit and judged by its length
HELD_OUT_EVERY = 10
#: a start from the data is tried when it fits the free sets this many times better than the
#: nominal cameras (median reprojection error), and kept when the fit from it is this many
#: times better again (:func:`_misfit`, with a k1 lens)
BETTER_START = 0.5


@dataclass
class WandError:
    """How far the fitted cameras put a wand's two LEDs from its length, on sets the fit never
    saw (m): what motion-capture suites report after a wand wave. Sets whose spots do not
    meet in a point (a reflection taken for an end) are counted apart, as the fit's own
    rejection would treat them."""

    sets: int
    mean: float  #: of |length − wand|
    p95: float
    rms: float
    per_camera: dict  #: camera id → mean |length − wand| over the held-out sets it saw
    discarded: int = 0  #: held-out sets whose spots disagree beyond the fit's rejection


def wand_errors(cameras, uv, wand: float, ids, pixel_sigma: float = np.inf) -> WandError:
    """The length errors of a wand's sets ``uv`` C×2M×2 (LEDs at 2m, 2m + 1), each LED
    triangulated from the cameras that saw it (sets with an LED seen by fewer than two: not
    judged; with a spot more than :data:`REJECT_SIGMAS` × ``pixel_sigma`` px off: discarded)."""
    from ..triangulation import reprojection_errors, triangulate

    seen = np.isfinite(uv).all(axis=2)
    two = seen.sum(axis=0) >= 2
    ok = two[0::2] & two[1::2]
    e = np.full(len(ok), np.nan)
    bad = np.zeros(len(ok), bool)
    if ok.any():
        cols = np.flatnonzero(np.repeat(ok, 2))
        P = triangulate(cameras, uv[:, cols]).X
        r = reprojection_errors(cameras, uv[:, cols], P)
        worst = np.nanmax(np.where(np.isfinite(r), r, 0.0), axis=0)
        bad[ok] = (worst[0::2] > REJECT_SIGMAS * pixel_sigma) | \
            (worst[1::2] > REJECT_SIGMAS * pixel_sigma)
        e[ok] = np.abs(np.linalg.norm(P[0::2] - P[1::2], axis=1) - wand)
    e[bad] = np.nan
    good = np.isfinite(e)
    per = {}
    for k, cid in enumerate(ids):
        mine = good & (seen[k, 0::2] | seen[k, 1::2])
        per[cid] = float(e[mine].mean()) if mine.any() else float("nan")
    if not good.any():
        return WandError(0, float("nan"), float("nan"), float("nan"), per, int(bad.sum()))
    return WandError(int(good.sum()), float(e[good].mean()),
                     float(np.percentile(e[good], 95)), float(np.sqrt(np.mean(e[good] ** 2))),
                     per, int(bad.sum()))


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


def _linkage(camera_ids, seen) -> None:
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


def _check_height(cameras, X, uv, uv_free, free_height, marks) -> None:
    """Refuse a stated free height the free sets contradict: where two cameras or more saw
    the LED, the nominal cameras place it; their heights must sit about ``free_height`` as
    closely as the references' triangulated heights sit about their measured ones (five times
    that, and the references as the yardstick: the nominal cameras' own error). ``marks``:
    which references are frame marks (N bools), for the words."""
    from ..triangulation import triangulate

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


def _check_inside(free_xyz, room, cameras) -> None:
    """Refuse a fit that puts most free LED positions outside the room — the spots did not
    fit these cameras (a camera's ids swapped, frames of another site)."""
    from shapely import contains_xy
    from shapely.geometry import Polygon

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


def _start(cameras, uv_free, free_height):
    """Free positions from the start cameras: triangulated where two or more saw the LED,
    the ray met with the plane z = ``free_height`` where one did (when stated)."""
    from ..triangulation import triangulate

    seen = np.isfinite(uv_free).all(axis=2)
    X = np.full((uv_free.shape[1], 3), np.nan)
    two = seen.sum(axis=0) >= 2
    if two.any():
        X[two] = triangulate(cameras, uv_free[:, two]).X
    if free_height is not None:
        for k, cam in enumerate(cameras):
            one = seen[k] & ~np.isfinite(X).all(axis=1)
            if one.any():
                d = cam.rays(uv_free[k, one])
                t = (free_height - cam.center[2]) / d[:, 2]
                X[one] = cam.center + t[:, None] * d
        X[np.isfinite(X).all(axis=1), 2] = free_height
    return X


def _reference_start(cameras, X, uv) -> np.ndarray:
    """The references' start: as measured, each unmeasured coordinate (a frame mark's empty
    cell) from the cameras — triangulated where two saw it, else (or where the rays of a
    rough start do not meet) the mean of its rays met with the plane of its measured height —
    else the measured points' mean."""
    from ..triangulation import triangulate

    X = np.array(X, float)
    if not np.isnan(X).any():
        return X
    seen = np.isfinite(uv).all(axis=2)
    guess = np.full(X.shape, np.nan)
    two = seen.sum(axis=0) >= 2
    if two.any():
        guess[two] = triangulate(cameras, uv[:, two]).X
    for i in np.flatnonzero(~np.isfinite(guess).all(axis=1) & seen.any(axis=0)
                            & np.isfinite(X[:, 2])):
        hits = []
        for k in np.flatnonzero(seen[:, i]):
            d = cameras[k].rays(uv[k, i:i + 1])[0]
            t = (X[i, 2] - cameras[k].center[2]) / d[2] if abs(d[2]) > 1e-9 else -1.0
            if t > 0:
                hits.append(cameras[k].center + t * d)
        if hits:
            guess[i] = np.mean(hits, axis=0)
    mean = np.nanmean(np.where(np.isfinite(X), X, np.nan), axis=0)
    guess = np.where(np.isfinite(guess), guess, np.nan_to_num(mean))
    return np.where(np.isfinite(X), X, guess)


def _reprojection(cameras, uv_free) -> float:
    """Median RMS reprojection error (px) of the free sets two cameras or more saw,
    triangulated with ``cameras``: how well a start fits the data, whatever its frame."""
    from ..triangulation import reprojection_errors, triangulate

    two = np.isfinite(uv_free).all(axis=2).sum(axis=0) >= 2
    if not two.any():
        return float("inf")
    sub = uv_free[:, two]
    if sub.shape[1] > 2000:
        sub = sub[:, np.linspace(0, sub.shape[1] - 1, 2000).astype(int)]
    r = reprojection_errors(cameras, sub, triangulate(cameras, sub).X)
    use = np.isfinite(sub[..., 0]) & np.isfinite(r)
    n = use.sum(axis=0)
    per = np.sqrt((np.where(use, r, 0.0) ** 2).sum(axis=0) / np.maximum(n, 1))[n >= 2]
    return float(np.median(per)) if len(per) else float("inf")


def _wand_points(spots, order, labelled: bool) -> np.ndarray:
    """A wand's spots C×M×2×2 as C×2M×2 points (set m's LEDs at 2m, 2m + 1), each camera's
    slots put in the LEDs' order (``order`` C×M×2 from :func:`.network.network_start`;
    unknown: not used) unless the spots are ``labelled``."""
    if labelled:
        lab = spots
    else:
        idx = np.maximum(order, 0)[..., None].repeat(2, axis=-1)
        lab = np.take_along_axis(spots, idx, axis=2)
        lab[order < 0] = np.nan
    return lab.reshape(lab.shape[0], -1, 2)


def _check_wand_length(nominal, points, wand: float) -> None:
    """Refuse a wand length the deployment's cameras contradict many times over (a length in
    millimetres, or another bar's): its ends triangulated with the planned cameras, whose
    scale a hand-hung install keeps to a few per cent, lie a median distance apart that the
    stated length must be within :data:`WAND_SCALE_RATIO` of (``points``: C×2M×2, a set's
    LEDs at 2m, 2m + 1)."""
    X = _start(nominal, points, None)
    d = np.linalg.norm(X[0::2] - X[1::2], axis=1)
    d = d[np.isfinite(d)]
    if len(d) < MIN_SHARED:
        return
    seen = float(np.median(d))
    if not 1 / WAND_SCALE_RATIO < wand / seen < WAND_SCALE_RATIO:
        raise SurveyError(f"the wand's two LEDs appear about {format_length(seen)} apart under "
                          f"the deployment's cameras (the median of {len(d)} sets), not "
                          f"{format_length(wand)}: is its length in metres, and the "
                          "deployment this site's?")


def _observations(uv_all, keep):
    return [(np.flatnonzero(keep[k]), uv_all[k, keep[k]]) for k in range(len(uv_all))]


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
    """:func:`_calibrate_free`; a joint fit that cannot converge is a :class:`SurveyError`
    that says how far the fit got."""
    try:
        return _calibrate_free(nominal, X, uv, ids, uv_free, lens, point_sigma, free_height,
                               room, progress, wand, labelled)
    except np.linalg.LinAlgError:
        raise SurveyError("the joint fit did not converge: its equations became singular "
                          "(cameras or references that nothing ties to the rest); nothing "
                          "was written") from None


def _calibrate_free(nominal: list[Camera], X, uv, ids, uv_free, lens: str = "auto",
                    point_sigma: float | str = "auto", free_height: float | None = None,
                    room=None, progress=None, wand: float | None = None,
                    labelled: bool = False) -> FreeCalibration:
    """Calibrate every camera from a free survey: ``X`` N×3 the references' measured
    positions (NaN: a coordinate not measured, as a frame mark's), ``uv`` C×N×2 their spots,
    ``uv_free`` C×M×2 the free sets' spots (NaN: not seen) — with a ``wand`` of that length
    (m), C×M×2×2, each camera's two spots in the LEDs' order if ``labelled``, else matched
    across cameras here. ``lens``: ``"auto"`` (one model for every camera, chosen by the
    free LED's held-out consistency: :func:`_joint_lens_choice`) or a model of
    :data:`~.lens.LENS_MODELS`. ``room``: the floor polygon (the plan's frame) the free
    positions and the datum floor are judged over.
    ``progress(i, n)``."""
    from .network import EPIPOLAR_SHARE, align_to_references, label_wand, network_start

    X, uv, uv_free = np.asarray(X, float), np.asarray(uv, float), np.asarray(uv_free, float)
    C, N = len(nominal), len(X)
    ids_c = [c.id for c in nominal]
    spots = uv_free if wand is not None else uv_free[:, :, None]
    if wand is not None and (uv_free.ndim != 4 or uv_free.shape[2] != 2):
        raise ValueError("uv_free: a wand's spots are C×M×2×2")
    seen_f = np.isfinite(spots[..., 0]).any(axis=2)
    if wand is not None:
        both = int((np.isfinite(spots[..., 0]).all(axis=2).sum(axis=0) >= 2).sum())
        if both < MIN_WAND_SETS:
            raise SurveyError(
                f"{both} of the {spots.shape[1]} free sets show the wand's two LEDs to two "
                f"cameras (expected {MIN_WAND_SETS} at least): this looks like a survey of one "
                "LED — calibrate it without the wand's length, or check that both LEDs are lit "
                "and in view; nothing was written")
    seen_r = np.isfinite(uv).all(axis=2)
    measured = np.isfinite(X)
    _linkage(ids_c, seen_f)
    scale = float(np.median([c.position[2] for c in nominal])) or 1.0
    X0 = _reference_start(nominal, X, uv)
    used_r = seen_r.any(axis=0)
    check_datum(X0[used_r], measured[used_r], free_height is not None, wand is not None,
                scale, marks=is_mark(X)[used_r])
    if free_height is not None:
        _check_height(nominal, X0, uv, uv_free, free_height, is_mark(X))
    estimated = isinstance(point_sigma, str)
    stated = None if estimated else float(point_sigma)
    notes: list = []
    assumed = False
    n_ref = int(used_r.sum())
    coords = int(measured[used_r].sum())
    # what the references must fix first: the frame's motions, but the scale a wand fixes
    datum = (4 if free_height is not None else 7) - (wand is not None)
    aspect = (np.array([c.fx / c.fy for c in nominal]), ASPECT_SPREAD)
    share, marks_only = mark_shares(X)
    if estimated and coords - datum < MIN_REDUNDANT:
        # too few references to show their own scatter: a precision is assumed
        stated, estimated, assumed = (MARK_PRECISION if marks_only else ASSUMED_TAPE), False, True
        notes.append(
            f"{n_ref} marks cannot show how precisely the LED stood on them (they have "
            f"{max(coords - datum, 0)} coordinates beyond what fixes the room): "
            f"±{MARK_PRECISION * 1000:g} mm in height (a floor's unevenness) assumed; state "
            "it, or add floor marks" if marks_only else
            f"{n_ref} reference points cannot show how precisely they were measured "
            f"(they have {max(coords - datum, 0)} coordinates beyond what fixes the "
            f"room): ±{ASSUMED_TAPE * 1000:g} mm (a tape) assumed; state their "
            "precision, or measure more points")
    # the start: the nominal cameras, or the cameras placed from the data where those fit
    # the free sets far better (a hand-hung install), moved onto the references
    net = network_start(nominal, spots, labelled or wand is None, wand)
    if wand is not None and (labelled or net is not None):
        _check_wand_length(nominal, _wand_points(spots, None if labelled else net.order,
                                                 labelled), wand)
    # the starts: the deployment's cameras, and those placed from the free sets, both moved
    # onto the references first (marks define a frame of their own)
    starts = [align_to_references(list(nominal), uv, X)]
    if net is not None:
        starts.append(align_to_references(net.cameras, uv, X, scale_fixed=wand is not None))

    def points_of(cams):
        """The free points' spots for a start: a wand's ends named per set by the pairwise
        matching where two of its cameras have it, else by ``cams``."""
        if wand is None:
            return uv_free
        if labelled:
            return _wand_points(spots, None, True)
        if net is not None:  # within a few times the start's own misfit
            tol = LABEL_TOLERANCE * _reprojection(cams, _wand_points(spots, net.order, False))
        else:  # a share of the image (the epipolar bound of the pairwise matching)
            tol = EPIPOLAR_SHARE * float(np.median([np.hypot(c.width, c.height)
                                                    for c in nominal]))
        order = label_wand(cams, spots, wand, tol if np.isfinite(tol) else np.inf)
        if net is not None:
            tree = (net.order >= 0).any(axis=2).sum(axis=0) >= 2
            order[:, tree] = net.order[:, tree]
        return _wand_points(spots, order, False)

    tries = [(cams, points_of(cams)) for cams in starts]
    errs = [_reprojection(cams, pts) for cams, pts in tries]
    if len(tries) > 1 and not errs[1] < BETTER_START * errs[0]:
        tries, errs = tries[:1], errs[:1]
    X0 = _reference_start(tries[0][0], X, uv)
    kept = ""
    if lens == "auto" and free_height is not None:
        # a robot's LED shows each camera one plane: the references must fix the rest of its
        # lens, which needs three or more of them in its view at two heights or more
        weak = [ids_c[k] for k in range(C)
                if seen_r[k].sum() < 3 or np.ptp(X0[seen_r[k], 2]) <= 0]
        if weak:
            lens = "pose"
            kept = (f"camera{'s' if len(weak) > 1 else ''} {', '.join(weak)} "
                    f"{'see' if len(weak) > 1 else 'sees'} fewer than three reference points "
                    "at two heights, and a robot's LED at one height cannot fix a lens alone")
            notes.append(f"lens kept as in the deployment (pose only): {kept}")
    step = 0
    total = progress_steps(N, wand, labelled) + 3 * (len(tries) - 1)

    def tick():
        nonlocal step
        step += 1
        if progress:
            progress(step, total)

    per_set = 2 if wand is not None else 1
    wand_sigma = None if wand is None else WAND_PRECISION * wand
    rejected = dict.fromkeys(ids_c, 0)
    dropped = 0
    P0 = free = unmeasured = uv_all = pair_i = free_idx = held_out = None

    def prepare(pts_free, cams):
        """The joint fit's unknowns from the free points' spots ``pts_free`` (C×M×2), started
        from ``cams``: the references, then the usable free points (two views, or one at a
        stated height; a wand's set whole, every tenth set held out to judge it; an even
        sample of at most :data:`MAX_FREE_SETS` sets). Returns the spots kept (C×P)."""
        nonlocal P0, free, unmeasured, uv_all, pair_i, free_idx, held_out, dropped
        seen_p = np.isfinite(pts_free).all(axis=2)
        F0 = _start(cams, pts_free, free_height)
        usable = np.isfinite(F0).all(axis=1)
        if free_height is None:
            usable &= seen_p.sum(axis=0) >= 2
        possible = F0[:, 2] > -0.05 * scale  # not under the floor (a floor's mirror image)
        for k, cam in enumerate(cams):  # in front of every camera that saw it (cheirality)
            depth = cam.to_camera(np.nan_to_num(F0))[:, 2]
            possible &= ~seen_p[k] | (depth > 0.05 * scale)
        # two views that cannot both be of the LED are dropped here; of three or more, the
        # fit's rejection finds the one that is not
        impossible = usable & ~possible & (seen_p.sum(axis=0) <= 2)
        dropped += int(impossible.sum())
        usable &= ~impossible
        held_out = np.zeros(len(usable), bool)
        if wand is not None:
            whole = usable[0::2] & usable[1::2]
            out = np.zeros(len(whole), bool)
            out[np.flatnonzero(whole)[HELD_OUT_EVERY - 1::HELD_OUT_EVERY]] = True
            held_out = np.repeat(out, 2)
            usable = np.repeat(whole & ~out, 2)
        free_idx = np.flatnonzero(usable)
        if len(free_idx) > MAX_FREE_SETS * per_set:  # time and memory bounded
            sets = free_idx[::per_set]
            note = (f"{len(sets)} free sets usable: {MAX_FREE_SETS} of them, evenly spread in "
                    "time, calibrate the cameras (more add little and cost much)")
            notes[:] = [n for n in notes if not n.endswith("(more add little and cost much)")]
            notes.append(note)
            sets = sets[np.linspace(0, len(sets) - 1, MAX_FREE_SETS).round().astype(int)]
            free_idx = (sets[:, None] + np.arange(per_set)).ravel()
        P0 = np.vstack([X0, F0[free_idx]])
        free = np.r_[np.zeros(N, bool), np.ones(len(free_idx), bool)]
        unmeasured = np.r_[~measured, np.zeros((len(free_idx), 3), bool)]
        uv_all = np.concatenate([uv, pts_free[:, free_idx]], axis=1)
        pair_i = N + np.arange(0, len(free_idx), 2) if wand is not None else np.zeros(0, int)
        return np.isfinite(uv_all).all(axis=2)

    def lengths_of(keep):
        """The wand's lengths between LEDs that two cameras still see each."""
        if wand is None:
            return None
        ok = (keep[:, pair_i].sum(axis=0) >= 2) & (keep[:, pair_i + 1].sum(axis=0) >= 2)
        return pair_i[ok], pair_i[ok] + 1, wand, wand_sigma

    def prior(s_x):
        """Per coordinate, how well it is known (m): the references' precision where they
        were measured, nothing for a free LED, the stated height as good as exact."""
        sig = np.full((len(free), 3), float(s_x))
        sig[:N] *= share
        sig[free] = np.inf
        sig[unmeasured] = np.inf
        if free_height is not None:
            sig[free, 2] = 1e-3 * s_x
        return sig

    def adjust(cams, models, keep):
        obs = _observations(uv_all, keep)
        s_px0 = 0.1
        return obs, estimate_precision(cams, P0, obs, models, s_px0, point_sigma=stated,
                                       free=free, fixed_height=free_height,
                                       unmeasured=unmeasured, lengths=lengths_of(keep),
                                       share=np.r_[share, np.ones((len(free) - N, 3))],
                                       aspect=aspect)

    def _adjust_state(state, cams, models, keep):
        """:func:`adjust` on a saved fit's unknowns."""
        nonlocal P0, free, unmeasured, uv_all, pair_i
        P0, free, unmeasured, uv_all, pair_i = (state[k] for k in (
            "P0", "free", "unmeasured", "uv_all", "pair_i"))
        return adjust(cams, models, keep)

    def reject(cams, models, keep):
        """Fit; reject what does not fit; fit again (three rounds at most)."""
        nonlocal dropped
        for _ in range(3):
            obs, (s_x, s_px, cams, adj) = adjust(cams, models, keep)
            tick()
            err = np.full(keep.shape, 0.0)
            for k, cam in enumerate(cams):
                idx = np.flatnonzero(keep[k])
                e = np.linalg.norm(cam.project(adj[idx])[0] - uv_all[k, idx], axis=1)
                err[k, idx] = np.nan_to_num(e, nan=np.inf)
            wrong = err.max(axis=0) > REJECT_SIGMAS * s_px
            long = _wrong_lengths(adj, pair_i, keep, wand, wand_sigma)
            if long.any():  # a wand set whose two "LEDs" are not the bar's ends
                keep[:, pair_i[long]] = keep[:, pair_i[long] + 1] = False
                wrong[pair_i[long]] = wrong[pair_i[long] + 1] = False
                dropped += int(long.sum())
            if not wrong.any() and not long.any():
                break
            views = keep.sum(axis=0)
            # three views or more (or a reference, which its record holds): the worst spot is
            # the one that disagrees; two views of a free LED that disagree cannot say which
            blame = wrong & ((views >= 3) | ~free | (free_height is not None))
            worst = err.argmax(axis=0)
            for j in np.flatnonzero(blame):
                keep[worst[j], j] = False
                rejected[ids_c[worst[j]]] += 1
            pair = wrong & ~blame
            keep[:, pair] = False
            dropped += int(pair.sum())
            if free_height is None:  # a free set left with one view fixes nothing
                keep[:, N:] &= keep[:, N:].sum(axis=0) >= 2
        return obs, s_x, s_px, cams, adj, keep

    models = ["pose"] * C

    def fitted_from(cams, pts):
        """The pose-only fit, with rejection, from a start; and the state it fitted."""
        nonlocal X0, dropped, rejected
        X0 = _reference_start(cams, X, uv)
        dropped, rejected = 0, dict.fromkeys(ids_c, 0)
        keep = prepare(pts, cams)
        got = reject(list(cams), models, keep)
        return got, dict(X0=X0, P0=P0, free=free, unmeasured=unmeasured, uv_all=uv_all,
                         pair_i=pair_i, free_idx=free_idx, held_out=held_out, dropped=dropped,
                         rejected=rejected, pts_free=pts)

    # from each start (the free sets' start only where it fits them far better): the fit
    # whose spots then scatter least, which is the deeper minimum of the same data
    fits = [fitted_from(cams, pts) for cams, pts in tries]
    if len(fits) > 1:
        # judged with a lens (k1) fitted from each: a pose-only fit leaves the lenses' error in
        # the references of both alike, and cannot tell the minima apart
        judged = []
        for (got, state) in fits:
            obs_, (s_x_, s_px_, cams_, adj_) = _adjust_state(state, got[3], ["k1"] * C, got[5])
            judged.append(((obs_, s_x_, s_px_, cams_, adj_, got[5]), state))
        # one scale for both: the finer fit's (a start that diverged has none)
        s_x0 = float(np.nanmin([j[0][1] for j in judged] + [np.inf]))
        s_px0 = float(np.nanmin([j[0][2] for j in judged] + [np.inf]))
        # the deployment's start is kept unless its fit is far worse: where both fit alike,
        # the data's start has shown no better minimum (and, on a carefully hung install,
        # can lead the lens choice astray)
        m = [_misfit(j, s_x0, s_px0) for j in judged]
        m = [v if np.isfinite(v) else np.inf for v in m]
        best = 1 if m[1] < BETTER_START * m[0] else 0
    else:
        best = 0
    (obs, s_x, s_px, cams, adj, keep), state = fits[best]
    X0, P0, free, unmeasured, uv_all, pair_i, free_idx, held_out, dropped, rejected, \
        pts_free = state.values()
    if best == 1:
        notes.append(f"the cameras' start placed from the free sets (they fit them to "
                     f"{errs[1]:.2g} px, the deployment's cameras to {errs[0]:.2g} px; the "
                     f"fit from them to ±{s_px:.2g} px, from the deployment's to "
                     f"±{fits[0][0][2]:.2g} px)")
    if wand is not None and not labelled:
        # the ends named again with the fitted cameras, every set's views at once, and
        # fitted again
        order = label_wand(cams, spots, wand, LABEL_TOLERANCE * s_px)
        (obs, s_x, s_px, cams, adj, keep), state = fitted_from(
            cams, _wand_points(spots, order, False))
        X0, P0, free, unmeasured, uv_all, pair_i, free_idx, held_out, dropped, rejected, \
            pts_free = state.values()
    choices = []
    if lens == "auto":
        chosen, held = _joint_lens_choice(cams, adj, prior(s_x), uv_all, keep, free, s_px,
                                          lengths=lengths_of(keep), aspect=aspect)
        models = [chosen] * C
        from .calibration import _lens_choice
        from .camera_fit import fit_camera

        for k, cam in enumerate(cams):
            idx = np.flatnonzero(keep[k])
            fit = fit_camera(nominal[k], adj[idx], uv_all[k, idx], [""] * len(idx), chosen,
                             start=cam)
            cand = {m: {"held_out_px": v, "supported": True, "reason": ""}
                    for m, v in held.items()}
            choices.append(_lens_choice(fit, cam.id, False, cand, adj[idx]))
    else:
        if lens not in LENS_MODELS:
            raise ValueError(f"lens: expected auto or one of {', '.join(LENS_MODELS)}")
        models = [lens] * C
    tick()
    obs, (s_x, s_px, cams, adj) = adjust(cams, models, keep)
    tick()
    _check_fit(cams, adj[N:], uv_all[:, N:], keep[:, N:], s_px, ids_c)
    _check_references_fit(seen_r, keep[:, :N], ids_c)
    in_marks_frame = bool((~measured).any())  # frame marks define a frame of their own
    if room is not None and in_marks_frame:  # the room moved into it
        from .marks_frame import polygons_in_marks_frame

        room = polygons_in_marks_frame(nominal, cams, [room])[0]
    _check_inside(adj[N:], room, cams)
    # the wand's length on held-out sets: a wand that does not fit is refused before the
    # references are left out in turn (each a joint fit)
    wand_error = None if wand is None else wand_errors(cams, pts_free[:, held_out], wand, ids_c,
                                                        s_px)
    if wand_error is not None and not wand_error.mean <= WAND_MISFIT * wand:
        said = (f"{wand_error.sets} held-out sets put its ends {format_length(wand_error.mean)} "
                f"from its {format_length(wand)} on average" if wand_error.sets else
                "no held-out set shows its two ends meeting")
        raise SurveyError(f"the wand does not fit the cameras: {said} (of "
                          f"{int(held_out.sum()) // 2} held out, {wand_error.discarded} whose "
                          f"spots do not meet; the spots fit to ±{s_px:.2g} px): the second "
                          "spot is not the wand's other LED "
                          "(a reflection, another light, a survey of one LED), or the LEDs' "
                          "names are swapped for a camera; nothing was written")
    # each reference left out: its prior removed (its spots kept), where the rest put it —
    # when the rest still fix the frame; of many, an even sample (each costs a joint fit)
    base = prior(s_x)
    left_out = np.unique(np.linspace(0, N - 1, min(N, MAX_LEFT_OUT)).round().astype(int))
    if len(left_out) < N:
        notes.append(f"{len(left_out)} of the {N} references left out in turn (an even "
                     "sample: each costs a joint fit)")

    def leave_each_out(cams_, adj_, out_, count=True):
        """Per reference of ``left_out``: how far from its record the fit (from ``cams_``,
        ``adj_``) puts it without its prior (m; NaN where the rest would not fix the room),
        the references ``out_`` (N bools) left out all along (their priors removed)."""
        loo_ = np.full(N, np.nan)
        start = np.where(out_[:, None], adj_[:N], X0)
        for i in left_out:
            if count:
                tick()
            rest = used_r & ~out_
            rest[i] = False
            if out_[i] or keep[:, i].sum() < (1 if free_height is not None else 2) \
                    or unfixed_motions(adj_[:N][rest], measured[rest], free_height is not None,
                                       wand is not None, scale):
                continue
            sig = base.copy()
            sig[:N][out_] = np.inf
            sig[i] = np.inf
            _, moved = refine_jointly(cams_, np.vstack([start[:i], adj_[i:i + 1],
                                                        start[i + 1:N], adj_[N:]]), obs,
                                      point_sigma=sig, pixel_sigma=s_px, models=models,
                                      iterations=6, lengths=lengths_of(keep), aspect=aspect)
            off = np.where(measured[i], moved[i] - X0[i], 0.0)
            loo_[i] = float(np.linalg.norm(off))
        return loo_

    loo = leave_each_out(cams, adj, np.zeros(N, bool))
    free_xyz = np.full((pts_free.shape[1], 3), np.nan)
    free_xyz[free_idx] = adj[N:]
    spread = {}
    for k, cam in enumerate(cams):
        idx = np.flatnonzero(keep[k] & free)
        err = np.linalg.norm(cam.project(adj[idx])[0] - uv_all[k, idx], axis=1)
        spread[ids_c[k]] = float(np.sqrt(np.mean(err ** 2))) if len(err) else float("nan")
    where = adj[N:] if room is None else _floor_points(room, adj[N:])
    floor = datum_floor(adj[:N][used_r], s_x * share[used_r], where, free_height is not None,
                        measured=measured[used_r],
                        wand_sigma=None if wand is None else WAND_PRECISION)
    # what the whole survey leaves in the cameras, predicted by the linearised adjustment
    from .budget import fix_errors

    # (a wand's lengths are not in the linearised model: without them its scale is free)
    errs = None if wand is not None else fix_errors(cams, adj, where, prior(s_x), s_px,
                                                    models[0])
    exact, predicted = (float("nan"),) * 2 if errs is None else map(
        lambda e: float(np.median(e)), errs)
    while step < total:  # the steps that had nothing to do (a reference no camera pair saw)
        tick()
    if not choices:
        from .calibration import _lens_choice
        from .camera_fit import fit_camera

        for k, cam in enumerate(cams):
            idx = np.flatnonzero(keep[k])
            fit = fit_camera(nominal[k], adj[idx], uv_all[k, idx], [""] * len(idx), models[k],
                             start=cam)
            choice = _lens_choice(fit, cam.id, True, {}, adj[idx])
            if kept:
                choice.reason = f"kept as in the deployment, as {kept}"
            choices.append(choice)
    cal = FreeCalibration(cams, models, choices, free_xyz, adj[:N], float(s_x),
                          estimated, float(s_px), int((keep[:, N:].sum(axis=0) >= 1).sum())
                          // per_set, rejected, spread, loo, floor, dropped, notes,
                          assumed, predicted, exact, wand, wand_error, pts_free, marks_only,
                          room, in_marks_frame, reference_ids=[str(i) for i in ids])
    # a reference whose left-out residual stands far beyond the others': named, with what the
    # survey gives without it (refitted without its prior, the others left out in turn again)
    named, limit = far_beyond(loo, cal.left_out_allowed)
    if named.any():
        with_ = without = moved = float("nan")
        if not unfixed_motions(adj[:N][used_r & ~named], measured[used_r & ~named],
                               free_height is not None, wand is not None, scale):
            sig = base.copy()
            sig[:N][named] = np.inf
            cams_w, adj_w = refine_jointly(
                cams, np.vstack([np.where(named[:, None], adj[:N], X0), adj[N:]]), obs,
                point_sigma=sig, pixel_sigma=s_px, models=models, iterations=WITHOUT_ITERATIONS,
                lengths=lengths_of(keep), aspect=aspect)
            loo_w = leave_each_out(cams_w, adj_w, named, count=False)
            both = np.isfinite(loo) & np.isfinite(loo_w) & ~named
            if both.any():
                with_, without = float(loo[both].mean()), float(loo_w[both].mean())
            moved = max(float(np.linalg.norm(np.subtract(a.center, b.center)))
                        for a, b in zip(cams, cams_w))
        cal.suspects = suspects_of(ids, loo, named, limit, with_, without, moved)
    return cal


def _wrong_lengths(adj, pair_i, keep, wand, wand_sigma) -> np.ndarray:
    """Per wand set (``pair_i``: its first LED's index), whether the fit puts its two LEDs
    further from the wand's length than its sets' own scatter allows (median absolute
    deviation, and the bar's precision, times :data:`REJECT_SIGMAS`)."""
    if wand is None or not len(pair_i):
        return np.zeros(len(pair_i), bool)
    active = (keep[:, pair_i].sum(axis=0) >= 2) & (keep[:, pair_i + 1].sum(axis=0) >= 2)
    res = np.abs(np.linalg.norm(adj[pair_i] - adj[pair_i + 1], axis=1) - wand)
    if not active.any():
        return np.zeros(len(pair_i), bool)
    scatter = 1.4826 * float(np.median(res[active]))
    return active & (res > REJECT_SIGMAS * max(scatter, wand_sigma))


def _check_references_fit(seen, kept, ids) -> None:
    """Refuse a fit that threw out most of a camera's sightings of the references: where the
    free LED places that camera, the references it saw are not — its free spots are another
    camera's, or the survey is another site's."""
    lost = seen & ~kept
    for k in np.flatnonzero((lost.sum(axis=1) >= 2) & (lost.sum(axis=1) > seen.sum(axis=1) / 2)):
        raise SurveyError(f"the free spots do not fit these cameras: where they place camera "
                          f"{ids[k]}, {int(lost[k].sum())} of the {int(seen[k].sum())} "
                          "reference points it saw are not (are the camera ids in free/ the "
                          "deployment's? is the survey from this site?); nothing was written")


def _misfit(fit, s_x: float, s_px: float) -> float:
    """How badly a pose-only fit (:func:`_calibrate_free`'s ``fitted_from``) explains its
    data, on one scale for every start (``s_x`` m, ``s_px`` px): the squared residuals of
    every spot and every measured reference coordinate in units of those, each capped at
    three (a rejected spot counts as the cap), so that a start whose fit throws data out or
    strains the references loses to one that explains them."""
    (_, _, _, cams, adj, keep), state = fit
    uv_all, X0, free, unmeasured = (state[k] for k in ("uv_all", "X0", "free", "unmeasured"))
    total = 0.0
    for k, cam in enumerate(cams):
        seen = np.isfinite(uv_all[k]).all(axis=1)
        r = np.linalg.norm(cam.project(adj[seen])[0] - uv_all[k, seen], axis=1) / s_px
        r = np.where(keep[k, seen], np.nan_to_num(r, nan=3.0), 3.0)
        total += float(np.sum(np.minimum(r, 3.0) ** 2))
    n = len(X0)
    known = ~unmeasured[:n]
    r = np.abs(adj[:n] - X0)[known] / s_x
    return total + float(np.sum(np.minimum(r, 3.0) ** 2))


def _check_fit(cams, X, uv, keep, s_px, ids) -> None:
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
def _joint_lens_choice(cams, P, sig, uv_all, keep, free, s_px, sets: int = 1200,
                       folds: int = 2, lengths=None, aspect=None):
    """One lens model for every camera, chosen by held-out consistency of the free LED: per
    model, the joint fit on the references and all but a fold of (a sample of) the free sets,
    then the held-out sets triangulated with the fitted cameras and their reprojection error —
    with two views, how far the spots are from seeing one point. The simplest model within one
    standard error of the best (paired over the sets). ``lengths``: a wand's (as
    :func:`~.calibration.refine_jointly` takes them), kept where both LEDs are in a fold's
    fit; ``aspect``: the focal lengths' ratios, as it takes them too. Returns (model,
    {model: held-out px})."""
    from ..triangulation import reprojection_errors, triangulate

    C = len(cams)
    cols = np.flatnonzero(free & (keep.sum(axis=0) >= 2))
    sub = np.random.default_rng(0).permutation(cols)[:sets]
    fold = np.arange(len(sub)) % folds
    fixed = np.flatnonzero(~free)
    loss, px = {}, {}
    for m in LENS_MODELS:
        e = np.full(len(sub), np.nan)
        for f in range(folds):
            train = np.r_[fixed, sub[fold != f]]
            test = sub[fold == f]
            kk = keep[:, train]
            obs = [(np.flatnonzero(kk[k]), uv_all[k, train][kk[k]]) for k in range(C)]
            held = None
            if lengths is not None:
                at = np.full(len(P), -1)
                at[train] = np.arange(len(train))
                a, b = at[lengths[0]], at[lengths[1]]
                both = (a >= 0) & (b >= 0)
                held = (a[both], b[both], *lengths[2:])
            try:
                fitted, _ = refine_jointly(cams, P[train], obs, point_sigma=sig[train],
                                           pixel_sigma=s_px, models=[m] * C, iterations=25,
                                           lengths=held, aspect=aspect)
            except (ValueError, np.linalg.LinAlgError):
                break
            uvt = np.where(keep[:, test, None], uv_all[:, test], np.nan)
            X = triangulate(fitted, uvt).X
            r = reprojection_errors(fitted, uvt, X)
            sq = np.where(np.isfinite(uvt[..., 0]) & np.isfinite(r), r, 0.0) ** 2
            n = (np.isfinite(uvt[..., 0]) & np.isfinite(r)).sum(axis=0)
            e[fold == f] = np.where(n > 0, np.sqrt(sq.sum(axis=0) / np.maximum(n, 1)), np.nan)
        if not np.isfinite(e).any():
            break
        loss[m], px[m] = e ** 2, float(np.sqrt(np.nanmean(e ** 2)))
    ok = np.logical_and.reduce([np.isfinite(v) for v in loss.values()])
    if len(loss) < 2 or ok.sum() < 2:
        return "pose", px
    best = min(loss, key=lambda m: loss[m][ok].mean())
    for m in loss:
        d = loss[m][ok] - loss[best][ok]
        if d.mean() <= d.std(ddof=1) / np.sqrt(len(d)):
            return m, px
    return best, px


def _floor_points(room, free_xyz) -> np.ndarray:
    """Where accuracy matters: the room's floor on a grid, at the free positions' heights."""
    room = np.asarray(room, float)
    lo, hi = room.min(axis=0), room.max(axis=0)
    g = np.stack(np.meshgrid(np.linspace(lo[0], hi[0], 12), np.linspace(lo[1], hi[1], 12)),
                 -1).reshape(-1, 2)
    zs = np.nanpercentile(free_xyz[:, 2], [10, 50, 90]) if len(free_xyz) else [0.0]
    return np.vstack([np.c_[g, np.full(len(g), z)] for z in zs])
