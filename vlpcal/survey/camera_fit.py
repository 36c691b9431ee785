"""One camera fitted to the survey points it saw: its pose and the lens numbers a model frees,
by robust least squares from OpenCV's PnP (or a given start, or the best of several), with
wrong spots found against the fit's own spread and dropped."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..geometry import Camera
from .errors import SurveyError
from .least_squares import levenberg_marquardt
from .lens import (
    MIN_POINTS_POSE,
    Support,
    from_vector,
    lens_support,
    min_points,
    project_with_jacobian,
    to_vector,
)

#: an observation further off than this many robust standard deviations is an outlier …
OUTLIER_SIGMAS = 5.0
#: … and never closer than this share of the image diagonal (a spot's own blur)
OUTLIER_IMAGE_SHARE = 0.005
#: iterations of a single camera's fit (it converges in a handful from any usable start)
FIT_ITERATIONS = 100
#: … and stops when a step gains less than this share of its cost
FIT_TOLERANCE = 1e-8
#: … or less than this share of its loss's scale squared (the residuals' own spread): a gain
#: that small moves nothing measurable
NEGLIGIBLE_GAIN = 1e-6


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
    #: with several starts: (camera, robust cost) each reached on all the points, the first
    #: from the given start (or PnP)
    minima: list = field(default_factory=list, repr=False)


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
    import cv2  # (OpenCV: loaded by a fit only)

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
               start: Camera | None = None, intrinsics: bool | None = None,
               starts: tuple = ()) -> CameraFit:
    """Pose (and the lens numbers ``model`` frees) of one camera from survey points it saw.

    Starts from OpenCV's SQPnP on the nominal lens (so a rough or tilted nominal guess does
    not matter) or from ``start``, then robust least squares on the reprojection error
    (soft-L1 at the fit's own scale); observations further off than ``outlier_px`` (default:
    :data:`OUTLIER_SIGMAS` robust standard deviations, at least
    :data:`OUTLIER_IMAGE_SHARE` of the image diagonal) are dropped and the fit repeated (a
    wrong spot, a mis-measured point), and reported by point id. ``starts``: more cameras
    to start from (the data's own, where a fit has several minima); the one reaching the
    lowest cost on all the points is kept. ``intrinsics=True`` is ``model="full"``. A model
    the survey determines only weakly is fitted all the same: its :class:`~.lens.Support`
    says so.
    """

    if intrinsics is not None:
        model = "full" if intrinsics else model
    X = np.asarray(X, float)
    uv = np.asarray(uv, float)
    need = min_points(model)
    if len(X) < need:
        raise SurveyError(f"camera {nominal.id}: sees {len(X)} survey points, needs at least "
                          f"{need}" + (f" to fit its lens ({model})" if model != "pose" else ""))
    keep = np.ones(len(X), bool)
    scale = OUTLIER_IMAGE_SHARE * float(np.hypot(nominal.width, nominal.height))  # 1 px at 160 px
    cam0 = start if start is not None else _pnp_start(nominal, X, uv)

    def solve(c0, mask):
        Xm, uvm = X[mask], uv[mask]

        def resid(p):
            r = from_vector(nominal, p, model).project(Xm)[0] - uvm
            return np.nan_to_num(r, nan=1e3 * scale).ravel()

        def jac(p):
            J = project_with_jacobian(from_vector(nominal, p, model), Xm, model)[1]
            return J.reshape(2 * len(Xm), -1)

        p, cost = levenberg_marquardt(resid, jac, to_vector(c0, model), f_scale=scale,
                                       iterations=FIT_ITERATIONS, tolerance=FIT_TOLERANCE,
                                       negligible=NEGLIGIBLE_GAIN)
        w = 1.0 / np.sqrt(np.sqrt(1 + (resid(p) / scale) ** 2))  # √ of the loss's weights
        return from_vector(nominal, p, model), (jac(p) * w[:, None], cost)

    cam, sol = solve(cam0, keep)
    minima = [(cam, sol[1])]
    for other in starts:  # the data's own starts: the one reaching the lowest cost is kept
        trial = solve(other, keep)
        minima.append((trial[0], trial[1][1]))
        if trial[1][1] < sol[1]:
            cam, sol = trial
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
    support = lens_support(cam, model, sol[0], sigma, X[keep], uv[keep], nominal)
    return CameraFit(cam, rms, int(keep.sum()), [i for i, k in zip(ids, keep) if not k],
                     model, sigma, support, keep, minima if starts else [])
