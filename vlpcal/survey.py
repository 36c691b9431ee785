"""Survey layer: what measured LED positions teach about an install.

Calibrating cameras from a survey (each camera's pose, optionally its lens, then a joint
refinement that lets each surveyed position move within its tape-measure uncertainty), and
learning the paper's approach (c) — for each floor region, the camera pair that was most
accurate there on the survey (section 3.3 (c): "we select the pair known to perform better
within the specific regions ... based on prior knowledge and experimental data").
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .fusion import RegionMap, pair_estimates
from .geometry import Camera


def learn_region_map(cameras: list[Camera], uv, X, room, cell: float = 0.3,
                     pair_method: str = "paper", min_points: int = 1) -> RegionMap:
    """Square cells of ``cell`` m over the room's bounding box, each naming the camera pair
    with the lowest mean 3D error on the survey points (``X`` N×3 measured, ``uv`` C×N×2) that
    fall in it. Cells with fewer than ``min_points`` usable points are left out (the fusion
    falls back to the nearest pair there).
    """
    from shapely.geometry import Polygon, box

    X = np.asarray(X, float)
    pairs, Xp = pair_estimates(cameras, uv, pair_method)
    err = np.linalg.norm(Xp - X[None], axis=2)  # P×N, NaN where the pair has no estimate
    room_poly = Polygon(room)
    x0, y0, x1, y1 = room_poly.bounds
    ix = np.floor((X[:, 0] - x0) / cell).astype(int)
    iy = np.floor((X[:, 1] - y0) / cell).astype(int)
    regions = []
    for cx, cy in sorted(set(zip(ix.tolist(), iy.tolist()))):
        inside = (ix == cx) & (iy == cy)
        e = err[:, inside]
        usable = np.isfinite(e).sum(axis=1)
        if usable.max() < min_points:
            continue
        total = np.where(np.isfinite(e), e, 0.0).sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(usable >= min_points, total / usable, np.inf)
        best = int(np.argmin(mean))
        square = box(x0 + cx * cell, y0 + cy * cell, x0 + (cx + 1) * cell, y0 + (cy + 1) * cell)
        poly = square.intersection(room_poly)
        if poly.is_empty or poly.geom_type != "Polygon":
            continue
        regions.append((poly, (cameras[pairs[best][0]].id, cameras[pairs[best][1]].id)))
    return RegionMap(regions)


# -- camera calibration from a survey --------------------------------------------------------

class SurveyError(ValueError):
    """The survey cannot support what was asked (one line: which camera, what is missing)."""


#: the fewest survey points a camera must see to be posed (6 unknowns, 2 equations a point,
#: with room to spot a wrong one)
MIN_POINTS_POSE = 6
#: … and to also fit focal lengths, principal point and distortion (14 unknowns)
MIN_POINTS_INTRINSICS = 12


@dataclass
class CameraFit:
    """One camera's calibration: the camera, its reprojection RMS (px) and its outliers."""

    camera: Camera
    rms_px: float
    used: int
    outliers: list  # point ids whose spot was rejected for this camera


def _params(cam: Camera, intrinsics: bool) -> np.ndarray:
    p = [*cam.rotation, *cam.position]
    if intrinsics:
        p += [cam.fx, cam.fy, cam.cx, cam.cy, cam.dist[0], cam.dist[1], cam.dist[2],
              cam.dist[3]]
    return np.array(p, float)


def _camera(base: Camera, p: np.ndarray, intrinsics: bool) -> Camera:
    kw = {"rotation": p[0:3], "position": p[3:6]}
    if intrinsics:
        kw.update(fx=p[6], fy=p[7], cx=p[8], cy=p[9], dist=(p[10], p[11], p[12], p[13], 0.0))
    return replace(base, **kw)


def _coplanar(X: np.ndarray) -> bool:
    """All points (nearly) on one plane: the smallest spread under 1 cm."""
    if len(X) < 4:
        return True
    s = np.linalg.svd(X - X.mean(axis=0), compute_uv=False)
    return s[-1] / np.sqrt(len(X)) < 0.01


def fit_camera(nominal: Camera, X, uv, ids, intrinsics: bool = False,
               outlier_px: float = 3.0) -> CameraFit:
    """Pose (and with ``intrinsics`` the lens) of one camera from survey points it saw.

    Starts from OpenCV's SQPnP on the nominal intrinsics (so a rough or tilted nominal guess
    does not matter), then robust least squares on the reprojection error (soft-L1 loss, 1 px
    scale); observations more than ``outlier_px`` off after the fit are dropped and the fit
    repeated (a wrong spot, a mis-measured point), and reported by point id.
    """
    import cv2
    from scipy.optimize import least_squares

    X = np.asarray(X, float)
    uv = np.asarray(uv, float)
    need = MIN_POINTS_INTRINSICS if intrinsics else MIN_POINTS_POSE
    if len(X) < need:
        raise SurveyError(f"camera {nominal.id}: sees {len(X)} survey points, needs at least "
                          f"{need}{' to fit its lens too' if intrinsics else ''}")
    if intrinsics and _coplanar(X):
        raise SurveyError(f"camera {nominal.id}: its survey points all lie on one plane; "
                          "fitting the lens needs points at two or more heights")
    xy = nominal.normalise(uv)
    ok, rvec, tvec = cv2.solvePnP(X.reshape(-1, 1, 3), xy.reshape(-1, 1, 2), np.eye(3),
                                  None, flags=cv2.SOLVEPNP_SQPNP)
    start = nominal
    if ok and np.isfinite(rvec).all():
        R = cv2.Rodrigues(rvec)[0]
        start = replace(nominal, rotation=rvec.ravel(), position=-R.T @ tvec.ravel())
        if np.median(np.linalg.norm(start.project(X)[0] - uv, axis=1)) > \
                np.median(np.linalg.norm(nominal.project(X)[0] - uv, axis=1)):
            start = nominal  # PnP fell into a worse minimum than the plan: keep the plan
    keep = np.ones(len(X), bool)

    def solve(cam0, mask):
        def resid(p):
            cam = _camera(cam0, p, intrinsics)
            r = cam.project(X[mask])[0] - uv[mask]
            return np.nan_to_num(r, nan=1e3).ravel()

        sol = least_squares(resid, _params(cam0, intrinsics), loss="soft_l1", f_scale=1.0,
                            x_scale="jac", max_nfev=200)
        return _camera(cam0, sol.x, intrinsics)

    cam = solve(start, keep)
    for _ in range(3):
        err = np.linalg.norm(cam.project(X)[0] - uv, axis=1)
        new = ~(err > outlier_px)
        if new.sum() < need or np.array_equal(new, keep):
            break
        keep = new
        cam = solve(cam, keep)
    err = np.linalg.norm(cam.project(X)[0] - uv, axis=1)
    rms = float(np.sqrt(np.mean(err[keep] ** 2)))
    return CameraFit(cam, rms, int(keep.sum()), [i for i, k in zip(ids, keep) if not k])


def refine_jointly(cameras: list[Camera], X, obs, intrinsics: bool = False,
                   point_sigma: float = 0.003, pixel_sigma: float = 0.1):
    """Bundle adjustment: every camera's pose (and lens) and every surveyed position together,
    each position free within its measurement uncertainty (``point_sigma`` m, a tape measure).

    ``obs``: list per camera of (point indices, uv K×2) — the observations kept by
    :func:`fit_camera`. Returns (cameras, adjusted positions N×3).
    """
    from scipy.optimize import least_squares
    from scipy.sparse import lil_matrix

    X = np.asarray(X, float)
    n_pts = len(X)
    npar = len(_params(cameras[0], intrinsics))
    p0 = np.concatenate([*(_params(c, intrinsics) for c in cameras), X.ravel()])
    n_res = sum(2 * len(idx) for idx, _ in obs) + 3 * n_pts
    sparsity = lil_matrix((n_res, len(p0)), dtype=int)
    row = 0
    for k, (idx, _) in enumerate(obs):
        for j, i in enumerate(idx):
            sparsity[row + 2 * j:row + 2 * j + 2, k * npar:(k + 1) * npar] = 1
            base = len(cameras) * npar + 3 * i
            sparsity[row + 2 * j:row + 2 * j + 2, base:base + 3] = 1
        row += 2 * len(idx)
    for i in range(n_pts):
        base = len(cameras) * npar + 3 * i
        sparsity[row + 3 * i:row + 3 * i + 3, base:base + 3] = np.eye(3, dtype=int)

    def resid(p):
        pts = p[len(cameras) * npar:].reshape(-1, 3)
        out = []
        for k, (idx, uv) in enumerate(obs):
            cam = _camera(cameras[k], p[k * npar:(k + 1) * npar], intrinsics)
            r = (cam.project(pts[idx])[0] - uv) / pixel_sigma
            out.append(np.nan_to_num(r, nan=1e4).ravel())
        out.append(((pts - X) / point_sigma).ravel())
        return np.concatenate(out)

    sol = least_squares(resid, p0, jac_sparsity=sparsity, loss="soft_l1", f_scale=3.0,
                        x_scale="jac", max_nfev=100)
    cams = [_camera(c, sol.x[k * npar:(k + 1) * npar], intrinsics)
            for k, c in enumerate(cameras)]
    return cams, sol.x[len(cameras) * npar:].reshape(-1, 3)


@dataclass
class Calibration:
    """The cameras fitted to a survey, and what the fit found."""

    cameras: list[Camera]
    fits: list[CameraFit]
    adjusted: np.ndarray  # N×3 survey positions after the joint refinement
    mismeasured: list  # (point id, how far the cameras put it from its record, m)


def calibrate(nominal: list[Camera], X, uv, ids, intrinsics: bool = False,
              point_sigma: float = 0.003, outlier_px: float = 3.0) -> Calibration:
    """Calibrate every camera from the survey: ``X`` N×3 measured positions, ``uv`` C×N×2 spots
    (NaN: not seen), ``ids`` the point ids. Per camera (:func:`fit_camera`), then jointly
    (:func:`refine_jointly`). A point rejected by two or more of the cameras that saw it is
    reported as mis-measured (a wrong tape reading moves it in every view), with how far from
    its record the calibrated cameras put it (NaN when fewer than two cameras saw it)."""
    X = np.asarray(X, float)
    uv = np.asarray(uv, float)
    fits, obs = [], []
    rejected: dict = {}
    for k, cam in enumerate(nominal):
        seen = np.flatnonzero(np.isfinite(uv[k]).all(axis=1))
        if not len(seen):
            raise SurveyError(f"camera {cam.id}: saw none of the {len(X)} survey points "
                              "(check its frames, its id, or where it looks)")
        fit = fit_camera(cam, X[seen], uv[k, seen], [ids[i] for i in seen], intrinsics,
                         outlier_px)
        fits.append(fit)
        out = set(fit.outliers)
        for pid in out:
            rejected[pid] = rejected.get(pid, 0) + 1
        keep = np.array([i for i in seen if ids[i] not in out], int)
        obs.append((keep, uv[k, keep]))
    cams, adjusted = refine_jointly([f.camera for f in fits], X, obs, intrinsics, point_sigma)
    seen_by = np.isfinite(uv).all(axis=2).sum(axis=0)
    suspects = [i for i, pid in enumerate(ids)
                if rejected.get(pid, 0) >= 2 or (rejected.get(pid, 0) >= 1 and seen_by[i] == 1)]
    # how far off the record is: where the calibrated cameras see the LED, against it
    from .triangulation import triangulate

    where = triangulate(cams, uv[:, suspects]).X if suspects else np.zeros((0, 3))
    bad = [(ids[i], float(np.linalg.norm(w - X[i]))) for i, w in zip(suspects, where)]
    for k, (fit, cam) in enumerate(zip(fits, cams)):
        idx, uvk = obs[k]
        err = np.linalg.norm(cam.project(adjusted[idx])[0] - uvk, axis=1)
        fit.camera, fit.rms_px = cam, float(np.sqrt(np.mean(err ** 2))) if len(err) else 0.0
    return Calibration(cams, fits, adjusted, bad)


def error_stats(err_m) -> dict:
    """mean, median, p90, max (m) and the share of points with a fix."""
    e = np.asarray(err_m, float)
    ok = np.isfinite(e)
    if not ok.any():
        return {"mean": None, "median": None, "p90": None, "max": None, "fixed": 0.0}
    e = e[ok]
    return {"mean": float(e.mean()), "median": float(np.median(e)),
            "p90": float(np.percentile(e, 90)), "max": float(e.max()), "fixed": float(ok.mean())}


#: held-out comparisons: (label, cameras, fusion)
HELD_OUT = (("nominal, (a) mean of pairs", "nominal", "mean"),
            ("nominal, (b) nearest pair", "nominal", "nearest"),
            ("nominal, all-camera LS", "nominal", "robust"),
            ("calibrated, (a) mean of pairs", "calibrated", "mean"),
            ("calibrated, (b) nearest pair", "calibrated", "nearest"),
            ("calibrated, (c) region map", "calibrated", "region"),
            ("calibrated, all-camera LS", "calibrated", "robust"))


def held_out(nominal: list[Camera], X, uv, ids, room, intrinsics: bool = False, folds: int = 5,
             point_sigma: float = 0.003, progress=None, seed: int = 0,
             per_point: dict | None = None, pair_method: str = "paper",
             max_residual: float = 2.0) -> dict:
    """k-fold accuracy by survey point: calibrate on the other folds, locate this fold's points
    from their spots, compare with their measured positions. Never the fitted points.

    Returns label → :func:`error_stats` (metres) over all folds, for :data:`HELD_OUT`; the
    per-point errors go into ``per_point`` (label → N errors, m) when given.
    """
    from .fusion import fuse

    X = np.asarray(X, float)
    uv = np.asarray(uv, float)
    order = np.random.default_rng(seed).permutation(len(X))
    parts = np.array_split(order, folds)
    errors = {label: np.full(len(X), np.nan) for label, _, _ in HELD_OUT}
    for f, test in enumerate(parts):
        train = np.setdiff1d(order, test)
        try:
            cal = calibrate(nominal, X[train], uv[:, train], [ids[i] for i in train],
                            intrinsics, point_sigma)
        except SurveyError as e:
            raise SurveyError(f"too few points for a {folds}-fold held-out check ({e} in a "
                              f"fold of {len(train)}); add points or use fewer folds") from None
        rmap = learn_region_map(cal.cameras, uv[:, train], cal.adjusted, room,
                                pair_method=pair_method)
        for label, which, method in HELD_OUT:
            cams = cal.cameras if which == "calibrated" else nominal
            fixed = fuse(cams, uv[:, test], method, region_map=rmap, pair_method=pair_method,
                         max_residual=max_residual).X
            errors[label][test] = np.linalg.norm(fixed - X[test], axis=1)
        if progress:
            progress(f + 1, folds)
    if per_point is not None:
        per_point.update(errors)
    return {label: error_stats(e) for label, e in errors.items()}


def survey_spots(deployment, bundle) -> tuple[np.ndarray, list[str]]:
    """The survey's spots ``C×N×2`` in the deployment's camera order, and notes: from the
    bundle's frames (the deployment's detector) or, without frames, its observations.csv."""
    from .detection import detect_spots

    ids = bundle.point_ids
    uv = np.full((len(deployment.cameras), len(ids), 2), np.nan)
    notes = []
    known = {c.id for c in deployment.cameras}
    strangers = sorted(set(bundle.camera_ids()) - known)
    if strangers:
        notes.append(f"ignored camera(s) {', '.join(strangers)} that the deployment lacks")
    for k, cam in enumerate(deployment.cameras):
        if bundle.frames:
            frames = [bundle.frame(p, cam.id) for p in ids]
            spots = detect_spots(frames, deployment.detector, deployment.detector_settings,
                                 shape=(cam.height, cam.width))
            uv[k] = spots.uv
            bad = [f"{p} {r.replace('_', ' ')}" for p, r in zip(ids, spots.reasons)
                   if r not in (None, "missing", "no_spot")]
            if bad:
                notes.append(f"camera {cam.id}: {len(bad)} frames not used: "
                             + ", ".join(bad[:8]) + (" …" if len(bad) > 8 else ""))
        else:
            for i, p in enumerate(ids):
                if (p, cam.id) in bundle.observations:
                    uv[k, i] = bundle.observations[(p, cam.id)]
    # the deployment's per-camera pixel corrections apply here exactly as in the locator, so
    # that the cameras are fitted to the spots the locator will see
    offsets = deployment.pixel_offsets
    for k, cam in enumerate(deployment.cameras):
        uv[k] -= offsets.get(cam.id, (0.0, 0.0))
    return uv, notes


# -- planning a survey ----------------------------------------------------------------------

@dataclass
class SurveyPlan:
    """Points to measure: ids in walking order, planned positions N×3, who sees what."""

    ids: list[str]
    xyz: np.ndarray
    seen: np.ndarray  # C×N: each camera sees the point (nominal cameras, 5 px margin)
    camera_ids: list[str]


def plan_survey(deployment, step: float = 0.3, heights=(0.0, 0.35, 0.7),
                min_per_camera: int = MIN_POINTS_INTRINSICS, min_per_pair: int = 6,
                margin_px: float = 5.0) -> SurveyPlan:
    """The points to measure: a grid over the room (minus keep-out areas) at each height, kept
    where a camera sees them, made finer where a camera or an overlapping pair of cameras would
    otherwise get fewer than ``min_per_camera`` / ``min_per_pair`` points. Two heights or more:
    a floor-only survey cannot separate a camera's height from its focal length.

    Ids follow the order an installer walks: height by height, rows in a serpentine.
    """
    from shapely import contains_xy
    from shapely.geometry import Polygon

    heights = sorted(set(float(h) for h in heights))
    if len(heights) < 2:
        raise SurveyError("a survey needs points at two or more heights (a floor-only survey "
                          "cannot separate height from scale)")
    room = Polygon(deployment.room)
    for poly in deployment.keep_out:
        room = room.difference(Polygon(poly))
    if room.is_empty or room.area < (step / 2) ** 2:
        raise SurveyError("the keep-out areas leave no floor to survey")
    cams = deployment.cameras

    def grid(s, offset=0.0):
        x0, y0, x1, y1 = room.bounds
        gx, gy = np.meshgrid(np.arange(x0 + s / 2 + offset, x1, s),
                             np.arange(y0 + s / 2 + offset, y1, s))
        xy = np.c_[gx.ravel(), gy.ravel()]
        return xy[contains_xy(room, xy[:, 0], xy[:, 1])]

    def seen_by(pts):
        return np.stack([c.project(pts, margin=margin_px)[2] for c in cams])

    pts = np.concatenate([np.c_[grid(step), np.full(len(grid(step)), h)] for h in heights])
    pts = pts[seen_by(pts).any(axis=0)]
    # where a camera or an overlapping pair has too few points: add a finer grid there
    for level in (2, 4):
        seen = seen_by(pts)
        fine_xy = grid(step / level, step / (2 * level))
        fine = np.concatenate([np.c_[fine_xy, np.full(len(fine_xy), h)] for h in heights])
        fine_seen = seen_by(fine)
        want = np.zeros(len(fine), bool)
        for k in range(len(cams)):
            if seen[k].sum() < min_per_camera:
                want |= fine_seen[k]
            for j in range(k + 1, len(cams)):
                both = fine_seen[k] & fine_seen[j]
                if both.any() and (seen[k] & seen[j]).sum() < min_per_pair:
                    want |= both
        if not want.any():
            break
        pts = np.unique(np.concatenate([pts, fine[want]]).round(6), axis=0)
    seen = seen_by(pts)
    for k, cam in enumerate(cams):
        if seen[k].sum() < MIN_POINTS_POSE:
            raise SurveyError(f"camera {cam.id}: sees only {int(seen[k].sum())} points of the "
                              "room at these heights (is it looking at the floor?)")
    order = _walking_order(pts)
    pts, seen = pts[order], seen[:, order]
    ids = [f"S{i + 1:04d}" for i in range(len(pts))]
    return SurveyPlan(ids, pts, seen, [c.id for c in cams])


# -- the whole calibration, as `vlpcal survey calibrate` runs it ------------------------------

#: held-out label → the fusion the calibrated deployment would then use
FUSION_OF = {"calibrated, (a) mean of pairs": "mean", "calibrated, (b) nearest pair": "nearest",
             "calibrated, (c) region map": "region", "calibrated, all-camera LS": "robust"}


@dataclass
class SurveyResult:
    """A calibrated deployment and the report behind it (all lengths in metres)."""

    deployment: object  #: the calibrated :class:`~vlpcal.deployment.Deployment`
    stats: dict  #: held-out label → :func:`error_stats`
    per_point: dict  #: held-out label → N errors
    cameras: list  #: per camera: rms_px, points, outliers, moved_cm, turned_deg, intrinsics
    mismeasured: list  #: (point id, m)
    fusion: str  #: the fusion chosen by held-out mean
    points: np.ndarray  #: N×3 the survey positions as measured

    def report(self, notes=()) -> dict:
        return {"held_out_m": self.stats, "cameras": self.cameras, "fusion": self.fusion,
                "mismeasured": [{"point_id": p, "moved_m": m} for p, m in self.mismeasured],
                "notes": list(notes)}


def calibrate_survey(dep, X, uv, ids, intrinsics: bool = False, folds: int = 5,
                     point_sigma: float = 0.003, progress=None, sources: dict | None = None
                     ) -> SurveyResult:
    """Calibrate ``dep``'s cameras from a survey, measure the held-out accuracy (k-fold), learn
    the region map (approach (c)) and choose the fusion with the lowest held-out mean; returns
    the calibrated deployment, its provenance naming ``sources``. ``progress(i, n)`` counts the
    full fit and each fold."""
    from .deployment import Deployment, provenance
    from .geometry import rodrigues

    cams = dep.cameras
    cal = calibrate(cams, X, uv, ids, intrinsics, point_sigma)
    if progress:
        progress(1, folds + 1)
    per_point: dict = {}
    stats = held_out(cams, X, uv, ids, dep.room, intrinsics, folds, point_sigma,
                     progress=(lambda i, n: progress(i + 1, n + 1)) if progress else None,
                     per_point=per_point, pair_method=dep.pair_method,
                     max_residual=dep.max_residual)
    rmap = learn_region_map(cal.cameras, uv, cal.adjusted, dep.room, pair_method=dep.pair_method)
    best = min(FUSION_OF, key=lambda k: stats[k]["mean"] if stats[k]["mean"] is not None
               else np.inf)
    extra = {k: v for k, v in dep.extra.items() if k != "provenance"}
    extra["fusion"] = {**extra.get("fusion", {}), "method": FUSION_OF[best],
                       "region_map": rmap.to_dict()}
    extra["provenance"] = provenance(
        "vlpcal survey calibrate", **{"from": {**(sources or {}), "points": len(ids)}},
        intrinsics=intrinsics, held_out_mean_m={k: v["mean"] for k, v in stats.items()})
    rows = []
    for nom, fit in zip(cams, cal.fits):
        c = fit.camera
        dR = rodrigues(c.rotation) @ rodrigues(nom.rotation).T
        angle = float(np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1, 1))))
        rows.append({"camera": c.id, "rms_px": fit.rms_px, "points": fit.used,
                     "outliers": fit.outliers,
                     "moved_cm": float(np.linalg.norm(np.subtract(c.position, nom.position))
                                       * 100),
                     "turned_deg": angle,
                     "fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy, "dist": list(c.dist)})
    calibrated = Deployment(dep.name, dep.ceiling_height, dep.room, cal.cameras, dep.keep_out,
                            extra)
    return SurveyResult(calibrated, stats, per_point, rows, cal.mismeasured, FUSION_OF[best],
                        np.asarray(X, float))


def _walking_order(pts: np.ndarray) -> np.ndarray:
    """The order an installer walks the points: height by height, row by row (rows of equal
    y), each row entered from the end nearer to where the last one left off — a serpentine
    even where the finer grid makes rows of unequal extent."""
    order: list = []
    x_at = None
    for z in np.unique(np.round(pts[:, 2], 6)):
        on = np.flatnonzero(np.isclose(pts[:, 2], z))
        for y in np.unique(np.round(pts[on, 1], 4)):
            row = on[np.isclose(np.round(pts[on, 1], 4), y)]
            row = row[np.argsort(pts[row, 0], kind="stable")]
            if x_at is not None and abs(pts[row[-1], 0] - x_at) < abs(pts[row[0], 0] - x_at):
                row = row[::-1]
            order.extend(row.tolist())
            x_at = pts[row[-1], 0]
    return np.array(order, int)
