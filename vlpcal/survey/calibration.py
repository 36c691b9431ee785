"""Cameras fitted to a survey: each camera on its own (:mod:`.camera_fit`), its lens model
decided by the held-out 3D error (:mod:`.lens_decision`), then every camera and every surveyed
position together, with the survey's measurement precision estimated from the fit when it is
not stated.

Every decision is relative to the scene: outliers against the fit's own residual spread and
the image size, lens models against the held-out points' own errors, the positions'
precision against the spot noise. The same survey scaled by any factor calibrates the same.

One module, a little over 500 lines: the per-camera fits, the joint refinement and the
precision estimate work on the same observations and are read in that order.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..geometry import Camera
from ..reading import slipped_units
from ..triangulation import triangulate
from .camera_fit import CameraFit, fit_camera
from .errors import SurveyError
from .least_squares import SchurSolver, levenberg_marquardt
from .lens import (
    LENS_MODELS,
    LENS_WORDS,
    SINGULAR,
    describe_lens,
    from_vector,
    lens_params,
    min_points,
    project_with_jacobian,
    to_vector,
)
from .lens_decision import as_start, data_starts, decide

#: a camera whose spots scatter about its best fit by more than this share of its image
#: diagonal is not seeing the LED (random spots, a wrong id)
GARBAGE_IMAGE_SHARE = 0.025
#: a tape's stated precision past this share of the survey's extent is a unit slip (a tape
#: read to within a tenth of the room measures nothing)
SIGMA_SHARE = 0.1


# -- the lens model, chosen by held-out error -----------------------------------------------

@dataclass
class LensChoice:
    """One camera's lens decision: the candidates' held-out figures and the one chosen."""

    camera_id: str
    chosen: str
    forced: bool
    #: model → {"held_out_px": RMS px or None, "held_out_3d_m": mean m (the other cameras as
    #: chosen) or None, "supported": whether it was fitted, "determined": whether the survey
    #: pins it, "reason": why not}
    candidates: dict
    depth_rel_range: float = float("nan")
    scene_per_px: float = float("nan")  # m per px at the camera's points (distance / f)
    #: why the model was set rather than chosen, when the survey (not the user) set it
    reason: str = ""
    #: what the survey determines only weakly in the chosen model (a warning, not a refusal)
    weak: str = ""


def _lens_choice(fit: CameraFit, camera_id: str, forced: bool, candidates: dict,
                 X) -> LensChoice:
    """The decision record of ``fit`` (on the points ``X`` it was given), with the scene's
    metres per pixel at the camera's points for the report's words."""
    cam = fit.camera
    depth = cam.to_camera(np.asarray(X, float)[fit.keep])[:, 2]
    return LensChoice(camera_id, fit.model, forced, candidates, fit.support.depth_rel_range,
                      float(np.median(depth) / (0.5 * (cam.fx + cam.fy))))


def _model_starts(nominal: Camera, X, uv, model: str) -> tuple:
    """The data's own starts for ``model`` (:func:`~.lens_decision.data_starts`) where it
    frees the principal point, whose fit has several minima; none otherwise."""
    if "cx" not in lens_params(model):
        return ()
    return tuple(as_start(s, nominal, model) for s in data_starts(nominal, X, uv))


def _decided_choice(decision, camera_id: str, fit: CameraFit, X) -> LensChoice:
    """The decision record of one camera from the held-out figures of ``decision``
    (:class:`~.lens_decision.LensDecision`): per model its held-out reprojection (px) and,
    with the other cameras as chosen, held-out 3D error (m)."""
    cand = {}
    for model, mf in decision.fits[camera_id].items():
        r = mf.reprojection_px[np.isfinite(mf.reprojection_px)]
        cand[model] = {"held_out_px": float(np.sqrt(np.mean(r ** 2))) if len(r) else None,
                       "held_out_3d_m": _finite_or_none(
                           decision.per_camera_m.get(camera_id, {}).get(model)),
                       "supported": True, "determined": bool(mf.fit.support.ok),
                       "reason": mf.fit.support.reason}
    choice = _lens_choice(fit, camera_id, False, cand, X)
    if not fit.support.ok:
        choice.weak = fit.support.reason
    return choice


def _finite_or_none(x) -> float | None:
    return float(x) if x is not None and np.isfinite(x) else None


# -- every camera and position together -----------------------------------------------------

def _pattern(npars, obs, n_pts, pairs=None):
    """Rows and columns of the bundle adjustment's Jacobian, in the order :func:`refine_jointly`
    fills its values: per camera, each observation row against the camera's parameters, then
    against its point's three coordinates; then each position prior against its point; last,
    each length of ``pairs`` (i, j) against both points' coordinates."""
    rows, cols = [], []
    off = np.concatenate([[0], np.cumsum(npars)])
    base_pts = off[-1]
    row = 0
    for k, (idx, _) in enumerate(obs):
        r = row + np.arange(2 * len(idx))
        rows += [np.repeat(r, npars[k]), np.repeat(r, 3)]
        cols += [np.tile(np.arange(off[k], off[k + 1]), 2 * len(idx)),
                 (base_pts + 3 * np.repeat(idx, 2)[:, None] + np.arange(3)).ravel()]
        row += 2 * len(idx)
    rows.append(row + np.arange(3 * n_pts))
    cols.append(base_pts + np.arange(3 * n_pts))
    row += 3 * n_pts
    if pairs is not None:
        i, j = pairs
        rows.append(np.repeat(row + np.arange(len(i)), 6))
        cols.append((base_pts + np.c_[3 * i[:, None] + np.arange(3),
                                      3 * j[:, None] + np.arange(3)]).ravel())
        row += len(i)
    return np.concatenate(rows), np.concatenate(cols), (row, base_pts + 3 * n_pts)


def refine_jointly(cameras: list[Camera], X, obs, intrinsics: bool = False,
                   point_sigma=0.003, pixel_sigma: float = 0.1,
                   models: list[str] | None = None, iterations: int = 60, lengths=None,
                   aspect=None):
    """Bundle adjustment: every camera's pose (and the lens its model frees) and every
    surveyed position together, each position free within its measurement uncertainty
    (``point_sigma`` m per axis: one for all, or N×3 per coordinate, ``inf`` for a position
    nothing measured — a free survey's LED, whose start ``X`` is only a start) against spots
    of ``pixel_sigma`` px.

    ``obs``: list per camera of (point indices, uv K×2) — the observations kept by
    :func:`fit_camera`. ``lengths``: (i, j, length, sigma), arrays of pairs of points held
    ``length`` m apart within ``sigma`` m (a wand's two LEDs). ``aspect``: (ratios, sigma):
    each freed pair of focal lengths keeps its ratio fx / fy near the camera's ratio (C, e.g.
    the deployment's) within the relative spread ``sigma`` — pixels are square, and a camera
    that sees the LED over part of its image cannot otherwise tell a stretched focal length
    from a shifted pose. Returns (cameras, adjusted positions N×3).
    """

    X = np.asarray(X, float)
    prior = (1.0 / np.broadcast_to(np.asarray(point_sigma, float), X.shape)).ravel()
    if models is None:
        models = ["full" if intrinsics else "pose"] * len(cameras)
    npars = [6 + len(lens_params(m)) for m in models]
    off = np.concatenate([[0], np.cumsum(npars)])
    p0 = np.concatenate([*(to_vector(c, m) for c, m in zip(cameras, models)), X.ravel()])

    if lengths is not None:
        li, lj = (np.asarray(a, int) for a in lengths[:2])
        L, w_len = (np.broadcast_to(np.asarray(a, float), li.shape) for a in lengths[2:])
        w_len = 1.0 / w_len
    rows, cols, shape = _pattern(npars, obs, len(X), None if lengths is None else (li, lj))
    stretch = ([k for k, m in enumerate(models) if "fy" in lens_params(m)]
               if aspect is not None else [])
    if stretch:  # a row per camera: fx − a₀ fy, in units of the ratio's spread
        ratio = np.asarray(aspect[0], float)[stretch]
        unit = np.array([aspect[1] * cameras[k].fy for k in stretch])
        at_fx = off[stretch] + 6  # fx, then fy, follow the pose in the vector
        rows = np.r_[rows, np.repeat(shape[0] + np.arange(len(stretch)), 2)]
        cols = np.r_[cols, np.c_[at_fx, at_fx + 1].ravel()]
        shape = (shape[0] + len(stretch), shape[1])

    def unpack(p):
        pts = p[off[-1]:].reshape(-1, 3)
        return pts, [from_vector(cameras[k], p[off[k]:off[k + 1]], models[k])
                     for k in range(len(cameras))]

    def resid(p):
        pts, cams = unpack(p)
        out = [np.nan_to_num((c.project(pts[idx])[0] - uv) / pixel_sigma, nan=1e4).ravel()
               for c, (idx, uv) in zip(cams, obs)]
        out.append((pts - X).ravel() * prior)
        if lengths is not None:
            out.append((np.linalg.norm(pts[li] - pts[lj], axis=1) - L) * w_len)
        if stretch:
            out.append((p[at_fx] - ratio * p[at_fx + 1]) / unit)
        return np.concatenate(out)

    def jac(p):
        from scipy.sparse import csr_matrix  # (scipy: loaded by a fit only)

        pts, cams = unpack(p)
        data = []
        for c, m, (idx, _) in zip(cams, models, obs):
            _, Jc, Jp = project_with_jacobian(c, pts[idx], m)
            data += [Jc.reshape(-1) / pixel_sigma, Jp.reshape(-1) / pixel_sigma]
        data.append(prior)
        if lengths is not None:
            d = pts[li] - pts[lj]
            u = d / np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None] * w_len[:, None]
            data.append(np.hstack([u, -u]).ravel())
        if stretch:
            data.append(np.c_[1.0 / unit, -ratio / unit].ravel())
        # a point beyond the lens's valid field has no derivative: no pull, not a NaN
        return csr_matrix((np.nan_to_num(np.concatenate(data), nan=0.0, posinf=0.0,
                                         neginf=0.0), (rows, cols)), shape=shape)

    solve = SchurSolver(off[-1], len(X), None if lengths is None else (li, lj))
    x = levenberg_marquardt(resid, jac, p0, f_scale=3.0, iterations=iterations, solve=solve)[0]
    cams = [from_vector(c, x[off[k]:off[k + 1]], m)
            for k, (c, m) in enumerate(zip(cameras, models))]
    return cams, x[off[-1]:].reshape(-1, 3)


def _redundancy(cameras, adjusted, obs, point_sigma, pixel_sigma, n_cam_params,
                measured=None):
    """How many of each group's residuals are free to show its noise (the redundancy
    numbers of a variance-component estimate): per point, the share of its position that its
    observations determine, tr(I_obs (I_prior + I_obs)⁻¹), with I_obs = Σ JᵀJ / σ_px² over the
    cameras that saw it and I_prior = diag(1 / σ_X²) (``point_sigma``: a scalar or N×3, ``inf``
    where nothing was measured); the cameras' own parameters come out of the pixels' share.
    Returns (r_points over the ``measured`` points, r_pixels)."""
    n = len(adjusted)
    info = np.zeros((n, 3, 3))
    n_px = 0
    for cam, (idx, _) in zip(cameras, obs):
        J = np.nan_to_num(cam.jacobian(adjusted[idx]))  # K×2×3
        np.add.at(info, idx, np.einsum("kai,kaj->kij", J, J) / pixel_sigma ** 2)
        n_px += 2 * len(idx)
    info = np.nan_to_num(info, nan=0.0, posinf=0.0, neginf=0.0)  # a point at a camera
    sig = np.broadcast_to(np.asarray(point_sigma, float), (n, 3))
    M = info + np.eye(3)[None] / sig[:, None, :] ** 2
    Minv = np.linalg.pinv(M)
    t = np.einsum("nij,nji->n", info, Minv)
    # a prior's own redundancy: its coordinates less their share, tr(I_prior M⁻¹) (3 − t
    # where all three were measured; an unmeasured coordinate has no prior to count)
    known = np.isfinite(sig)
    r_prior = known.sum(axis=1) - np.einsum("nii,ni->n", Minv, np.where(known, 1 / sig ** 2,
                                                                        0.0))
    mine = slice(None) if measured is None else measured
    return float(r_prior[mine].sum()), float(n_px - n_cam_params - t.sum())


def estimate_precision(cameras, X, obs, models, pixel_sigma: float, iterations: int = 5,
                       point_sigma: float | None = None, free=None,
                       fixed_height: float | None = None, unmeasured=None, lengths=None,
                       share=None, aspect=None):
    """The survey positions' measurement precision (m per axis) and the spots' (px), by
    variance components: refine jointly, compare each group's residuals with its redundancy,
    rescale, repeat. Bounded below by what the spots can resolve — a tenth of a point's
    spot-noise precision (distance / f · σ_px) — since finer position noise cannot be told from
    none. A stated ``point_sigma`` is kept and only the spots' precision estimated (weighting
    the spots by a scatter that includes the tape's would waste them).

    ``free`` (bool per point): positions nothing measured (a free survey's LED: ``X`` is only
    their start), at height ``fixed_height`` when one is stated (an LED on a robot).
    ``unmeasured`` (N×3 bool): coordinates of measured points that were not measured (a frame
    mark's empty cells). ``lengths``: as :func:`refine_jointly` takes them (a wand).
    ``share`` (N×3): each coordinate's precision as a multiple of the points' (a frame mark's
    coordinate set by definition: a small share); default 1. ``aspect``: as
    :func:`refine_jointly` takes it.
    Returns (point_sigma, pixel_sigma, cameras, adjusted)."""
    X = np.asarray(X, float)
    free = np.zeros(len(X), bool) if free is None else np.asarray(free, bool)
    measured = ~free
    npars = sum(6 + len(lens_params(m)) for m in models)
    per_px = np.median(np.concatenate([
        np.linalg.norm(c.to_camera(X[idx]), axis=1) / (0.5 * (c.fx + c.fy))
        for c, (idx, _) in zip(cameras, obs) if len(idx)]))  # m per px at the points
    floor = 0.1 * per_px * pixel_sigma
    s_px = pixel_sigma
    s_x = point_sigma if point_sigma is not None else max(per_px * pixel_sigma, floor)

    def sigmas(s_x):
        sig = np.full(X.shape, float(s_x)) * (1.0 if share is None else share)
        sig[free] = np.inf
        if unmeasured is not None:
            sig[unmeasured] = np.inf
        if fixed_height is not None:
            sig[free, 2] = 1e-3 * floor  # stated: as good as exact
        return sig

    cams, adj = cameras, X
    for _ in range(iterations):
        cams, adj = refine_jointly(cams, X, obs, point_sigma=sigmas(s_x), pixel_sigma=s_px,
                                   models=models, lengths=lengths, aspect=aspect)
        r_x, r_px = _redundancy(cams, adj, obs, sigmas(s_x), s_px, npars, measured)
        v_px = np.concatenate([(c.project(adj[idx])[0] - uv).ravel()
                               for c, (idx, uv) in zip(cams, obs)])
        # as robust as the fit's loss (a point past the lens's valid field: at the cap)
        v_px = np.clip(np.nan_to_num(v_px, nan=3 * s_px), -3 * s_px, 3 * s_px)
        known = np.isfinite(sigmas(s_x)) & measured[:, None]
        v_x = np.clip((adj - X)[known], -3 * s_x, 3 * s_x)
        new_px = float(np.sqrt(np.sum(v_px ** 2) / max(r_px, 1.0)))
        new_x = float(np.sqrt(np.sum(v_x ** 2) / max(r_x, 1e-9))) if r_x > 0.5 else s_x
        new_x = max(new_x, floor) if point_sigma is None else point_sigma
        done = abs(np.log(new_x / s_x)) < 0.05 and abs(np.log(new_px / s_px)) < 0.05
        s_x, s_px = new_x, max(new_px, 1e-6)
        floor = 0.1 * per_px * s_px
        if done:
            break
    return s_x, s_px, cams, adj


@dataclass
class Calibration:
    """The cameras fitted to a survey, and what the fit found."""

    cameras: list[Camera]
    fits: list[CameraFit]
    adjusted: np.ndarray  # N×3 survey positions after the joint refinement
    mismeasured: list  # (point id, how far the cameras put it from its record, m)
    lens: list = field(default_factory=list)  # LensChoice per camera
    point_sigma: float = float("nan")  # m per axis, as stated or estimated
    pixel_sigma: float = float("nan")  # px, the spots' estimated scatter
    point_sigma_estimated: bool = False
    #: the held-out 3D figures behind the lens models (:class:`~.lens_decision.LensDecision`),
    #: when they were decided or a forced model weighed
    decision: object = None

    @property
    def models(self) -> dict:
        return {f.camera.id: f.model for f in self.fits}


def fold_of(n: int, folds: int, seed: int = 0) -> np.ndarray:
    """Each of ``n`` points' fold (0 … folds − 1): a seeded shuffle cut into equal parts."""
    order = np.random.default_rng(seed).permutation(n)
    fold = np.empty(n, int)
    for f, part in enumerate(np.array_split(order, folds)):
        fold[part] = f
    return fold


def calibrate(nominal: list[Camera], X, uv, ids, intrinsics: bool = False,
              point_sigma: float | str = 0.003, outlier_px: float | None = None,
              lens: str | dict | None = None, folds: int = 5, seed: int = 0,
              starts: list[Camera] | None = None,
              pixel_sigma: float | None = None, progress=None) -> Calibration:
    """Calibrate every camera from the survey: ``X`` N×3 measured positions, ``uv`` C×N×2
    spots (NaN: not seen), ``ids`` the point ids.

    ``lens``: ``"auto"`` (each camera's model decided by the held-out 3D error over ``folds``
    folds, :mod:`.lens_decision`), one of :data:`~.lens.LENS_MODELS` for every camera, or
    camera id → model; default ``"full"`` with ``intrinsics`` else ``"pose"``. A forced model
    is fitted even where the survey determines it only weakly; a forced string is weighed by
    its held-out 3D error against the deployment's lens for the report (a dict, a fold's
    models, is not).
    ``starts``: a camera per camera to start each fit from (a fold of a calibration: the
    same minimum as the whole). ``point_sigma``: metres, or ``"auto"``
    (:func:`estimate_precision`); with it, ``pixel_sigma`` (px) stated too (a fold of a
    calibration: the whole survey's) leaves one joint fit to do. ``progress(i, n)`` counts the
    cameras whose lens models are weighed.

    Per camera, then jointly (:func:`refine_jointly`). A point rejected by two or more of the
    cameras that saw it is reported as mis-measured (a wrong tape reading moves it in every
    view), with how far from its record the calibrated cameras put it (NaN when fewer than two
    cameras saw it)."""
    X = np.asarray(X, float)
    uv = np.asarray(uv, float)
    if lens is None:
        lens = "full" if intrinsics else "pose"
    estimated = isinstance(point_sigma, str)
    if estimated and point_sigma != "auto":
        raise ValueError(f"point_sigma: expected metres or 'auto', got {point_sigma!r}")
    extent = float(np.linalg.norm(np.ptp(X, axis=0))) if len(X) else 0.0
    if not estimated and not (
            1e-9 * extent < float(point_sigma) <= SIGMA_SHARE * extent):
        units = slipped_units(float(point_sigma),
                              lambda m: 1e-9 * extent < m <= SIGMA_SHARE * extent)
        raise SurveyError(f"the stated precision of the survey positions, ±{point_sigma} m, is "
                          f"not between a billionth of the survey's extent ({extent:.3g} m) and "
                          f"a tenth of it: {units} (metres expected, or 'auto')")
    fits, obs, choices = [], [], []
    rejected: dict = {}
    decision = None
    for k, cam in enumerate(nominal):
        if not np.isfinite(uv[k]).all(axis=1).any():
            raise SurveyError(f"camera {cam.id}: saw none of the {len(X)} survey points "
                              "(check its frames, its id, or where it looks)")
    fold = fold_of(len(X), folds, seed)
    if lens == "auto" or (isinstance(lens, str) and lens != "pose"):
        asked = LENS_MODELS if lens == "auto" else ("pose", lens)
        decision = decide(nominal, X, uv, ids, fold, asked,
                          fixed=None if lens == "auto" else {c.id: lens for c in nominal},
                          progress=progress)
    for k, cam in enumerate(nominal):
        seen = np.flatnonzero(np.isfinite(uv[k]).all(axis=1))
        pid = [ids[i] for i in seen]
        if lens == "auto":
            model = decision.models[cam.id]
            fit = decision.fits[cam.id][model].fit
            choices.append(_decided_choice(decision, cam.id, fit, X[seen]))
        else:
            model = lens.get(cam.id, "pose") if isinstance(lens, dict) else lens
            while isinstance(lens, dict) and model != "pose" and len(seen) < min_points(model):
                # a fold of a calibration whose camera saw few points: the next simpler model,
                # as its choice would have been on this fold
                model = LENS_MODELS[LENS_MODELS.index(model) - 1]
            if decision is not None and model in decision.fits[cam.id]:
                fit = decision.fits[cam.id][model].fit
            else:
                fit = fit_camera(cam, X[seen], uv[k, seen], pid, model, outlier_px,
                                 start=None if starts is None else starts[k],
                                 starts=_model_starts(cam, X[seen], uv[k, seen], model)
                                 if starts is None else ())
            if isinstance(lens, str) and not fit.support.rcond > SINGULAR:
                # asked for, and no fit at all (as OpenCV's would not be)
                raise SurveyError(f"camera {cam.id}: cannot fit its lens ({model}): "
                                  f"{fit.support.reason}")
            choice = _decided_choice(decision, cam.id, fit, X[seen]) if decision else \
                _lens_choice(fit, cam.id, True, {}, X[seen])
            choice.forced = True
            choices.append(choice)
        fits.append(fit)
        for p in fit.outliers:
            rejected[p] = rejected.get(p, 0) + 1
        keep = seen[fit.keep]
        obs.append((keep, uv[k, keep]))
    for cam, fit in zip(nominal, fits):
        diag = float(np.hypot(cam.width, cam.height))
        if not fit.resid_px <= GARBAGE_IMAGE_SHARE * diag:
            raise SurveyError(f"camera {cam.id}: its spots fit no pose (scatter ±"
                              f"{fit.resid_px:.3g} px, {fit.resid_px / diag:.1%} of its image "
                              "diagonal): check its frames, its id, or what it sees")
    models = [f.model for f in fits]
    stated = None if estimated else float(point_sigma)
    rounds = 1 if pixel_sigma is not None and stated is not None else 5
    if pixel_sigma is None:
        pixel_sigma = float(np.sqrt(np.nanmean([f.resid_px ** 2 for f in fits])))
    pixel_sigma = float(np.fmax(pixel_sigma, 1e-6))
    point_sigma, pixel_sigma, cams, adjusted = estimate_precision(
        [f.camera for f in fits], X, obs, models, pixel_sigma, point_sigma=stated,
        iterations=rounds)
    seen_by = np.isfinite(uv).all(axis=2).sum(axis=0)
    suspects = [i for i, pid in enumerate(ids)
                if rejected.get(pid, 0) >= 2 or (rejected.get(pid, 0) >= 1 and seen_by[i] == 1)]
    # how far off the record is: where the calibrated cameras see the LED, against it

    where = triangulate(cams, uv[:, suspects]).X if suspects else np.zeros((0, 3))
    bad = [(ids[i], float(np.linalg.norm(w - X[i]))) for i, w in zip(suspects, where)]
    for k, (fit, cam) in enumerate(zip(fits, cams)):
        idx, uvk = obs[k]
        err = np.linalg.norm(cam.project(adjusted[idx])[0] - uvk, axis=1)
        fit.camera, fit.rms_px = cam, float(np.sqrt(np.mean(err ** 2))) if len(err) else 0.0
    return Calibration(cams, fits, adjusted, bad, choices, float(point_sigma),
                       float(pixel_sigma), estimated, decision)


def lens_sentence(choice: LensChoice, camera: Camera, nominal: Camera) -> str:
    """The lens decision for one camera in a surveyor's words, with the held-out figures
    behind it: the 3D error of held-out points where the choice was made by it, else the
    reprojection (px, and what that is at the camera's points); and what the survey pins only
    weakly, with what that costs the fixes."""
    cand = choice.candidates
    in_3d = any(c.get("held_out_3d_m") is not None for c in cand.values())

    def fig(model):
        if in_3d:
            m = cand.get(model, {}).get("held_out_3d_m")
            return None if m is None else format_length(m)
        px = cand.get(model, {}).get("held_out_px")
        if px is None:
            return None
        return f"{px:.2f} px ({format_length(px * choice.scene_per_px)} at its points)"

    what = "held-out 3D error" if in_3d else "held-out"
    cid, chosen = choice.camera_id, choice.chosen
    if choice.forced and choice.reason:
        return f"{cid}: lens model {chosen} ({LENS_WORDS[chosen]}): {choice.reason}"
    notes = ""
    if "cx" in lens_params(chosen) and not (-0.5 <= camera.cx <= camera.width - 0.5
                                            and -0.5 <= camera.cy <= camera.height - 0.5):
        notes += ("; its principal point lands outside the image: in a view this narrow it "
                  "trades against the camera's tilt, which is harmless for fixes inside the "
                  "surveyed volume but says nothing about the lens itself")
    if choice.weak:
        notes += f"; weakly determined: {choice.weak}"
        if in_3d and choice.forced and chosen != "pose" and fig(chosen) and fig("pose"):
            better = cand[chosen]["held_out_3d_m"] <= cand["pose"]["held_out_3d_m"]
            notes += (f" ({'harmless to' if better else 'it costs'} the fixes: {what} "
                      f"{fig(chosen)} with it, {fig('pose')} with the lens as in the "
                      "deployment" + ("" if better else "; the automatic choice avoids it")
                      + ")")
        elif in_3d:
            notes += ": chosen for what it does to the fixes, which the held-out 3D error counts"
    if choice.forced:
        return f"{cid}: lens model {chosen} as asked ({LENS_WORDS[chosen]}): " \
               f"{describe_lens(camera, nominal, chosen)}" + notes
    if chosen != "pose":
        said = (f"{what} {fig(chosen)} with every camera as chosen, {fig('pose')} with this "
                "one's lens as in the deployment" if in_3d else
                f"{what} {fig(chosen)} instead of {fig('pose')} with the lens as in the "
                "deployment")
        return f"{cid}: lens fitted ({describe_lens(camera, nominal, chosen)}): {said}" + notes
    tried = [m for m, c in cand.items() if c["supported"] and m != "pose" and fig(m)]
    if tried and fig("pose"):
        key = "held_out_3d_m" if in_3d else "held_out_px"
        best = min(tried, key=lambda m: cand[m][key])
        why = (f"fitting it did not clearly help: {what} {fig('pose')} as in the deployment, "
               f"{fig(best)} with {best}")
    else:
        why = "nothing richer could be fitted"
    refused = [m for m, c in cand.items() if not c["supported"]]
    if refused:
        why += f"; {refused[0]} not fitted: {cand[refused[0]]['reason']}"
    return f"{cid}: lens kept as in the deployment ({why})"


def format_length(m: float) -> str:
    """A length in the unit that suits it (the same scene at any scale reads naturally)."""
    a = abs(m)
    if a >= 1:
        return f"{m:.2f} m"
    if a >= 0.01:
        return f"{m * 100:.2f} cm"
    if a >= 1e-5:
        return f"{m * 1000:.3g} mm"
    return f"{m * 1e6:.3g} µm"
