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
from .calibration import estimate_precision, refine_jointly
from .errors import SurveyError
from .lens import LENS_MODELS

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
#: a survey whose cameras are predicted to place fixes this many times worse than its references
#: and spots allow is weak (the free LED cannot fix the lens across pair overlaps alone)
WEAK_FACTOR = 2.0
#: … else this precision (a tape measure, per axis, m) is assumed and said
ASSUMED_TAPE = 0.003


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

    @property
    def weakly_fixed(self) -> bool:
        """Whether the survey leaves the cameras far looser than its references allow: fixes
        predicted more than :data:`WEAK_FACTOR` times the error of exact cameras placed in the
        references' frame (the spot noise and the datum floor together)."""
        return bool(self.predicted_error > WEAK_FACTOR * np.hypot(self.exact_error,
                                                                  self.datum_floor))


def datum_floor(references, sigma: float, where, free_height: bool = False) -> float:
    """RMS displacement (m) at the points ``where`` of the frame that ``references`` measured to
    ±``sigma`` per axis define: the similarity transform (translation, rotation, scale; with a
    known floor plane only x, y, yaw and scale) fitted to their noise, linearised."""
    R = np.asarray(references, float)
    c = R.mean(axis=0)

    def design(P):
        d = np.asarray(P, float) - c
        n = len(d)
        rows = np.zeros((n, 3, 7))
        rows[:, :, :3] = np.eye(3)
        # small rotation ω × d: columns ω_x, ω_y, ω_z
        rows[:, 0, 4], rows[:, 0, 5] = d[:, 2], -d[:, 1]
        rows[:, 1, 3], rows[:, 1, 5] = -d[:, 2], d[:, 0]
        rows[:, 2, 3], rows[:, 2, 4] = d[:, 1], -d[:, 0]
        rows[:, :, 6] = d
        if free_height:  # z, and the tilts ω_x, ω_y, are fixed by the plane
            rows = rows[:, :2][:, :, [0, 1, 5, 6]]
        return rows.reshape(-1, rows.shape[-1])

    A = design(R)
    cov = sigma ** 2 * np.linalg.pinv(A.T @ A)
    B = design(where)
    k = 2 if free_height else 3
    per = np.einsum("ij,jk,ik->i", B, cov, B).reshape(-1, k).sum(axis=1)
    return float(np.sqrt(per.mean()))


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


def _check_references(X, seen_ref, free_height, scale: float) -> None:
    """Refuse references that cannot fix the room's frame: too few, all at one place (within
    1e-3 of ``scale``, the cameras' distance), or on one line."""
    need = 2 if free_height is not None else 3
    used = np.asarray(X, float)[seen_ref.any(axis=0)]
    if len(used) < need:
        raise SurveyError(f"{len(used)} reference point{'s' if len(used) != 1 else ''} seen by "
                          f"a camera; fixing the room's frame needs at least {need}"
                          + (" (or --free-height and 2)" if free_height is None else ""))
    s = np.linalg.svd(used - used.mean(axis=0), compute_uv=False)
    if not s[0] > 1e-3 * scale:
        raise SurveyError("the reference points are all at one place: they cannot fix the "
                          "room's scale and rotation (spread them over the room)")
    if free_height is None and s[1] <= 1e-3 * s[0]:
        raise SurveyError("the reference points lie on one line: they cannot fix the room's "
                          "rotation about it (add a point off the line)")


def _check_height(cameras, X, uv, uv_free, free_height) -> None:
    """Refuse a stated free height the free sets contradict: where two cameras or more saw
    the LED, the nominal cameras place it; their heights must sit about ``free_height`` as
    closely as the references' triangulated heights sit about their measured ones (five times
    that, and the references as the yardstick: the nominal cameras' own error)."""
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
        raise SurveyError(f"--free-height {free_height:g}: the {int(two.sum())} free sets that "
                          f"two cameras saw put the LED at {lo:.2f}–{hi:.2f} m (half of them "
                          f"more than {np.nanmedian(off):.2f} m from {free_height:g}), while the "
                          f"reference points come out within {yard * 1000:.0f} mm of their "
                          "measured heights: the LED was not at that height (drop --free-height"
                          " if it moved up and down)")


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
    """Free positions from the nominal cameras: triangulated where two or more saw the LED,
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


def _observations(uv_all, keep):
    return [(np.flatnonzero(keep[k]), uv_all[k, keep[k]]) for k in range(len(uv_all))]


def calibrate_free(nominal: list[Camera], X, uv, ids, uv_free, lens: str = "auto",
                   point_sigma: float | str = "auto", free_height: float | None = None,
                   room=None, progress=None) -> FreeCalibration:
    """:func:`_calibrate_free`; a joint fit that cannot converge is a :class:`SurveyError`."""
    try:
        return _calibrate_free(nominal, X, uv, ids, uv_free, lens, point_sigma, free_height,
                               room, progress)
    except np.linalg.LinAlgError:
        raise SurveyError("the joint fit did not converge: the free spots do not fit these "
                          "cameras (are the camera ids in free/ the deployment's? is the "
                          "survey from this site?); nothing was written") from None


def _calibrate_free(nominal: list[Camera], X, uv, ids, uv_free, lens: str = "auto",
                    point_sigma: float | str = "auto", free_height: float | None = None,
                    room=None, progress=None) -> FreeCalibration:
    """Calibrate every camera from a free survey: ``X`` N×3 the references' measured
    positions, ``uv`` C×N×2 their spots, ``uv_free`` C×M×2 the free sets' spots (NaN: not seen).
    ``lens``: ``"auto"`` (one model for every camera, chosen by the free LED's held-out
    consistency: :func:`_joint_lens_choice`) or a model of :data:`~.lens.LENS_MODELS`.
    ``room``: the floor polygon the datum floor is judged over. ``progress(i, n)``."""
    X, uv, uv_free = np.asarray(X, float), np.asarray(uv, float), np.asarray(uv_free, float)
    C, N = len(nominal), len(X)
    ids_c = [c.id for c in nominal]
    seen_f = np.isfinite(uv_free).all(axis=2)
    seen_r = np.isfinite(uv).all(axis=2)
    _linkage(ids_c, seen_f)
    scale = float(np.median([c.position[2] for c in nominal])) or 1.0
    _check_references(X, seen_r, free_height, scale)
    if free_height is not None:
        _check_height(nominal, X, uv, uv_free, free_height)
    estimated = isinstance(point_sigma, str)
    stated = None if estimated else float(point_sigma)
    notes: list = []
    assumed = False
    n_ref = int(seen_r.any(axis=0).sum())
    datum = 4 if free_height is not None else 7  # what the references must fix first
    if estimated and 3 * n_ref - datum < MIN_REDUNDANT:
        # too few references to show their own scatter: a tape's precision is assumed
        stated, estimated, assumed = ASSUMED_TAPE, False, True
        notes.append(f"{n_ref} reference points cannot show how precisely they were measured "
                     f"(they have {max(3 * n_ref - datum, 0)} coordinates beyond what fixes the "
                     f"room): ±{ASSUMED_TAPE * 1000:g} mm (a tape) assumed; state --point-sigma, "
                     "or measure more points")
    kept = ""
    if lens == "auto" and free_height is not None:
        # a robot's LED shows each camera one plane: the references must fix the rest of its
        # lens, which needs three or more of them in its view at two heights or more
        weak = [ids_c[k] for k in range(C)
                if seen_r[k].sum() < 3 or np.ptp(X[seen_r[k], 2]) <= 0]
        if weak:
            lens = "pose"
            kept = (f"camera{'s' if len(weak) > 1 else ''} {', '.join(weak)} "
                    f"{'see' if len(weak) > 1 else 'sees'} fewer than three reference points "
                    "at two heights, and a robot's LED at one height cannot fix a lens alone")
            notes.append(f"lens kept as in the deployment (pose only): {kept}")
    step = 0
    total = 5 + min(N, MAX_LEFT_OUT)

    def tick():
        nonlocal step
        step += 1
        if progress:
            progress(step, total)

    F0 = _start(nominal, uv_free, free_height)
    usable = np.isfinite(F0).all(axis=1)
    if free_height is None:
        usable &= seen_f.sum(axis=0) >= 2
    free_idx = np.flatnonzero(usable)
    if len(free_idx) > MAX_FREE_SETS:  # time and memory bounded: an even sample of them
        notes.append(f"{len(free_idx)} free sets usable: {MAX_FREE_SETS} of them, evenly "
                     "spread in time, calibrate the cameras (more add little and cost much)")
        free_idx = free_idx[np.linspace(0, len(free_idx) - 1, MAX_FREE_SETS).round()
                            .astype(int)]
    P0 = np.vstack([X, F0[free_idx]])
    free = np.r_[np.zeros(N, bool), np.ones(len(free_idx), bool)]
    uv_all = np.concatenate([uv, uv_free[:, free_idx]], axis=1)
    keep = np.isfinite(uv_all).all(axis=2)
    rejected = dict.fromkeys(ids_c, 0)

    def adjust(cams, models, keep):
        obs = _observations(uv_all, keep)
        s_px0 = 0.1
        return obs, estimate_precision(cams, P0, obs, models, s_px0, point_sigma=stated,
                                       free=free, fixed_height=free_height)

    models = ["pose"] * C
    cams = list(nominal)
    dropped = 0
    for _ in range(3):  # fit; reject what does not fit; fit again
        obs, (s_x, s_px, cams, adj) = adjust(cams, models, keep)
        tick()
        err = np.full(keep.shape, 0.0)
        for k, cam in enumerate(cams):
            idx = np.flatnonzero(keep[k])
            e = np.linalg.norm(cam.project(adj[idx])[0] - uv_all[k, idx], axis=1)
            err[k, idx] = np.nan_to_num(e, nan=np.inf)
        wrong = err.max(axis=0) > REJECT_SIGMAS * s_px
        if not wrong.any():
            break
        views = keep.sum(axis=0)
        # three views or more (or a reference, which its record holds): the worst spot is the
        # one that disagrees; two views of a free LED that disagree cannot say which is wrong
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
    choices = []
    if lens == "auto":
        sig = np.where(free[:, None], np.inf, np.full((len(free), 3), s_x))
        if free_height is not None:
            sig[free, 2] = 1e-3 * s_x
        chosen, held = _joint_lens_choice(cams, adj, sig, uv_all, keep, free, s_px)
        models = [chosen] * C
        from .calibration import _lens_choice, fit_camera

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
    _check_inside(adj[N:], room, cams)
    # each reference left out: its prior removed (its spots kept), where the rest put it; of
    # many, an even sample (each costs a joint fit)
    loo = np.full(N, np.nan)
    need = 2 if free_height is not None else 3
    if seen_r.any(axis=0).sum() > need:
        base = np.where(free[:, None], np.inf, np.full((len(free), 3), s_x))
        if free_height is not None:
            base[free, 2] = 1e-3 * s_x  # stated: as good as exact
        left_out = np.unique(np.linspace(0, N - 1, min(N, MAX_LEFT_OUT)).round().astype(int))
        if len(left_out) < N:
            notes.append(f"{len(left_out)} of the {N} references left out in turn (an even "
                         "sample: each costs a joint fit)")
        for i in left_out:
            tick()
            if keep[:, i].sum() < (1 if free_height is not None else 2):
                continue
            sig = base.copy()
            sig[i] = np.inf
            _, moved = refine_jointly(cams, np.vstack([X[:i], adj[i:i + 1], X[i + 1:N],
                                                       adj[N:]]), obs, point_sigma=sig,
                                      pixel_sigma=s_px, models=models, iterations=6)
            loo[i] = float(np.linalg.norm(moved[i] - X[i]))
    free_xyz = np.full((uv_free.shape[1], 3), np.nan)
    free_xyz[free_idx] = adj[N:]
    spread = {}
    for k, cam in enumerate(cams):
        idx = np.flatnonzero(keep[k] & free)
        err = np.linalg.norm(cam.project(adj[idx])[0] - uv_all[k, idx], axis=1)
        spread[ids_c[k]] = float(np.sqrt(np.mean(err ** 2))) if len(err) else float("nan")
    where = adj[N:] if room is None else _floor_points(room, adj[N:])
    floor = datum_floor(X[seen_r.any(axis=0)], s_x, where, free_height is not None)
    # what the whole survey leaves in the cameras, predicted by the linearised adjustment
    from .budget import fix_errors

    sig = np.where(free[:, None], np.inf, np.full((len(free), 3), s_x))
    if free_height is not None:
        sig[free, 2] = 1e-3 * s_x
    errs = fix_errors(cams, adj, where, sig, s_px, models[0])
    exact, predicted = (float("nan"),) * 2 if errs is None else map(
        lambda e: float(np.median(e)), errs)
    while step < total:  # the steps that had nothing to do (a reference no camera pair saw)
        tick()
    if not choices:
        from .calibration import _lens_choice, fit_camera

        for k, cam in enumerate(cams):
            idx = np.flatnonzero(keep[k])
            fit = fit_camera(nominal[k], adj[idx], uv_all[k, idx], [""] * len(idx), models[k],
                             start=cam)
            choice = _lens_choice(fit, cam.id, True, {}, adj[idx])
            if kept:
                choice.reason = f"kept as in the deployment, as {kept}"
            choices.append(choice)
    return FreeCalibration(cams, models, choices, free_xyz, adj[:N], float(s_x),
                           estimated, float(s_px), int((keep[:, N:].sum(axis=0) >= 1).sum()),
                           rejected, spread, loo, floor, dropped, notes,
                           assumed, predicted, exact)


def _joint_lens_choice(cams, P, sig, uv_all, keep, free, s_px, sets: int = 1200,
                       folds: int = 2):
    """One lens model for every camera, chosen by held-out consistency of the free LED: per
    model, the joint fit on the references and all but a fold of (a sample of) the free sets,
    then the held-out sets triangulated with the fitted cameras and their reprojection error —
    with two views, how far the spots are from seeing one point. The simplest model within one
    standard error of the best (paired over the sets). Returns (model, {model: held-out px})."""
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
            try:
                fitted, _ = refine_jointly(cams, P[train], obs, point_sigma=sig[train],
                                           pixel_sigma=s_px, models=[m] * C, iterations=25)
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
