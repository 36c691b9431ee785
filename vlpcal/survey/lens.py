"""Lens models for survey calibration: which of a camera's numbers a fit may change.

Nested, simplest first (each adds to the one before): ``pose`` (rotation and position, the lens
as in the deployment), ``focal`` (+ fx, fy), ``principal`` (+ cx, cy), ``k1`` (+ the first radial
term), ``k2`` (+ k2 and the tangential p1, p2), ``full`` (+ k3). A fit's parameters are a flat
vector: rotation (3), position (3), then the model's lens numbers in that order.

How well a survey *determines* a model is judged from the fit itself, never in metres. Free
focal lengths trade against the camera's distance unless the points spread in depth: the
perspective the survey shows — its depth range relative to the distance, times the points'
radius from the image centre — must stand :data:`PERSPECTIVE_SNR` times above the fit's own residual
spread, the fit's information matrix (columns scaled to unit norm) must not be singular, and
its covariance must pin the focal length (relative standard error) more finely than the
depth span relative to the distance.
Both are ratios of the scene to itself: the same survey at any scale gets the same verdict.
The verdict is a warning, never a refusal: a focal length that trades against the distance
costs the fixes nothing, and whether a model helps is decided by what it does to them
(:mod:`.lens_decision`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..geometry import Camera
from ..spelling import Spelling
from .errors import SurveyError


class LensModel(Spelling):
    """A nested lens model, simplest first; the value is the spelling of files and reports
    (a member equals its string: ``LensModel.K1 == "k1"``)."""

    POSE = "pose"  #: rotation and position only, the lens as in the deployment
    FOCAL = "focal"  #: + fx, fy
    PRINCIPAL = "principal"  #: + cx, cy
    K1 = "k1"  #: + the first radial term
    K2 = "k2"  #: + k2 and the tangential p1, p2
    FULL = "full"  #: + k3: OpenCV's whole five-term lens


#: the nested lens models, simplest first
LENS_MODELS = tuple(LensModel)
_ADDS = {"pose": (), "focal": ("fx", "fy"), "principal": ("cx", "cy"), "k1": ("k1",),
         "k2": ("k2", "p1", "p2"), "full": ("k3",)}
_DIST = {"k1": 0, "k2": 1, "p1": 2, "p2": 3, "k3": 4}
#: in words, for the terminal and the report
LENS_WORDS = {"pose": "pose only (lens as in the deployment)", "focal": "+ focal lengths",
              "principal": "+ principal point", "k1": "+ radial k1",
              "k2": "+ k2 and tangential p1, p2", "full": "+ k3 (the full OpenCV lens)"}
#: the fewest points a camera must see to be posed (6 unknowns, 2 equations a point, with room
#: to spot a wrong one)
MIN_POINTS_POSE = 6
#: the survey's perspective (px) must exceed the fit's residual spread this many times
PERSPECTIVE_SNR = 4.0
#: reciprocal condition number of the scaled information matrix below which a fit is singular
SINGULAR = 1e-12


def lens_params(model: str) -> tuple[str, ...]:
    """The lens numbers ``model`` frees, in vector order (``pose``: none)."""
    if model not in LENS_MODELS:
        raise ValueError(f"unknown lens model {model!r}; expected one of "
                         f"{', '.join(LENS_MODELS)}")
    names: tuple[str, ...] = ()
    for m in LENS_MODELS[:LENS_MODELS.index(model) + 1]:
        names += _ADDS[m]
    return names


def min_points(model: str) -> int:
    """Points a camera must see to fit ``model``: at least as many as unknowns (and 6)."""
    return max(MIN_POINTS_POSE, 6 + len(lens_params(model)))


def to_vector(cam: Camera, model: str) -> np.ndarray:
    """The fit's parameters of ``cam`` under ``model``."""
    p = [*cam.rotation, *cam.position]
    for name in lens_params(model):
        p.append(cam.dist[_DIST[name]] if name in _DIST else getattr(cam, name))
    return np.array(p, float)


def from_vector(base: Camera, p, model: str) -> Camera:
    """``base`` with the numbers of the vector ``p`` (as :func:`to_vector` lays them out)."""
    kw: dict = {"rotation": p[0:3], "position": p[3:6]}
    dist = list(base.dist)
    for k, name in enumerate(lens_params(model), start=6):
        if name in _DIST:
            dist[_DIST[name]] = p[k]
        else:
            kw[name] = p[k]
    if len(p) > 6:
        kw["dist"] = dist
    return replace(base, **kw)


@dataclass
class Support:
    """Whether a fit determines its lens: the perspective its points show (px), the fit's
    residual spread (px), the reciprocal condition of its scaled information, the verdict."""

    ok: bool
    perspective_px: float  # depth range / mean depth × RMS image radius
    depth_rel_range: float  # depth range (5th–95th percentile) / mean depth
    resid_px: float
    rcond: float
    reason: str = ""


def lens_support(cam: Camera, model: str, jac, resid_px: float, X, uv,
                 nominal: Camera | None = None) -> Support:
    """Judge whether a fit of ``model`` (its Jacobian ``jac`` at the solution, residual spread
    ``resid_px``) on points ``X`` seen at ``uv`` determines its lens (module docstring)."""
    depth = cam.to_camera(np.asarray(X, float))[:, 2]
    lo, hi = np.percentile(depth, [5, 95])
    rel = float((hi - lo) / np.mean(depth))
    # from the image's centre, not the fitted principal point: a fit cannot inflate its own lever
    centre = [(cam.width - 1) / 2, (cam.height - 1) / 2]
    radius = float(np.sqrt(np.mean((np.asarray(uv, float) - centre) ** 2) * 2))
    persp = rel * radius
    J = np.asarray(jac.toarray() if hasattr(jac, "toarray") else jac, float)
    scale = np.linalg.norm(J, axis=0)
    scale[scale == 0] = 1.0
    pose_sv = np.linalg.svd(J[:, :6] / scale[:6], compute_uv=False)
    if not (pose_sv[0] > 0 and (pose_sv[-1] / pose_sv[0]) ** 2 > SINGULAR):
        raise _pose_error(cam)
    if model == "pose":
        return Support(True, persp, rel, resid_px, 1.0)
    sv = np.linalg.svd(J / scale, compute_uv=False)
    A = (J / scale).T @ (J / scale)
    rcond = float((sv[-1] / sv[0]) ** 2) if sv[0] > 0 else 0.0
    if not rcond > SINGULAR:
        return Support(False, persp, rel, resid_px, rcond,
                       "its survey points cannot separate the lens from the pose (the fit is "
                       "singular, as when they all lie on one plane): survey at more heights")
    # and the fit must pin the focal length more finely than the depth span it has to go by
    cov = np.linalg.pinv(A) / np.outer(scale, scale) * resid_px ** 2
    f = 0.5 * (cam.fx + cam.fy)
    focal_se = float(np.sqrt(max((cov[6, 6] + cov[7, 7] + 2 * cov[6, 7]) / 4, 0.0)) / f)
    if persp >= PERSPECTIVE_SNR * resid_px and focal_se > rel:
        return Support(False, persp, rel, resid_px, rcond,
                       f"its points span only {rel:.2%} of their distance in depth: fits that "
                       f"place them equally well differ in focal length by ±{focal_se:.2%} "
                       "with this lens model (it trades against the camera's distance along "
                       "the view)")
    ok = bool(persp >= PERSPECTIVE_SNR * resid_px)
    if ok and nominal is not None:
        ratio = (cam.fx + cam.fy) / (nominal.fx + nominal.fy)
        if not 0.5 <= ratio <= 2.0:
            return Support(False, persp, rel, resid_px, rcond,
                           f"the fit moved its focal length {ratio:.2g} times the deployment's "
                           "(a lens this far off is a trade against the pose, not a lens)")
    reason = "" if ok else (
        f"its points span only {rel:.2%} of their distance in depth, giving {persp:.2g} px of "
        f"perspective, less than {PERSPECTIVE_SNR:g}× its {resid_px:.2g} px of spot scatter, so "
        "its focal length cannot be told from its distance (more heights would)")
    return Support(ok, persp, rel, resid_px, rcond, reason)


def _pose_error(cam: Camera) -> SurveyError:
    return SurveyError(f"camera {cam.id}: its survey points cannot fix its pose (they lie on "
                       "a line or at one place as it sees them): spread them over the floor "
                       "and at two or more heights")


def describe_lens(cam: Camera, nominal: Camera, model: str) -> str:
    """What a fit changed in the lens, in a surveyor's words: ``k1 −0.21, f +1.2 %, …``."""
    names = lens_params(model)
    if not names:
        return "lens as in the deployment"
    parts = []
    if "fx" in names:
        f0 = 0.5 * (nominal.fx + nominal.fy)
        parts.append(f"f {100 * (0.5 * (cam.fx + cam.fy) - f0) / f0:+.1f} %")
    if "cx" in names:
        parts.append(f"centre {cam.cx - nominal.cx:+.1f}, {cam.cy - nominal.cy:+.1f} px")
    for name in ("k1", "k2", "p1", "p2", "k3"):
        if name in names:
            parts.append(f"{name} {cam.dist[_DIST[name]]:+.3g}")
    return ", ".join(parts).replace("-", "−")


def project_with_jacobian(cam: Camera, X, model: str):
    """Pixels of world points ``X`` (N×3) and their analytic derivatives: ``(uv N×2,
    J_params N×2×P in :func:`to_vector`'s order, J_points N×2×3)``. Rows where the point does
    not project (behind the camera) are NaN in ``uv`` and zero in both Jacobians. Analytic so
    that a bundle adjustment over hundreds of points and cameras costs one projection per step
    instead of one per parameter."""
    import cv2  # (OpenCV: loaded by a fit only)

    X = np.asarray(X, float)
    uv, _, _ = cam.project(X)
    d = X - cam.center
    Xc = d @ cam.R.T
    z = Xc[:, 2]
    good = np.isfinite(uv).all(axis=1) & (z > 0)
    iz = np.where(good, 1.0 / np.where(good, z, 1.0), 0.0)
    x, y = Xc[:, 0] * iz, Xc[:, 1] * iz
    J_pts = np.nan_to_num(cam.jacobian(np.where(good[:, None], X, cam.center + cam.axis)))
    J_pts[~good] = 0.0
    A = J_pts @ cam.R.T  # d pixel / d camera-frame point (N×2×3), as J_X = A · R
    names = lens_params(model)
    J = np.zeros((len(X), 2, 6 + len(names)))
    dR = cv2.Rodrigues(np.asarray(cam.rotation, float))[1].reshape(3, 3, 3)  # i, a, b
    for i in range(3):
        J[:, :, i] = np.einsum("nak,nk->na", A, d @ dR[i].T)
    J[:, :, 3:6] = -J_pts
    r2 = x * x + y * y
    k1, k2, p1, p2, k3 = cam.dist
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    dd = {"k1": (x * r2, y * r2), "k2": (x * r2 ** 2, y * r2 ** 2),
          "k3": (x * r2 ** 3, y * r2 ** 3), "p1": (2 * x * y, r2 + 2 * y * y),
          "p2": (r2 + 2 * x * x, 2 * x * y)}
    for k, name in enumerate(names, start=6):
        if name == "fx":
            J[:, 0, k] = xd
        elif name == "fy":
            J[:, 1, k] = yd
        elif name == "cx":
            J[:, 0, k] = 1.0
        elif name == "cy":
            J[:, 1, k] = 1.0
        else:
            J[:, 0, k] = cam.fx * dd[name][0]
            J[:, 1, k] = cam.fy * dd[name][1]
    J[~good] = 0.0
    return uv, J, J_pts
