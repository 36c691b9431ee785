"""Every camera's lens model, decided by what it does to the fixes.

Each nested model (:data:`~.lens.LENS_MODELS`) is fitted to each camera on all but one fold of
the survey points; the left-out fold is triangulated with every camera's fit and compared with
its measured positions. The models kept are those that put held-out points closest in 3D: a
focal length that trades against the distance along the view costs the fixes nothing and is
not refused for its own uncertainty. Where two choices fix the points equally well (within one
standard error, paired over the points), the camera's held-out reprojection error decides, the
simplest model within one standard error of the best.

Plain OpenCV (``calibrateCamera`` with its full lens from the deployment's lens, per camera)
is fitted on the same folds as the baseline: a choice whose held-out 3D error is worse than
OpenCV's is not kept while a better one exists, and OpenCV's fit is among the starts of every
model that frees the principal point, with a few more principal-point starts where the fit has
several minima (:func:`data_starts`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..deployment import DeploymentError, check_intrinsics
from ..geometry import Camera
from ..triangulation import triangulate
from .camera_fit import fit_camera
from .errors import SurveyError
from .lens import LENS_MODELS, SINGULAR, lens_params, min_points

#: principal-point starts: a grid of this many per image axis over the image's central half
#: (OpenCV from each; the lowest cost is kept)
PRINCIPAL_STARTS = 3
#: a failed or wild prediction counts as this many times the typical held-out error, so that
#: one diverged fold cannot outweigh every other point
ERROR_CAP = 10.0
#: rounds of the camera-by-camera search
ROUNDS = 3
#: two starts reached different minima when their principal points lie further apart than
#: this share of the image diagonal
OTHER_MINIMUM_SHARE = 0.01


@dataclass
class ModelFit:
    """One camera under one lens model: the fit on every point and each fold's camera."""

    fit: object  #: :class:`~.calibration.CameraFit` on all the camera's points
    folds: dict  #: fold → Camera fitted without that fold
    reprojection_px: np.ndarray  #: N: held-out reprojection error per point (NaN: not seen)


@dataclass
class LensDecision:
    """The models chosen and the held-out 3D figures behind them (m, means over points seen
    by two or more cameras; an error past :data:`ERROR_CAP` typical errors counts at it)."""

    models: dict  #: camera id → chosen model
    held_out_m: float  #: the choice
    opencv_m: float  #: plain OpenCV per camera, full lens, on the same folds
    uniform_m: dict  #: model → every camera with that model
    #: camera id → model → the choice with only that camera's model changed
    per_camera_m: dict = field(default_factory=dict)
    points: int = 0  #: held-out points that count (seen by two or more cameras)
    fits: dict = field(default_factory=dict, repr=False)  #: camera id → model → ModelFit
    #: camera id → :class:`StartsDisagree`, where its chosen model's starts reached different
    #: minima
    starts_disagree: dict = field(default_factory=dict)
    cap_m: float = float("inf")  #: where a failed or wild prediction counts (m)
    opencv_capped: int = 0  #: points plain OpenCV could not fit or put past the cap


@dataclass
class StartsDisagree:
    """Two minima of one camera's fit: from the simpler model's fit (or PnP) and the best of
    the data's starts; the lower cost is kept."""

    model: str
    chained: tuple  #: (cx, cy) px from the simpler model's fit
    best: tuple  #: (cx, cy) px of the lowest cost
    cost_ratio: float  #: the chained start's cost over the best's


def opencv_camera(nominal: Camera, X, uv, principal=None) -> Camera | None:
    """Plain OpenCV: ``calibrateCamera`` on one camera's points with the full 5-term lens,
    from the deployment's lens (``CALIB_USE_INTRINSIC_GUESS``, as a non-planar target needs)
    or with the principal point at ``principal``; None where OpenCV refuses."""
    return _opencv_fit(nominal, X, uv, principal)[0]


def _opencv_fit(nominal: Camera, X, uv, principal=None) -> tuple[Camera | None, float]:
    """:func:`opencv_camera` and OpenCV's own reprojection RMS (px; inf where it refused)."""
    import cv2  # (OpenCV: loaded by a fit only)

    X = np.asarray(X, float)
    uv = np.asarray(uv, float)
    K = nominal.K.copy()
    if principal is not None:
        K[0, 2], K[1, 2] = principal
    try:
        rms, K, d, rv, tv = cv2.calibrateCamera(
            [X.astype(np.float32)], [uv.astype(np.float32)], (nominal.width, nominal.height),
            K, np.zeros(5), flags=cv2.CALIB_USE_INTRINSIC_GUESS)
    except cv2.error:
        return None, np.inf
    R = cv2.Rodrigues(rv[0])[0]
    cam = Camera(nominal.id, nominal.width, nominal.height, K[0, 0], K[1, 1], K[0, 2], K[1, 2],
                 tuple(d.ravel()[:5]), -R.T @ tv[0].ravel(), rv[0].ravel())
    ok = np.isfinite([cam.fx, cam.fy, cam.cx, cam.cy, *cam.dist]).all() and cam.fx > 0 \
        and cam.fy > 0
    return (cam, float(rms)) if ok else (None, np.inf)


def data_starts(nominal: Camera, X, uv) -> list[Camera]:
    """Starts for a fit that frees the lens, from the data alone: OpenCV from the
    deployment's lens and from :data:`PRINCIPAL_STARTS`² principal points over the image's
    central half (a narrow view's principal point has several minima), the lowest of those
    by OpenCV's own cost."""
    grid = [(nominal.width * a, nominal.height * b)
            for a in np.linspace(0.25, 0.75, PRINCIPAL_STARTS)
            for b in np.linspace(0.25, 0.75, PRINCIPAL_STARTS)]
    best = min((_opencv_fit(nominal, X, uv, pp) for pp in grid), key=lambda fit: fit[1])[0]
    return [c for c in (opencv_camera(nominal, X, uv), best) if c is not None]


def as_start(cam: Camera, nominal: Camera, model: str) -> Camera:
    """``cam`` with only the lens numbers ``model`` frees: the rest as in the deployment."""
    free = lens_params(model)
    dist = [d if name in free else n for name, d, n in
            zip(("k1", "k2", "p1", "p2", "k3"), cam.dist, nominal.dist)]
    kw = {name: getattr(cam if name in free else nominal, name)
          for name in ("fx", "fy", "cx", "cy")}
    return replace(cam, dist=tuple(dist), **kw)


def holdable(cam: Camera) -> bool:
    """Whether a deployment file can hold ``cam``'s lens (a principal point within one image
    of the image, distortion terms a lens can have): a narrow view's fit can wander past
    them, trading the principal point against the camera's tilt."""
    try:
        check_intrinsics(cam.to_dict(), cam.id)
    except DeploymentError:
        return False
    return True


def fit_models(nominal: Camera, X, uv, ids, fold, models=LENS_MODELS) -> dict:
    """``models`` (nested, simplest first) fitted to one camera's points ``X``/``uv``: each
    on all of them (from the simpler model's fit and, where the model frees the principal
    point, from :func:`data_starts` on the spots the first fit kept) and on each fold's
    complement (from the fit on all: the same minimum, found without the fold). Returns
    model → :class:`ModelFit`; a model the points cannot fit (too few, or a singular fit)
    is absent, and so is every richer one; so is a fit no deployment can hold
    (:func:`holdable`)."""
    out: dict = {}
    prev, starts = None, None  # the simpler model's fit, the data's starts
    for model in models:
        if len(X) < min_points(model):
            break
        if starts is None and "cx" in lens_params(model):
            kept = prev.keep if prev is not None else slice(None)
            starts = data_starts(nominal, X[kept], uv[kept])  # a wrong spot would mislead
        extra = tuple(as_start(s, nominal, model) for s in starts) \
            if "cx" in lens_params(model) else ()
        try:
            fit = fit_camera(nominal, X, uv, ids, model, starts=extra,
                             start=None if prev is None else prev.camera)
        except SurveyError:
            break
        if not fit.support.rcond > SINGULAR:  # the points cannot separate lens and pose
            break
        if not holdable(fit.camera):
            continue
        folds, err = {}, np.full(len(X), np.nan)
        for f in np.unique(fold):
            test = fold == f
            if (~test).sum() < min_points(model):
                continue
            try:
                cam = fit_camera(nominal, X[~test], uv[~test], [""] * int((~test).sum()),
                                 model, start=fit.camera).camera
            except SurveyError:
                continue
            folds[f] = cam
            err[test] = np.linalg.norm(cam.project(X[test])[0] - uv[test], axis=1)
        out[model] = ModelFit(fit, folds, err)
        prev = fit
    return out


def _opencv_folds(nominal: Camera, X, uv, fold) -> dict:
    """Plain OpenCV's camera on each fold's complement (fold → Camera or None)."""
    return {f: opencv_camera(nominal, X[fold != f], uv[fold != f]) for f in np.unique(fold)}


#: a choice that could not be fitted on a fold (see :meth:`_HeldOut.errors`)
FAILED = "failed"
#: plain OpenCV's fit, judged beside the models
OPENCV = "opencv"


class _HeldOut:
    """Per-point held-out 3D errors of any assignment of fold cameras (C × folds)."""

    def __init__(self, X, uv, fold):
        self._tri = triangulate
        self.X, self.uv, self.fold = X, uv, fold
        self.counted = np.isfinite(uv).all(axis=2).sum(axis=0) >= 2
        self.cap = np.inf

    def errors(self, cams_of) -> np.ndarray:
        """``cams_of(f)``: the C cameras of fold f: a Camera, :data:`FAILED` where this
        choice could not be fitted there (the points it saw count as failed), or None where
        no choice could (a camera too thin on that fold: left out, as for every choice)."""
        err = np.full(len(self.X), np.nan)
        for f in np.unique(self.fold):
            test = np.flatnonzero((self.fold == f) & self.counted)
            cams = cams_of(f)
            if not len(test):
                continue
            have = [k for k, c in enumerate(cams) if isinstance(c, Camera)]
            if len(have) >= 2:
                Xh = self._tri([cams[k] for k in have], self.uv[have][:, test]).X
                err[test] = np.linalg.norm(Xh - self.X[test], axis=1)
            failed = [k for k, c in enumerate(cams) if c is FAILED]
            if failed:
                err[test[np.isfinite(self.uv[failed][:, test]).all(axis=2).any(axis=0)]] = np.inf
        err = np.where(self.counted, np.nan_to_num(err, nan=np.inf), np.nan)
        return np.fmin(err, self.cap)

    def mean(self, err) -> float:
        e = err[self.counted]
        return float(e.mean()) if len(e) else float("nan")


def decide(nominal: list[Camera], X, uv, ids, fold, models=LENS_MODELS, progress=None,
           fixed: dict | None = None) -> LensDecision:
    """Choose every camera's model (module docstring): ``X`` N×3 measured positions, ``uv``
    C×N×2 spots (NaN: not seen), ``fold`` N fold indices. ``progress(i, n)`` counts cameras.
    ``fixed`` (camera id → model, a model the user set): no choice, only its figures and
    each camera's alternatives beside it."""
    X = np.asarray(X, float)
    uv = np.asarray(uv, float)
    C = len(nominal)
    fits, opencv = {}, {}
    clean = uv.copy()  # the spots each camera's first fit kept: a wrong one judges no lens
    for k, cam in enumerate(nominal):
        seen = np.flatnonzero(np.isfinite(uv[k]).all(axis=1))
        per = fit_models(cam, X[seen], uv[k, seen], [ids[i] for i in seen], fold[seen],
                         models)
        if not per:
            raise SurveyError(f"camera {cam.id}: sees {len(seen)} survey points, needs at "
                              f"least {min_points('pose')}")
        for mf in per.values():  # per point of the survey, not of the camera
            full = np.full(len(X), np.nan)
            full[seen] = mf.reprojection_px
            mf.reprojection_px = full
        fits[cam.id] = per
        clean[k, seen[~next(iter(per.values())).fit.keep]] = np.nan
        opencv[cam.id] = _opencv_folds(cam, X[seen], uv[k, seen], fold[seen])
        if progress:
            progress(k + 1, C)
    held = _HeldOut(X, clean, fold)
    ids_c = [c.id for c in nominal]

    def fold_camera(c, model, f):
        found = fits[c][model].folds.get(f) if model in fits[c] else opencv[c].get(f)
        if found is not None:
            return found
        return FAILED if any(f in mf.folds for mf in fits[c].values()) else None

    def errors(assign):
        return held.errors(lambda f: [fold_camera(c, assign[c], f) for c in ids_c])

    uniform = {m: errors({c: m if m in fits[c] else list(fits[c])[-1] for c in ids_c})
               for m in models}
    typical = [np.nanmedian(e[held.counted]) for e in uniform.values() if held.counted.any()]
    held.cap = ERROR_CAP * min(typical) if typical and np.isfinite(min(typical)) else np.inf
    uniform = {m: np.fmin(e, held.cap) for m, e in uniform.items()}
    e_cv = held.errors(lambda f: [fold_camera(c, OPENCV, f) for c in ids_c])
    assign = {c: min(models, key=lambda m: held.mean(uniform[m])
                     if all(m in fits[d] for d in ids_c) else np.inf) for c in ids_c}
    assign = {c: m if m in fits[c] else list(fits[c])[-1] for c, m in assign.items()}
    if fixed is not None:
        assign = {c: m if m in fits[c] else list(fits[c])[-1] for c, m in fixed.items()}
    seen_best = (held.mean(errors(assign)), dict(assign))
    per_camera: dict = {}
    for _ in range(1 if fixed is not None else ROUNDS):
        changed = False
        for c in ids_c:
            options = {m: errors({**assign, c: m}) for m in fits[c]}
            pick = _pick(options, {m: fits[c][m].reprojection_px for m in options}, held)
            per_camera[c] = {m: held.mean(e) for m, e in options.items()}
            for m, e in options.items():
                if held.mean(e) < seen_best[0]:
                    seen_best = (held.mean(e), {**assign, c: m})
            if fixed is None:
                changed |= pick != assign[c]
                assign[c] = pick
        if not changed:
            break
    chosen = held.mean(errors(assign))
    if fixed is None and np.isfinite(held.mean(e_cv)) and chosen > held.mean(e_cv) \
            and seen_best[0] < chosen:
        assign, chosen = seen_best[1], seen_best[0]
    disagree = {c: d for c in ids_c if (d := _disagreement(fits[c][assign[c]].fit)) is not None}
    return LensDecision(assign, chosen, held.mean(e_cv),
                        {m: held.mean(e) for m, e in uniform.items()}, per_camera,
                        int(held.counted.sum()), fits, disagree, float(held.cap),
                        int((e_cv[held.counted] >= held.cap).sum()))


def _disagreement(fit) -> StartsDisagree | None:
    """Whether ``fit``'s starts reached different minima (principal points further apart
    than :data:`OTHER_MINIMUM_SHARE` of the image diagonal)."""
    if len(fit.minima) < 2:
        return None
    chained, cost0 = fit.minima[0]
    best, cost = min(fit.minima, key=lambda m: m[1])
    diag = float(np.hypot(best.width, best.height))
    if np.hypot(best.cx - chained.cx, best.cy - chained.cy) <= OTHER_MINIMUM_SHARE * diag:
        return None
    return StartsDisagree(fit.model, (chained.cx, chained.cy), (best.cx, best.cy),
                          float(cost0 / cost) if cost > 0 else float("inf"))


def _pick(options: dict, reprojection: dict, held: _HeldOut) -> str:
    """The model whose held-out 3D errors are lowest; among those within one standard error
    of it (paired over the points), the simplest within one standard error of the lowest
    held-out reprojection."""
    means = {m: held.mean(e) for m, e in options.items()}
    finite = {m: v for m, v in means.items() if np.isfinite(v)}
    if finite:
        best = min(finite, key=finite.get)
        ties = [m for m in finite if _within_se(options[m], options[best], held.counted)]
    else:  # nothing triangulated: the reprojection alone
        ties = list(options)
    loss = {m: reprojection[m] ** 2 for m in ties}
    ok = np.logical_and.reduce([np.isfinite(v) for v in loss.values()])
    if ok.sum() < 2:
        return min(ties, key=lambda m: means.get(m, np.inf)) if finite else ties[0]
    best_r = min(loss, key=lambda m: loss[m][ok].mean())
    return next(m for m in ties if _within_se(loss[m], loss[best_r], ok))


def _within_se(a, b, mask) -> bool:
    """Whether the mean of ``a − b`` over ``mask`` is within one standard error of zero."""
    d = (a - b)[mask]
    d = d[np.isfinite(d)]
    if len(d) < 2:
        return True
    return float(d.mean()) <= float(d.std(ddof=1) / np.sqrt(len(d)))
