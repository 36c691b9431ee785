"""What a survey costs the fixes: the error a tape survey leaves in the calibrated cameras,
predicted before anyone kneels with a tape, as a share of the cameras' own spot noise.

Linearised joint adjustment (the one :func:`.calibration.refine_jointly` solves): every
camera's pose and lens (a representative model, ``k1``) and every surveyed position, the
positions known to ``tape`` m per axis, the spots to ``spot`` px. Eliminating the positions
(the Schur complement of their 3 × 3 blocks) leaves the cameras' covariance; a fix at a test
point moves with the cameras by ``dX/dθ = −F⁻¹ Σ J_Xᵀ J_θ`` (F the fix's information), so the
calibration adds ``D Cov_θ Dᵀ`` to the fix's own ``σ² F⁻¹`` (two independent sources).
The ratio of the two mean errors is dimensionless: the same survey of the same scene at any
scale, with tape and spots scaled alike, predicts the same share.

Checked against the survey benchmark: 345 points at ±3 mm under the qvga profile's cameras
(spots ≈ 0.035 px) predict 1.2× the true cameras' error; the full calibration measured 1.23×.
"""

from __future__ import annotations

import numpy as np

from .lens import lens_params, project_with_jacobian

#: the lens model the prediction assumes: the one surveys of cheap cameras most often support
BUDGET_MODEL = "k1"


#: a site of more cameras is judged on the block of this many around its middle camera: the
#: cost of a survey is local (each camera's points), and the prediction stays bounded
LOCAL_CAMERAS = 9


def calibration_ratio(cameras, survey_xyz, test_xyz, tape, spot: float,
                      model: str = BUDGET_MODEL, margin_px: float = 5.0,
                      draws: int = 400) -> tuple[float, float]:
    """Predicted mean 3D error of fixes at ``test_xyz`` with cameras calibrated from a survey
    at ``survey_xyz`` (positions to ``tape`` m, spots to ``spot`` px), divided by the same
    with exact cameras: (median, 95th percentile) over ``draws`` surveys. A survey's tape
    errors are one draw: the cameras it leaves are off in one direction for every fix, so the
    ratio varies from survey to survey and both figures matter. (NaN, NaN) when no test
    point is seen by two cameras that triangulate it. Deterministic (a fixed seed).
    ``tape``: m, one for all, or per point (``n``) or per point and axis (``n×3``); ``inf``
    for a position nobody measured (a free survey's LED)."""
    errors = fix_errors(cameras, survey_xyz, test_xyz, tape, spot, model, margin_px, draws)
    if errors is None:
        return float("nan"), float("nan")
    ratio = errors[1] / errors[0]
    return float(np.median(ratio)), float(np.quantile(ratio, 0.95))


def fix_errors(cameras, survey_xyz, test_xyz, tape, spot: float, model: str = BUDGET_MODEL,
               margin_px: float = 5.0, draws: int = 400):
    """:func:`calibration_ratio`'s draws: the mean 3D error (m) of fixes at ``test_xyz`` with
    exact cameras and with the calibrated ones, per draw (two arrays), or None."""
    cams = _local_block(list(cameras))
    survey_xyz = np.asarray(survey_xyz, float).reshape(-1, 3)
    test_xyz = np.asarray(test_xyz, float).reshape(-1, 3)
    npar = 6 + len(lens_params(model))
    P = len(cams) * npar
    sig = np.asarray(tape, float)
    sig = np.broadcast_to(sig[:, None] if sig.ndim == 1 else sig, survey_xyz.shape)
    # a position nobody measured that fewer cameras see than fix it tells nothing: left out
    views = sum(c.project(survey_xyz, margin=margin_px)[2].astype(int) for c in cams)
    told = 2 * views + np.isfinite(sig).sum(axis=1) >= 3
    survey_xyz, sig = survey_xyz[told], sig[told]
    # the joint normal matrix: cameras (P × P) and the points' 3 × 3 blocks; each camera's
    # coupling to the points it sees, kept per camera (a point is seen by few cameras)
    A_cc = np.zeros((P, P))
    with np.errstate(divide="ignore"):
        A_pp = np.einsum("ni,ij->nij", 1.0 / sig ** 2, np.eye(3))
    seen_by, couple = [], []
    for k, cam in enumerate(cams):
        idx = np.flatnonzero(cam.project(survey_xyz, margin=margin_px)[2])
        _, Jc, Jp = project_with_jacobian(cam, survey_xyz[idx], model)
        Jc, Jp = Jc / spot, Jp / spot
        s = slice(k * npar, (k + 1) * npar)
        A_cc[s, s] += np.einsum("nai,naj->ij", Jc, Jc)
        A_pp[idx] += np.einsum("nai,naj->nij", Jp, Jp)
        seen_by.append(idx)
        couple.append(np.einsum("nai,naj->nij", Jc, Jp))  # n_k × npar × 3
    P_inv = _inverse(A_pp)
    if P_inv is None:
        return None
    # Schur complement, pair by pair over the points both cameras see
    schur = A_cc
    for k in range(len(cams)):
        mine = {p: i for i, p in enumerate(seen_by[k])}
        W = np.einsum("nij,njk->nik", couple[k], P_inv[seen_by[k]])  # n_k × npar × 3
        for j in range(k, len(cams)):
            both = np.intersect1d(seen_by[k], seen_by[j], assume_unique=True)
            if not len(both):
                continue
            a = np.array([mine[p] for p in both])
            b = np.searchsorted(seen_by[j], both)
            block = np.einsum("nik,njk->ij", W[a], couple[j][b])
            schur[k * npar:(k + 1) * npar, j * npar:(j + 1) * npar] -= block
            if j != k:
                schur[j * npar:(j + 1) * npar, k * npar:(k + 1) * npar] -= block.T

    info = np.zeros((len(test_xyz), 3, 3))
    mix = np.zeros((len(test_xyz), 3, P))
    views = np.zeros(len(test_xyz), int)
    for k, cam in enumerate(cams):
        seen = cam.project(test_xyz, margin=margin_px)[2]
        _, Jc, Jp = project_with_jacobian(cam, test_xyz, model)
        Jc[~seen], Jp[~seen] = 0.0, 0.0
        info += np.einsum("nai,naj->nij", Jp, Jp)
        mix[:, :, k * npar:(k + 1) * npar] += np.einsum("nai,naj->nij", Jp, Jc)
        views += seen
    ok = views >= 2
    if ok.any():  # two cameras that see a place from one spot do not triangulate it
        w = np.linalg.eigvalsh(info[ok])
        ok[ok] = w[:, 0] > 1e-9 * w[:, -1]
    if not ok.any():
        return None
    F_inv = np.linalg.inv(info[ok])
    D = -np.einsum("nij,njp->nip", F_inv, mix[ok])  # how a fix moves with the cameras
    # draws of the cameras' error (covariance schur⁻¹; its parameters scaled to unit
    # information first, so that metres, radians and pixels weigh alike at any scale) and of
    # the fixes' own spot noise
    d = 1.0 / np.sqrt(np.maximum(np.diag(schur), 1e-300))
    try:
        w, V = np.linalg.eigh(schur * d[:, None] * d[None, :])
    except np.linalg.LinAlgError:
        return None
    keep = w > w.max() * 1e-12
    rng = np.random.default_rng(0)
    theta = d[:, None] * ((V[:, keep] / np.sqrt(w[keep]))
                          @ rng.standard_normal((int(keep.sum()), draws)))
    L = np.linalg.cholesky(spot ** 2 * F_inv)
    z = rng.standard_normal((draws, len(F_inv), 3))
    noise = np.einsum("nij,dnj->dni", L, z)
    shift = np.einsum("nip,pd->dni", D, theta)
    return (np.linalg.norm(noise, axis=2).mean(axis=1),
            np.linalg.norm(noise + shift, axis=2).mean(axis=1))


def _inverse(blocks):
    """Inverses of 3 × 3 blocks, or None if one is not invertible (a point no prior holds and
    fewer than two cameras see)."""
    d = np.sqrt(np.einsum("nii->ni", blocks))
    if not (d > 0).all():
        return None
    scaled = blocks / d[:, :, None] / d[:, None, :]
    if (np.linalg.eigvalsh(scaled)[:, 0] <= 1e-9).any():
        return None
    return np.linalg.inv(scaled) / d[:, :, None] / d[:, None, :]


def _local_block(cams: list) -> list:
    """The :data:`LOCAL_CAMERAS` cameras nearest the site's middle camera (all of them on a
    small site)."""
    if len(cams) <= LOCAL_CAMERAS:
        return cams
    xy = np.array([c.position[:2] for c in cams])
    middle = np.argmin(np.linalg.norm(xy - np.median(xy, axis=0), axis=1))
    near = np.argsort(np.linalg.norm(xy - xy[middle], axis=1), kind="stable")[:LOCAL_CAMERAS]
    return [cams[i] for i in sorted(near)]
