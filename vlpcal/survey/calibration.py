"""Cameras fitted to a survey: each camera on its own, its lens model chosen by held-out error,
then every camera and every surveyed position together, with the survey's measurement
precision estimated from the fit when it is not stated.

Every decision is relative to the scene: outliers against the fit's own residual spread and
the image size, lens support against the survey's perspective (:mod:`.lens`), the positions'
precision against the spot noise. The same survey scaled by any factor calibrates the same.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..geometry import Camera
from .errors import SurveyError
from .lens import (
    LENS_MODELS,
    MIN_POINTS_POSE,
    Support,
    from_vector,
    lens_params,
    lens_support,
    min_points,
    project_with_jacobian,
    to_vector,
)

#: an observation further off than this many robust standard deviations is an outlier …
OUTLIER_SIGMAS = 5.0
#: … and never closer than this share of the image diagonal (a spot's own blur)
OUTLIER_IMAGE_SHARE = 0.005
#: a camera whose spots scatter about its best fit by more than this share of its image
#: diagonal is not seeing the LED (random spots, a wrong id)
GARBAGE_IMAGE_SHARE = 0.025


@dataclass
class CameraFit:
    """One camera's calibration: the camera, its reprojection RMS (px) and its outliers."""

    camera: Camera
    rms_px: float
    used: int
    outliers: list  # point ids whose spot was rejected for this camera
    model: str = "pose"
    resid_px: float = float("nan")  # robust standard deviation of a residual component
    support: Support | None = None
    keep: np.ndarray | None = field(default=None, repr=False)  # mask over the points given


def robust_sigma(r) -> float:
    """Standard deviation of residual components from their median absolute value."""
    r = np.asarray(r, float).ravel()
    r = r[np.isfinite(r)]
    return float(1.4826 * np.median(np.abs(r))) if len(r) else float("nan")


def _outlier_limit(cam: Camera, sigma: float) -> float:
    diag = float(np.hypot(cam.width, cam.height))
    return max(OUTLIER_SIGMAS * np.sqrt(2) * sigma, OUTLIER_IMAGE_SHARE * diag)


def _pnp_start(nominal: Camera, X, uv) -> Camera:
    """OpenCV's SQPnP on the nominal lens, unless it lands worse than the nominal pose."""
    from dataclasses import replace

    import cv2

    xy = nominal.normalise(uv)
    good = np.isfinite(xy).all(axis=1)
    if good.sum() < MIN_POINTS_POSE:
        return nominal
    try:
        ok, rvec, tvec = cv2.solvePnP(X[good].reshape(-1, 1, 3), xy[good].reshape(-1, 1, 2),
                                      np.eye(3), None, flags=cv2.SOLVEPNP_SQPNP)
    except cv2.error:  # degenerate points (all at one place): the fit below will say so
        return nominal
    if not ok or not np.isfinite(rvec).all():
        return nominal
    R = cv2.Rodrigues(rvec)[0]
    start = replace(nominal, rotation=rvec.ravel(), position=-R.T @ tvec.ravel())

    def med(c):
        e = np.linalg.norm(c.project(X)[0] - uv, axis=1)
        return np.median(np.where(np.isfinite(e), e, np.inf))
    return start if med(start) <= med(nominal) else nominal


def fit_camera(nominal: Camera, X, uv, ids, model: str = "pose", outlier_px: float | None = None,
               start: Camera | None = None, intrinsics: bool | None = None) -> CameraFit:
    """Pose (and the lens numbers ``model`` frees) of one camera from survey points it saw.

    Starts from OpenCV's SQPnP on the nominal lens (so a rough or tilted nominal guess does
    not matter) or from ``start``, then robust least squares on the reprojection error
    (soft-L1 at the fit's own scale); observations further off than ``outlier_px`` (default:
    :data:`OUTLIER_SIGMAS` robust standard deviations, at least
    :data:`OUTLIER_IMAGE_SHARE` of the image diagonal) are dropped and the fit repeated (a
    wrong spot, a mis-measured point), and reported by point id. ``intrinsics=True`` is
    ``model="full"``.
    """
    from scipy.optimize import least_squares

    if intrinsics is not None:
        model = "full" if intrinsics else model
    X = np.asarray(X, float)
    uv = np.asarray(uv, float)
    need = min_points(model)
    if len(X) < need:
        raise SurveyError(f"camera {nominal.id}: sees {len(X)} survey points, needs at least "
                          f"{need}" + (f" to fit its lens ({model})" if model != "pose" else ""))
    cam0 = start if start is not None else _pnp_start(nominal, X, uv)
    keep = np.ones(len(X), bool)
    scale = OUTLIER_IMAGE_SHARE * float(np.hypot(nominal.width, nominal.height))  # 1 px at 160 px

    def solve(c0, mask):
        Xm, uvm = X[mask], uv[mask]

        def resid(p):
            r = from_vector(nominal, p, model).project(Xm)[0] - uvm
            return np.nan_to_num(r, nan=1e3 * scale).ravel()

        def jac(p):
            J = project_with_jacobian(from_vector(nominal, p, model), Xm, model)[1]
            return J.reshape(2 * len(Xm), -1)

        sol = least_squares(resid, to_vector(c0, model), jac=jac, loss="soft_l1",
                            f_scale=scale, x_scale="jac", max_nfev=200)
        return from_vector(nominal, sol.x, model), sol

    cam, sol = solve(cam0, keep)
    for _ in range(4):
        err = np.linalg.norm(cam.project(X)[0] - uv, axis=1)
        sigma = robust_sigma(cam.project(X[keep])[0] - uv[keep])
        limit = outlier_px if outlier_px is not None else _outlier_limit(cam, sigma)
        new = err <= limit
        scale_new = max(sigma, 1e-6 * np.hypot(cam.width, cam.height))
        if new.sum() < need or (np.array_equal(new, keep) and scale_new >= scale / 2):
            break
        keep, scale = new, scale_new
        cam, sol = solve(cam, keep)
    r = cam.project(X[keep])[0] - uv[keep]
    sigma = robust_sigma(r)
    rms = float(np.sqrt(np.mean(np.sum(r ** 2, axis=1))))
    support = lens_support(cam, model, sol.jac, sigma, X[keep], uv[keep], nominal)
    return CameraFit(cam, rms, int(keep.sum()), [i for i, k in zip(ids, keep) if not k],
                     model, sigma, support, keep)


# -- the lens model, chosen by held-out error -----------------------------------------------

@dataclass
class LensChoice:
    """One camera's lens decision: the candidates' held-out figures and the one chosen."""

    camera_id: str
    chosen: str
    forced: bool
    #: model → {"held_out_px": RMS px or None, "supported": bool, "reason": str, and for the
    #: models compared "excess_px2" (mean squared error above the best model's, px²) and
    #: "se_px2" (its standard error): the simplest with excess ≤ se is chosen}
    candidates: dict
    depth_rel_range: float = float("nan")
    scene_per_px: float = float("nan")  # m per px at the camera's points (distance / f)
    #: why the model was set rather than chosen, when the survey (not the user) set it
    reason: str = ""


def _lens_choice(fit: CameraFit, camera_id: str, forced: bool, candidates: dict,
                 X) -> LensChoice:
    """The decision record of ``fit`` (on the points ``X`` it was given), with the scene's
    metres per pixel at the camera's points for the report's words."""
    cam = fit.camera
    depth = cam.to_camera(np.asarray(X, float)[fit.keep])[:, 2]
    return LensChoice(camera_id, fit.model, forced, candidates, fit.support.depth_rel_range,
                      float(np.median(depth) / (0.5 * (cam.fx + cam.fy))))


def _held_out_px(nominal, X, uv, model, fold, starts: dict):
    """Per point: reprojection error (px) when the point's fold was left out of the fit; and
    each fold's fitted camera. Each fold's fit starts from ``starts[fold]`` (the simpler
    model's fit on the same fold) or from PnP, never from a fit that saw its test points."""
    err = np.full(len(X), np.nan)
    cams = {}
    for f in np.unique(fold):
        test = fold == f
        try:
            fit = fit_camera(nominal, X[~test], uv[~test], [""] * int((~test).sum()), model,
                             start=starts.get(f))
        except SurveyError:
            return np.full(len(X), np.nan), {}
        cams[f] = fit.camera
        err[test] = np.linalg.norm(fit.camera.project(X[test])[0] - uv[test], axis=1)
    return err, cams


def choose_lens(nominal: Camera, X, uv, ids, fold, models=LENS_MODELS) -> tuple[CameraFit,
                                                                                LensChoice]:
    """Fit ``models`` (nested, simplest first) to one camera's points and choose by held-out
    reprojection error over the folds ``fold`` (N fold indices): the simplest model within one
    standard error of the best (paired over the points; errors capped at the outlier limit so
    that a wrong spot cannot decide). A model the survey does not determine
    (:func:`~.lens.lens_support`) is not a candidate, nor is any richer one.
    Returns the chosen model's full fit and the decision."""
    X = np.asarray(X, float)
    uv = np.asarray(uv, float)
    fits, errs, cand, fold_cams = {}, {}, {}, {}
    for model in models:
        if len(X) < min_points(model):
            cand[model] = {"held_out_px": None, "supported": False,
                           "reason": f"needs {min_points(model)} points, sees {len(X)}"}
            break
        fit = fit_camera(nominal, X, uv, ids, model,
                         start=fits[list(fits)[-1]].camera if fits else None)
        if not fit.support.ok:
            cand[model] = {"held_out_px": None, "supported": False,
                           "reason": fit.support.reason}
            break
        err, fold_cams = _held_out_px(nominal, X, uv, model, fold, fold_cams)
        if not np.isfinite(err).any():
            if model == "pose":
                fits[model] = fit
            cand[model] = {"held_out_px": None, "supported": False,
                           "reason": f"a held-out fold leaves fewer than {min_points(model)} "
                                     "points to fit it"}
            break
        fits[model], errs[model] = fit, err
    if not errs:  # not even the pose could be checked on held-out points: keep the pose
        fit = fits.get("pose") or fit_camera(nominal, X, uv, ids, "pose")
        cand.setdefault("pose", {"held_out_px": None, "supported": True, "reason": ""})
        return fit, _lens_choice(fit, nominal.id, False, cand, X)
    richest = fits[list(errs)[-1]]
    cap = _outlier_limit(richest.camera, richest.resid_px)
    loss = {m: np.fmin(e, cap) ** 2 for m, e in errs.items()}  # a failed prediction: the cap
    ok = np.logical_and.reduce([np.isfinite(v) for v in loss.values()])
    for m, v in loss.items():
        cand[m] = {"held_out_px": float(np.sqrt(np.mean(v[ok]))) if ok.any() else None,
                   "supported": True, "reason": ""}
    chosen = "pose"
    if ok.sum() > 1:
        best = min(loss, key=lambda m: loss[m][ok].mean())
        for m in loss:  # simplest first: the first within one standard error of the best
            d = loss[m][ok] - loss[best][ok]
            se = float(d.std(ddof=1) / np.sqrt(len(d)))
            cand[m]["excess_px2"], cand[m]["se_px2"] = float(d.mean()), se
        chosen = next(m for m in loss if cand[m]["excess_px2"] <= cand[m]["se_px2"])
    fit = fits[chosen]
    return fit, _lens_choice(fit, nominal.id, False, cand, X)


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
        from scipy.sparse import csr_matrix

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

    solve = _SchurSolver(off[-1], len(X), None if lengths is None else (li, lj))
    x = _sparse_levenberg_marquardt(resid, jac, p0, f_scale=3.0, iterations=iterations,
                                    solve=solve)
    cams = [from_vector(c, x[off[k]:off[k + 1]], m)
            for k, (c, m) in enumerate(zip(cameras, models))]
    return cams, x[off[-1]:].reshape(-1, 3)


class _SchurSolver:
    """Solve a bundle adjustment's damped normal equations by the Schur complement: the
    points' blocks (3 × 3, or 6 × 6 for two points held a length apart, in general one block
    per group of linked points) are inverted in one batch and eliminated, leaving a dense
    system in the cameras' few parameters (Triggs et al., "Bundle adjustment — a modern
    synthesis", §6.1). ``n_cam``: camera parameters first, then ``n_pts`` × 3 coordinates;
    ``pairs``: index arrays of linked points. Returns None where a block is singular (the
    caller falls back to a general sparse solve)."""

    def __init__(self, n_cam: int, n_pts: int, pairs=None):
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        self.n_cam = n_cam
        if pairs is not None and len(pairs[0]):
            i, j = pairs
            g = coo_matrix((np.ones(len(i)), (i, j)), shape=(n_pts, n_pts))
            _, comp = connected_components(g, directed=False)
        else:
            comp = np.arange(n_pts)
        order = np.argsort(comp, kind="stable")  # points grouped by their block
        c_sorted = comp[order]
        starts = np.flatnonzero(np.r_[True, c_sorted[1:] != c_sorted[:-1]])
        sizes = np.diff(np.r_[starts, n_pts])
        rank = np.empty(n_pts, int)
        rank[order] = np.arange(n_pts) - np.repeat(starts, sizes)
        block_of = np.empty(n_pts, int)
        block_of[order] = np.repeat(np.arange(len(starts)), sizes)
        self.block = np.repeat(block_of, 3)  # per coordinate: its block,
        self.local = (3 * rank[:, None] + np.arange(3)).ravel()  # and its place in it
        self.size = 3 * sizes  # per block
        # per block size: the blocks of that size and their coordinates (B × s, global)
        self.groups = []
        for sz in np.unique(self.size):
            blocks = np.flatnonzero(self.size == sz)
            coords = np.zeros((len(blocks), sz), int)
            where = np.full(len(starts), -1)
            where[blocks] = np.arange(len(blocks))
            q = np.flatnonzero(where[self.block] >= 0)
            coords[where[self.block[q]], self.local[q]] = q
            self.groups.append((sz, blocks, coords, where))

    def __call__(self, A, g, damping):
        """``step`` solving ``(A + diag(damping)) step = -g`` (``A``: CSC), or None."""
        from scipy.sparse import coo_matrix

        nc = self.n_cam
        A = A.tocsr()
        U = A[:nc, :nc].toarray() + np.diag(damping[:nc])
        W = A[:nc, nc:]
        V = A[nc:, nc:].tocoo()
        dp = damping[nc:]
        keep = self.block[V.row] == self.block[V.col]
        r, c, v = V.row[keep], V.col[keep], V.data[keep]
        rows, cols, vals = [], [], []
        for sz, blocks, coords, where in self.groups:
            mine = where[self.block[r]] >= 0
            B = np.zeros((len(blocks), sz, sz))
            np.add.at(B, (where[self.block[r[mine]]], self.local[r[mine]],
                          self.local[c[mine]]), v[mine])
            B[:, np.arange(sz), np.arange(sz)] += dp[coords]
            try:
                Binv = np.linalg.inv(B)
            except np.linalg.LinAlgError:
                return None
            rows.append(np.repeat(coords, sz, axis=1).ravel())
            cols.append(np.tile(coords, (1, sz)).ravel())
            vals.append(Binv.ravel())
        n = A.shape[0] - nc
        Vinv = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(n, n)).tocsr()
        WV = W @ Vinv
        S = U - (WV @ W.T).toarray()
        gc, gp = g[:nc], g[nc:]
        try:
            dc = np.linalg.solve(S, -(gc - WV @ gp))
        except np.linalg.LinAlgError:
            return None
        step = np.r_[dc, Vinv @ (-gp - W.T @ dc)]
        return step if np.isfinite(step).all() else None


def _sparse_levenberg_marquardt(resid, jac, p0, f_scale: float, iterations: int = 60,
                                solve=None):
    """Minimise the soft-L1 cost of ``resid`` (scale ``f_scale``) from ``p0``: Levenberg–
    Marquardt on the sparse normal equations, reweighted at each step (the robust loss's
    weights ρ′). ``solve(A, g, damping)``: a solver that knows the problem's structure
    (:class:`_SchurSolver`), else (or where it returns None) a general direct sparse solve."""
    from scipy.sparse import diags
    from scipy.sparse.linalg import spsolve

    def cost_of(r):
        z = (r / f_scale) ** 2
        return f_scale ** 2 * np.sum(np.sqrt(1 + z) - 1)

    p = np.asarray(p0, float).copy()
    r = resid(p)
    cost = cost_of(r)
    lam = 1e-3
    for _ in range(iterations):
        J = jac(p)
        w = 1.0 / np.sqrt(1 + (r / f_scale) ** 2)
        A = (J.T @ diags(w) @ J).tocsc()
        g = J.T @ (w * r)
        d = A.diagonal()
        d = np.where(d > 0, d, 1.0)
        while True:
            step = solve(A, g, lam * d) if solve is not None else None
            if step is None:
                step = spsolve((A + diags(lam * d)).tocsc(), -g)
            trial = p + step
            r_new = resid(trial)
            new = cost_of(r_new)
            if np.isfinite(new) and new <= cost:
                break
            lam *= 4
            if lam > 1e12:
                return p
        small = cost - new <= 1e-10 * max(cost, 1e-300)
        p, r, cost = trial, r_new, new
        lam = max(lam / 3, 1e-9)
        if small:
            break
    return p


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


def _references(cams, X, uv, obs, point_sigma: float, pixel_sigma: float) -> list:
    """Per camera, the survey positions as the *other* cameras see them: each point
    triangulated from the other cameras' kept spots, averaged with its measured position by
    their precisions (the triangulation's predicted error, the survey's ``point_sigma``), the
    measured position alone where fewer than two others saw it. A lens judged against these
    is judged below the tape's noise, without its own spots in the reference."""
    from ..triangulation import predicted_rms_error, triangulate

    clean = np.full_like(uv, np.nan)
    for k, (idx, uvk) in enumerate(obs):
        clean[k, idx] = uvk
    w_m = 1.0 / (3 * point_sigma ** 2)
    refs = []
    for k in range(len(cams)):
        others = clean.copy()
        others[k] = np.nan
        tri = triangulate(cams, others)
        ok = np.isfinite(tri.X).all(axis=1) & (tri.used.sum(axis=0) >= 2)
        R = X.copy()
        if ok.any():
            sig = predicted_rms_error(cams, np.where(ok[:, None], tri.X, X), tri.used & ok,
                                      pixel_sigma)
            good = ok & np.isfinite(sig) & (sig > 0)
            w_t = np.where(good, 1.0 / np.where(good, sig, 1.0) ** 2, 0.0)
            R = np.where(good[:, None], (w_t[:, None] * np.nan_to_num(tri.X) + w_m * X)
                         / (w_t + w_m)[:, None], X)
        refs.append(R)
    return refs


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
              lens: str | dict | None = None, folds: int = 5, seed: int = 0) -> Calibration:
    """Calibrate every camera from the survey: ``X`` N×3 measured positions, ``uv`` C×N×2
    spots (NaN: not seen), ``ids`` the point ids.

    ``lens``: ``"auto"`` (each camera's model chosen by :func:`choose_lens` over ``folds``
    folds), one of :data:`~.lens.LENS_MODELS` for every camera, or camera id → model; default
    ``"full"`` with ``intrinsics`` else ``"pose"``. A forced model the survey does not determine
    is refused. ``point_sigma``: metres, or ``"auto"`` (:func:`estimate_precision`).

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
            1e-9 * extent < float(point_sigma) < extent):
        raise SurveyError(f"the stated precision of the survey positions, ±{point_sigma} m, is "
                          f"not between a billionth of the survey's extent ({extent:.3g} m) and "
                          "the extent itself: metres expected (or 'auto')")
    fits, obs, choices = [], [], []
    rejected: dict = {}
    for k, cam in enumerate(nominal):
        seen = np.flatnonzero(np.isfinite(uv[k]).all(axis=1))
        if not len(seen):
            raise SurveyError(f"camera {cam.id}: saw none of the {len(X)} survey points "
                              "(check its frames, its id, or where it looks)")
        pid = [ids[i] for i in seen]
        if lens == "auto":
            if len(seen) < min_points("pose"):
                raise SurveyError(f"camera {cam.id}: sees {len(seen)} survey points, needs at "
                                  f"least {min_points('pose')}")
            fit, choice = choose_lens(cam, X[seen], uv[k, seen], pid, fold_of(len(seen), folds,
                                                                              seed))
            choices.append(choice)
        else:
            model = lens.get(cam.id, "pose") if isinstance(lens, dict) else lens
            fit = fit_camera(cam, X[seen], uv[k, seen], pid, model, outlier_px)
            while isinstance(lens, dict) and model != "pose" and not fit.support.ok:
                # a fold of an automatic choice: the next simpler model, as the choice would
                model = LENS_MODELS[LENS_MODELS.index(model) - 1]
                fit = fit_camera(cam, X[seen], uv[k, seen], pid, model, outlier_px)
            if not fit.support.ok:
                raise SurveyError(f"camera {cam.id}: cannot fit its lens ({model}): "
                                  f"{fit.support.reason} (or let --lens auto decide)")
            choices.append(_lens_choice(fit, cam.id, True, {}, X[seen]))
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
    pixel_sigma = float(np.sqrt(np.nanmean([f.resid_px ** 2 for f in fits])))
    pixel_sigma = float(np.fmax(pixel_sigma, 1e-6))
    stated = None if estimated else float(point_sigma)
    point_sigma, pixel_sigma, cams, adjusted = estimate_precision(
        [f.camera for f in fits], X, obs, models, pixel_sigma, point_sigma=stated)
    if lens == "auto" and len(nominal) >= 3:
        # again, against references free of the tape: where the other cameras see each point
        refs = _references(cams, X, uv, obs, point_sigma, pixel_sigma)
        choices, starts = [], []
        for k, cam in enumerate(nominal):
            seen = np.flatnonzero(np.isfinite(uv[k]).all(axis=1))
            fit2, choice = choose_lens(cam, refs[k][seen], uv[k, seen], [ids[i] for i in seen],
                                       fold_of(len(seen), folds, seed))
            choices.append(choice)
            fits[k].model, fits[k].support = fit2.model, fit2.support
            starts.append(fit2.camera)
        models = [f.model for f in fits]
        point_sigma, pixel_sigma, cams, adjusted = estimate_precision(
            starts, X, obs, models, pixel_sigma, point_sigma=stated)
    seen_by = np.isfinite(uv).all(axis=2).sum(axis=0)
    suspects = [i for i, pid in enumerate(ids)
                if rejected.get(pid, 0) >= 2 or (rejected.get(pid, 0) >= 1 and seen_by[i] == 1)]
    # how far off the record is: where the calibrated cameras see the LED, against it
    from ..triangulation import triangulate

    where = triangulate(cams, uv[:, suspects]).X if suspects else np.zeros((0, 3))
    bad = [(ids[i], float(np.linalg.norm(w - X[i]))) for i, w in zip(suspects, where)]
    for k, (fit, cam) in enumerate(zip(fits, cams)):
        idx, uvk = obs[k]
        err = np.linalg.norm(cam.project(adjusted[idx])[0] - uvk, axis=1)
        fit.camera, fit.rms_px = cam, float(np.sqrt(np.mean(err ** 2))) if len(err) else 0.0
    return Calibration(cams, fits, adjusted, bad, choices, float(point_sigma),
                       float(pixel_sigma), estimated)


def lens_sentence(choice: LensChoice, camera: Camera, nominal: Camera) -> str:
    """The lens decision for one camera in a surveyor's words, with the held-out figures
    behind it (px, and what that is at the camera's points)."""
    from .lens import LENS_WORDS, describe_lens

    def fig(model):
        px = choice.candidates.get(model, {}).get("held_out_px")
        if px is None:
            return None
        return f"{px:.2f} px ({format_length(px * choice.scene_per_px)} at its points)"

    cid, chosen = choice.camera_id, choice.chosen
    if choice.forced and choice.reason:
        return f"{cid}: lens model {chosen} ({LENS_WORDS[chosen]}): {choice.reason}"
    if choice.forced:
        return f"{cid}: lens model {chosen} as asked ({LENS_WORDS[chosen]}): " \
               f"{describe_lens(camera, nominal, chosen)}"
    if chosen != "pose":
        off = ""
        if "cx" in lens_params(chosen) and not (-0.5 <= camera.cx <= camera.width - 0.5
                                                and -0.5 <= camera.cy <= camera.height - 0.5):
            off = ("; its principal point lands outside the image: in a view this narrow it "
                   "trades against the camera's tilt, which is harmless for fixes inside the "
                   "surveyed volume but says nothing about the lens itself")
        return (f"{cid}: lens fitted ({describe_lens(camera, nominal, chosen)}): held-out "
                f"{fig(chosen)} instead of {fig('pose')} with the lens as in the deployment"
                + off)
    refused = [m for m, c in choice.candidates.items() if not c["supported"]]
    tried = [m for m, c in choice.candidates.items() if c["supported"] and m != "pose"
             and c["held_out_px"] is not None]
    if tried and fig("pose"):
        best = min(tried, key=lambda m: choice.candidates[m]["held_out_px"])
        why = (f"fitting it did not clearly help: held-out {fig('pose')} as in the deployment, "
               f"{fig(best)} with {best}")
    else:
        why = "nothing richer could be fitted"
    if refused:
        why += f"; {refused[0]} not fitted: {choice.candidates[refused[0]]['reason']}"
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
